#!/usr/bin/env bash
# Write the book's PDF from the LaTeX that Sphinx wrote, or the article's: xelatex through
# latexmk, or say which of TeX Live's tools are missing.
#
# Usage: tools/xelatex.sh --check      only check that xelatex and latexmk are installed
#        tools/xelatex.sh DIR [NAME]   run latexmk on DIR/NAME.tex (default depthcore), which
#                                      writes DIR/NAME.pdf
# The images are compressed at zlib's level 6, not 9: 3 s instead of 7, a PDF 3 % larger.
set -euo pipefail
for tool in xelatex latexmk; do
  command -v "$tool" >/dev/null || {
    echo "make pdf: $tool not found: the PDF needs TeX Live (Debian: apt-get install" \
      "texlive-xetex texlive-latex-extra texlive-fonts-recommended lmodern latexmk" \
      "fonts-freefont-otf)" >&2
    exit 1
  }
done
[[ $1 == --check ]] && exit 0
name=${2:-depthcore}
cd "$1"
latexmk -xelatex -interaction=nonstopmode -halt-on-error \
  -e '$xdvipdfmx = "xdvipdfmx -z 6 -E -o %D %O %S"' "$name.tex" >latexmk.log 2>&1 || {
  tail -n 40 latexmk.log >&2
  echo "make pdf: xelatex failed, see $1/$name.log" >&2
  exit 1
}
echo "make pdf: wrote $1/$name.pdf"

#!/usr/bin/env bash
# Gather what the HTML book offers for download into a folder: the paper's figures (PDF,
# SVG, PNG), depthcore's source archive (with CITATION.cff inside the package, for the page
# "Cite this work" run alone), the book's own package's archive (depthbook.tar.gz, with the
# records its pages read), the pinned requirements and CITATION.cff. The PDF of the book
# is copied in by the build that writes it.
#
# Usage: tools/build-downloads.sh PYTHON FIGURES OUT
#   PYTHON   the venv's python, with setuptools
#   FIGURES  the folder of the figures already written (python -m depthbook figures)
#   OUT      the downloads' folder, made afresh
set -euo pipefail
python=$(cd "$(dirname "$1")" && pwd)/$(basename "$1") figures=$2 out=$3
rm -rf "$out"
mkdir -p "$out"
cp -r "$figures" "$out/figures"
rm -f "$out/figures/.written"
cp CITATION.cff depthcore/CITATION.cff
trap 'rm -f depthcore/CITATION.cff' EXIT
sdist='from setuptools import build_meta; import sys; sys.stdout = sys.stderr; build_meta.build_sdist(sys.argv[1])'
into=$(cd "$out" && pwd)
"$python" -c "$sdist" "$into" 2>/dev/null
(cd depthbook && "$python" -c "$sdist" "$into" 2>/dev/null && rm -rf depthbook.egg-info)
mv "$out"/depthcore-*.tar.gz "$out/depthcore.tar.gz"
mv "$out"/depthbook-*.tar.gz "$out/depthbook.tar.gz"
cp requirements.txt CITATION.cff "$out/"

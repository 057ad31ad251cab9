#!/usr/bin/env bash
# The Debian packages `make test` needs beyond Python: TeX Live's xelatex for the
# PDF of the book (`make pdf`), pdftotext for its checks, and Chromium with its
# driver for the browser checks of the built book. Installs what is missing when
# this runs as root or with password-less sudo; otherwise names the packages and
# fails. Usage: tools/system-packages.sh [--check]  (--check: only report).
set -euo pipefail

packages=(chromium chromium-driver)
# without the recommended packages (documentation, other engines), about 400 MB
tex=(texlive-xetex texlive-latex-extra texlive-fonts-recommended lmodern latexmk
     fonts-freefont-otf poppler-utils)

installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
browser=() latex=()
for pkg in "${packages[@]}"; do installed "$pkg" || browser+=("$pkg"); done
for pkg in "${tex[@]}"; do installed "$pkg" || latex+=("$pkg"); done
missing=("${browser[@]}" "${latex[@]}")
((${#missing[@]})) || exit 0

if [[ "${1:-}" == "--check" ]] || ! command -v apt-get >/dev/null; then
  echo "missing system packages: ${missing[*]}" >&2
  echo "on Debian: apt-get install --no-install-recommends ${missing[*]}" >&2
  exit 1
fi
sudo=()
if [[ $(id -u) -ne 0 ]]; then
  if ! sudo -n true 2>/dev/null; then
    echo "missing system packages: ${missing[*]}; install them as root:" >&2
    echo "  apt-get install --no-install-recommends ${missing[*]}" >&2
    exit 1
  fi
  sudo=(sudo -n)
fi
echo "installing system packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
if ((${#browser[@]})); then
  "${sudo[@]}" apt-get install -y -qq "${browser[@]}" >/dev/null
fi
if ((${#latex[@]})); then
  "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${latex[@]}" >/dev/null
fi

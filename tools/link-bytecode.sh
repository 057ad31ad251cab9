#!/usr/bin/env bash
# Link the bytecode Python compiled for one venv's packages to their copies in another.
#
# Usage: tools/link-bytecode.sh FROM TO
#   FROM, TO  the bytecode folders (under PYTHONPYCACHEPREFIX) of the two site-packages
# The pages run alone (a venv whose site-packages are a copy of .venv's) then do not compile
# again what the tests compiled. Python checks each file against the size and time of its
# source, which the copy kept, and compiles again one whose source differs. Hard links where
# the file system makes them, copies elsewhere.
set -euo pipefail
from=$1 to=$2
[[ -d $from ]] || exit 0
mkdir -p "$to"
cp -al --remove-destination "$from/." "$to/" 2>/dev/null ||
  cp -a --remove-destination "$from/." "$to/"

#!/usr/bin/env bash
# Make a virtual environment with Python 3.11 and install pinned requirements into it with uv.
#
# Usage: tools/make-venv.sh PYTHON VENV UV_HOME REQUIREMENTS
#   PYTHON        the Python 3.11 that makes the venv (refused if another version)
#   VENV          the venv's folder, made afresh
#   UV_HOME       where uv is installed (pip --target), if it is not there already
#   REQUIREMENTS  the pinned requirements file
# uv installs the pinned set in seconds where pip takes a minute. pip puts uv in a folder of
# its own, so that the venv holds the requirements alone: the pip of PYTHON when it has one,
# else one that ensurepip first installs into the venv.
set -euo pipefail
python=$1 venv=$2 uv_home=$3 requirements=$4
uv_pin=uv==0.13.9

if [[ -z "$python" ]]; then
  echo "make: no python3.11 or python3 on PATH" >&2
  exit 1
fi
if ! "$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  echo "make: Python 3.11 is required, $python is $("$python" --version 2>&1);" \
    "set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
rm -rf "$venv"
"$python" -m venv --without-pip "$venv"
if [[ ! -x "$uv_home/bin/uv" ]]; then
  env -u PYTHONPYCACHEPREFIX "$python" -m pip install -q --no-compile --no-deps \
    --target "$uv_home" "$uv_pin" 2>/dev/null || {
    rm -rf "$uv_home"
    "$venv/bin/python" -m ensurepip >/dev/null
    "$venv/bin/python" -m pip install -q --target "$uv_home" "$uv_pin"
  }
fi
"$uv_home/bin/uv" pip install -q --python "$venv/bin/python" -r "$requirements"

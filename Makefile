# depthcore: the package, its tests and the executable book.
#
#   make book               clean, strict build of the book into _build/html
#   make test               core tests, notebook drift check, book build, checks of the built book
#   make notebooks          re-run every book page and compare its outputs with book/_nbval/
#   make notebooks-update   re-execute every page and rewrite book/_nbval/ (deliberate update)
#   make check-book         checks of the built book alone (equation numbers, browser)
#   make figures            write the paper's figures to figures/
#   make bench              print the benchmark tables
#   make lint               ruff check of the package, tests, tools and benchmarks
#   make clean              remove build outputs (make distclean also removes .venv/)
#
# Every target runs in .venv/, created with Python 3.11 from the pinned
# requirements.txt and rebuilt from scratch whenever requirements.txt changes;
# depthcore is (re)installed into it in editable mode when pyproject.toml or
# its version (depthcore/__init__.py) changes.

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3 2>/dev/null)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EDITABLE := $(VENV)/.editable
PYTEST_ARGS ?=

# Kernels and tools run from .venv/ even where a user-wide Jupyter setup exists.
export JUPYTER_PREFER_ENV_PATH := 1
export PYDEVD_DISABLE_FILE_VALIDATION := 1
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: help venv book test test-core notebooks notebooks-update check-book figures bench clean distclean

help:
	@sed -n '3,/^#$$/p' Makefile | sed -e 's/^# \{0,1\}//' -e '/^$$/d'

$(STAMP): requirements.txt
	@test -n "$(PYTHON)" || { echo "make: no python3.11 or python3 on PATH" >&2; exit 1; }
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' || \
	  { echo "make: Python 3.11 is required, $(PYTHON) is $$($(PYTHON) --version 2>&1); set PYTHON=/path/to/python3.11" >&2; exit 1; }
	rm -rf $(VENV)
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q -r requirements.txt
	touch $(STAMP)

$(EDITABLE): $(STAMP) pyproject.toml depthcore/__init__.py
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	touch $(EDITABLE)

venv: $(EDITABLE)

book: $(EDITABLE)
	rm -rf _build
	$(VENV)/bin/jupyter-book build . --all -W -n --keep-going

test: $(EDITABLE)
	$(MAKE) --no-print-directory test-core
	$(MAKE) --no-print-directory notebooks
	$(MAKE) --no-print-directory book
	$(MAKE) --no-print-directory check-book

test-core: $(EDITABLE)
	$(PY) -m pytest -q -n 2 tests $(PYTEST_ARGS)

notebooks: $(EDITABLE)
	$(PY) tools/check_notebooks.py check

notebooks-update: $(EDITABLE)
	$(PY) tools/check_notebooks.py update

# Checks of the built book in _build/html (run `make book` first).
check-book: $(EDITABLE)
	$(PY) -m pytest -q tests/book $(PYTEST_ARGS)

figures: $(EDITABLE)
	$(PY) -m depthcore figures --out figures/

bench: $(EDITABLE)
	$(PY) benchmarks/bench_optimal.py
	$(PY) benchmarks/bench_ekf_filterpy.py
	$(PY) benchmarks/bench_trials.py
	$(PY) benchmarks/bench_import.py

.PHONY: lint
lint: $(EDITABLE)
	$(VENV)/bin/ruff check .

clean:
	rm -rf _build figures .pytest_cache .hypothesis book/.nbval-check-*
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) *.egg-info

# depthcore: the package, its tests and the executable book.
#
#   make book               clean, strict build of the book into _build/html, with its downloads
#   make pdf                the book as a PDF, _build/latex/depthcore.pdf (needs TeX Live's xelatex)
#   make books              the PDF and the book, from one reading of the pages (make test's build)
#   make lab                JupyterLab on the book's pages (MyST .md files open as notebooks)
#   make test               core tests; every page executed once, alone, and compared with
#                           book/_nbval/; the PDF and the book built from that execution;
#                           checks of the built book; the checks in JupyterLab beside the last two
#   make notebooks          re-run every book page and compare its outputs with book/_nbval/
#   make notebooks-alone    execute every page once, alone in a folder of its own with only
#                           requirements.txt and the book's source archive installed (as a
#                           reader runs its download), into the execution cache the PDF and
#                           book builds read, and compare its outputs with book/_nbval/
#   make notebooks-standalone  run the notebook each page of the built book offers, alone in the
#                           same way, and compare its outputs with book/_nbval/
#   make notebooks-update   re-execute every page and rewrite book/_nbval/ (deliberate update)
#                           (PAGES="fig6 cite": only those pages, in these three targets)
#   make check-book         checks of the built book alone (equation numbers, browser)
#   make check-lab          checks of the pages in JupyterLab (needs no built book)
#   make records            compute again every study (and brute-force sum) the book reads from its record
#                           (depthcore/provenance/study_records/), then rewrite the references of
#                           the pages that read them
#   make figures            write the paper's figures to figures/
#   make bench              run every benchmark at full size, print its tables and write its
#                           record depthcore/provenance/benchmark_records/<script>.json; then rewrite the README's
#                           tables and the references of the pages that show the records
#                           (BENCH="bench_bank": that benchmark alone)
#   make lint               ruff check and ruff format --check of the package, tests, tools, benchmarks
#   make clean              remove build outputs (make distclean also removes .venv/)
#
# Every target runs in .venv/, created with Python 3.11 from the pinned
# requirements.txt (installed by uv) and rebuilt from scratch whenever requirements.txt changes;
# depthcore is (re)installed into it in editable mode when pyproject.toml or
# its version (depthcore/__init__.py) changes.
#
# The HTML and the PDF builds execute each page once between them: Jupyter
# Book's execution cache (_build/.jupyter_cache) keeps each page's outputs,
# emptied when depthcore, requirements.txt or CITATION.cff change and dropped
# for a page whose text changes; the pages it lacks are executed two at a time
# before the build (tools/check_notebooks.py cache --execute). In `make test`
# that execution is the drift check's (`make notebooks-alone`), so that each
# page runs once; `make book` after `make test` on an unchanged tree executes nothing.

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3 2>/dev/null)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EDITABLE := $(VENV)/.editable
PYTEST_ARGS ?=
# make notebooks / notebooks-update: only these pages (e.g. PAGES="fig6 cite"), all when empty.
PAGES ?=
# cffconvert (validates CITATION.cff) pins jsonschema 3: a venv of its own.
CITE_VENV := $(VENV)/cffconvert
CITE_STAMP := $(CITE_VENV)/.installed
# make notebooks-alone, notebooks-standalone: a venv with requirements.txt alone, into which the
# book's source archive is installed before each run.
ALONE_VENV := $(VENV)/standalone
ALONE_STAMP := $(ALONE_VENV)/.installed

# uv installs the pinned sets into the venvs (in seconds, where pip takes a minute); pip puts
# it, at this version, in a folder of its own, so that .venv/ holds requirements.txt alone:
# the pip of the Python that makes .venv/ when it has one (run with the bytecode that Python
# keeps beside it, not compiled again into .venv/pycache/), else one that ensurepip first
# installs into .venv/ (some 7 s more).
UV_PIN := uv==0.13.9
UV_HOME := $(VENV)/uv
UV := $(UV_HOME)/bin/uv
# Python caches the bytecode it compiles in .venv/pycache/, even where PYTHONDONTWRITEBYTECODE
# is set: otherwise every process (each page's kernel, each Sphinx build, each test worker)
# compiles NumPy, SciPy, Matplotlib and Sphinx again, some 3 s each.
unexport PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX := $(CURDIR)/$(VENV)/pycache

# Kernels and tools run from .venv/ even where a user-wide Jupyter setup exists.
export JUPYTER_PREFER_ENV_PATH := 1
export PYDEVD_DISABLE_FILE_VALIDATION := 1
export PIP_DISABLE_PIP_VERSION_CHECK := 1
# The book's pages run with the python3 kernel of tools/jupyter/kernels/ (ipykernel
# without its notice about local TCP, which would repeat once per page in the logs),
# also installed into .venv/ for Jupyter run from .venv/ outside make.
export JUPYTER_PATH := $(CURDIR)/tools/jupyter$(if $(JUPYTER_PATH),:$(JUPYTER_PATH))
KERNEL := $(VENV)/share/jupyter/kernels/python3

.PHONY: help venv cite-venv downloads book html-build pdf pdf-build books books-html books-xelatex lab test core test-core notebooks notebooks-update notebooks-standalone notebooks-alone check-book check-lab figures records bench clean distclean

help:
	@sed -n '3,/^#$$/p' Makefile | sed -e 's/^# \{0,1\}//' -e '/^$$/d'

$(STAMP): requirements.txt
	@test -n "$(PYTHON)" || { echo "make: no python3.11 or python3 on PATH" >&2; exit 1; }
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' || \
	  { echo "make: Python 3.11 is required, $(PYTHON) is $$($(PYTHON) --version 2>&1); set PYTHON=/path/to/python3.11" >&2; exit 1; }
	rm -rf $(VENV)
	$(PYTHON) -m venv --without-pip $(VENV)
	env -u PYTHONPYCACHEPREFIX $(PYTHON) -m pip install -q --no-compile --no-deps --target $(UV_HOME) \
	  $(UV_PIN) 2>/dev/null || { rm -rf $(UV_HOME); \
	  $(PY) -m ensurepip > /dev/null && $(PY) -m pip install -q --target $(UV_HOME) $(UV_PIN); }
	$(UV) pip install -q --python $(PY) -r requirements.txt
	touch $(STAMP)

$(KERNEL)/.installed: $(STAMP) $(wildcard tools/jupyter/kernels/python3/*)
	mkdir -p $(KERNEL)
	cp tools/jupyter/kernels/python3/kernel.json tools/jupyter/kernels/python3/launch.py $(KERNEL)/
	touch $@

$(EDITABLE): $(STAMP) $(KERNEL)/.installed pyproject.toml depthcore/__init__.py
	$(UV) pip install -q --python $(PY) --no-deps --no-build-isolation -e .
	touch $(EDITABLE)

venv: $(EDITABLE)

$(CITE_STAMP): requirements-cite.txt $(STAMP)
	rm -rf $(CITE_VENV)
	$(PYTHON) -m venv --without-pip $(CITE_VENV)
	$(UV) pip install -q --python $(CITE_VENV)/bin/python -r requirements-cite.txt
	touch $(CITE_STAMP)

cite-venv: $(CITE_STAMP)

# The packages are those .venv/ installed from requirements.txt, copied rather than
# installed again; depthcore's editable install is left out. Before each run the pins
# are checked against requirements.txt (and installed if unmet; a package not pinned is
# an error) and the source archive is installed (tools/check_notebooks.py).
SITE := lib/python3.11/site-packages
$(ALONE_STAMP): requirements.txt $(STAMP)
	rm -rf $(ALONE_VENV)
	$(PYTHON) -m venv --without-pip $(ALONE_VENV)
	cp -a $(VENV)/$(SITE)/. $(ALONE_VENV)/$(SITE)/
	rm -rf $(ALONE_VENV)/$(SITE)/__editable__*depthcore* $(ALONE_VENV)/$(SITE)/depthcore-*.dist-info
	touch $(ALONE_STAMP)

# The HTML book ships, under _build/html/downloads/, what a reader takes away:
# Figures 2-6 as PDF, SVG and PNG, depthcore's source archive (with CITATION.cff
# inside the package, for the page "Cite this work" run alone) with the pinned
# requirements, and the PDF of the book when `make pdf` has built it (as
# `make test` does first). The pages' executed notebooks are offered on each page.
DOWNLOADS := _build/extra/downloads
PDF := _build/latex/depthcore.pdf

# The paper's figures for the downloads, written again when depthcore changes.
FIGURES := _build/figures
$(FIGURES)/.written: $(EDITABLE) $(shell find depthcore -type f ! -path '*/__pycache__/*')
	rm -rf $(FIGURES)
	$(PY) -m depthcore figures --out $(FIGURES)
	touch $@

# What the book offers for download, except the PDF (copied by `make book` when built).
downloads: $(EDITABLE) $(FIGURES)/.written
	rm -rf $(DOWNLOADS)
	mkdir -p $(DOWNLOADS)
	cp -r $(FIGURES) $(DOWNLOADS)/figures
	rm -f $(DOWNLOADS)/figures/.written
	cp CITATION.cff depthcore/CITATION.cff
	$(PY) -c 'from setuptools import build_meta; import sys; sys.stdout = sys.stderr; \
	  print(build_meta.build_sdist("$(DOWNLOADS)"))' 2>/dev/null || { rm -f depthcore/CITATION.cff; exit 1; }
	rm -f depthcore/CITATION.cff
	mv $(DOWNLOADS)/depthcore-*.tar.gz $(DOWNLOADS)/depthcore.tar.gz
	cp requirements.txt CITATION.cff $(DOWNLOADS)/

book: downloads
	$(clear-book)
	@if [[ -f $(PDF) ]]; then cp $(PDF) $(DOWNLOADS)/depthcore.pdf; else \
	  echo "make book: NOTE: $(PDF) not found, so the book does not offer the PDF: run \`make pdf\` first" >&2; fi
	$(PY) tools/check_notebooks.py cache --execute
	$(MAKE) --no-print-directory html-build

# What a build of the HTML book starts from: _build/ without the previous HTML build (the
# LaTeX build, the execution cache, the figures and the downloads are kept).
define clear-book
find _build -mindepth 1 -maxdepth 1 ! -name latex ! -name pdf ! -name .jupyter_cache ! -name figures \
  ! -name extra -exec rm -rf {} + 2>/dev/null || true
endef

# Sphinx's HTML build, from the execution cache (filled first by make book, make books).
html-build:
	$(VENV)/bin/jupyter-book build . --all -W -n --keep-going 2>&1 | tee _build/book.log

# Every page executed once, alone (a folder holding only its notebook, .venv/standalone/ with only the
# book's requirements.txt and source archive), into the execution cache that the
# PDF and HTML builds then read; its outputs compared with book/_nbval/.
# Every study a page reads must come from its record there (DEPTHCORE_RECORDS=require).
notebooks-alone: $(EDITABLE) $(ALONE_STAMP) downloads
	$(link-bytecode)
	DEPTHCORE_RECORDS=require $(PY) tools/check_notebooks.py cache --execute --python $(ALONE_VENV)/bin/python \
	  --uv $(UV)

# The bytecode Python has compiled for .venv/'s packages (in .venv/pycache/, under each source's
# path), linked for their copies in .venv/standalone/: the pages run alone then do not compile
# again what the tests before them compiled. Python checks each file against the size and time
# of its source, which the copy kept, and compiles again one whose source differs. (Copied
# where the file system makes no hard links.)
SITE_BYTECODE := $(PYTHONPYCACHEPREFIX)$(CURDIR)/$(VENV)/$(SITE)
ALONE_BYTECODE := $(PYTHONPYCACHEPREFIX)$(CURDIR)/$(ALONE_VENV)/$(SITE)
define link-bytecode
if [[ -d $(SITE_BYTECODE) ]]; then mkdir -p $(ALONE_BYTECODE); \
  cp -al --remove-destination $(SITE_BYTECODE)/. $(ALONE_BYTECODE)/ 2>/dev/null || \
  cp -a --remove-destination $(SITE_BYTECODE)/. $(ALONE_BYTECODE)/; fi
endef

# Sphinx's LaTeX builder, then xelatex (Debian: texlive-xetex texlive-latex-extra
# texlive-fonts-recommended lmodern latexmk fonts-freefont-otf; .ci/run installs them).
pdf: $(EDITABLE)
	$(check-tex)
	$(PY) tools/check_notebooks.py cache --execute
	$(MAKE) --no-print-directory pdf-build

define check-tex
@for tool in xelatex latexmk; do command -v $$tool >/dev/null || { \
  echo "make pdf: $$tool not found: the PDF needs TeX Live (Debian: apt-get install texlive-xetex" \
    "texlive-latex-extra texlive-fonts-recommended lmodern latexmk fonts-freefont-otf)" >&2; exit 1; }; done
endef

# make pdf: the LaTeX build reads every page itself (--all), keeping its doctrees and executed
# notebooks in _build/pdf/ (Jupyter Book puts them beside its output), apart from an HTML
# build's; its output then moves to _build/latex/, where xelatex writes the PDF.
LATEX_BUILD := _build/pdf
pdf-build:
	rm -rf _build/latex $(LATEX_BUILD)
	mkdir -p _build
	$(VENV)/bin/jupyter-book build . --builder latex --path-output $(LATEX_BUILD) --all -W -n \
	  --keep-going 2>&1 | tee _build/latex.log
	mv $(LATEX_BUILD)/_build/latex _build/latex
	$(xelatex)

# xelatex, through latexmk, on _build/latex/depthcore.tex (its images compressed at zlib's
# level 6, not 9: 3 s instead of 7, for a PDF 3 % larger).
define xelatex
cd _build/latex && latexmk -xelatex -interaction=nonstopmode -halt-on-error \
  -e '$$xdvipdfmx = "xdvipdfmx -z 6 -E -o %D %O %S"' depthcore.tex > latexmk.log 2>&1 || { tail -n 40 latexmk.log >&2; echo "make pdf: xelatex failed, see _build/latex/depthcore.log" >&2; exit 1; }
@echo "make pdf: wrote $(PDF)"
endef

# make books (make test's build of both): Sphinx reads every page once. Its LaTeX builder reads
# them (--all) from the execution cache that make notebooks-alone filled, keeping the doctrees
# in _build/.doctrees, and writes the LaTeX; then, side by side, xelatex writes the PDF and the
# HTML builder writes the book from those doctrees, finding every page up to date (it reads none
# again: 37 s instead of 54). The book links the PDF (DEPTHCORE_DOWNLOADS_PENDING, read by
# tools/sphinx/depthcore_book.py), which is copied into its downloads once xelatex has written it.
books: downloads
	$(check-tex)
	$(PY) tools/check_notebooks.py cache --execute
	$(clear-book)
	rm -rf _build/latex
	rm -f $(DOWNLOADS)/depthcore.pdf
	DEPTHCORE_DOWNLOADS_PENDING=depthcore.pdf $(VENV)/bin/jupyter-book build . --builder latex --all -W -n \
	  --keep-going 2>&1 | tee _build/latex.log
	DEPTHCORE_DOWNLOADS_PENDING=depthcore.pdf $(MAKE) -j2 --no-print-directory --output-sync=target \
	  books-html books-xelatex
	cp $(PDF) $(DOWNLOADS)/depthcore.pdf
	cp $(PDF) _build/html/downloads/depthcore.pdf

# make books' HTML build, from the doctrees its LaTeX build left, and its xelatex.
books-html:
	$(VENV)/bin/jupyter-book build . -W -n --keep-going 2>&1 | tee _build/book.log

books-xelatex:
	$(xelatex)

# JupyterLab from .venv/; jupytext opens the book's MyST pages (book/*.md) as
# notebooks with one click (tools/jupyter/lab/settings/overrides.json, copied
# into .venv/ where JupyterLab reads its defaults); jupytext.toml keeps a saved,
# unchanged page byte for byte. As root (many containers) with --allow-root,
# which JupyterLab otherwise refuses. LAB_ARGS, e.g. --no-browser.
LAB_ARGS ?=
lab: $(EDITABLE)
	mkdir -p $(VENV)/share/jupyter/lab/settings
	cp tools/jupyter/lab/settings/overrides.json $(VENV)/share/jupyter/lab/settings/overrides.json
	$(VENV)/bin/jupyter lab --ServerApp.root_dir=. $(if $(filter 0,$(shell id -u)),--allow-root) \
	  $(LAB_ARGS) book/intro.md

# make test's stages, one after the other, each one's time printed as it ends and all of them
# at the end. From the start of LAB_BESIDE on, the checks in JupyterLab (make check-lab: one
# browser and one kernel, no built book needed) run beside the stages that remain, filling
# the core that the builds leave idle (the LaTeX build reads the pages in one process, and
# the HTML build ends alone); their output is shown at the end.
TEST_STAGES := lint core notebooks-alone books check-book
LAB_BESIDE := books
test: $(EDITABLE)
	tools/system-packages.sh
	@lab_log=$$(mktemp); lab=; status=0; times=(); \
	for stage in $(TEST_STAGES); do \
	  if [[ $$stage == $(LAB_BESIDE) ]]; then \
	    { start=$$SECONDS; if $(MAKE) --no-print-directory check-lab > $$lab_log 2>&1; then s=0; \
	      else s=$$?; fi; echo "make test: check-lab took $$((SECONDS - start)) s" >> $$lab_log; \
	      exit $$s; } & lab=$$!; fi; \
	  start=$$SECONDS; if ! $(MAKE) --no-print-directory $$stage; then status=1; break; fi; \
	  times+=("$$stage $$((SECONDS - start)) s"); echo "make test: $$stage took $$((SECONDS - start)) s"; \
	done; \
	if [[ -n $$lab ]]; then wait $$lab || status=1; cat $$lab_log; fi; rm -f $$lab_log; \
	if [[ $$status != 0 ]]; then echo "make test: failed" >&2; exit 1; fi; \
	echo "make test: passed ($$(IFS=,; echo "$${times[*]}" | sed 's/,/, /g'); check-lab beside from $(LAB_BESIDE) on)"

# Two workers; one that runs out of tests takes the other's pending ones (worksteal), so that
# neither waits for the other at the end.
test-core: $(EDITABLE) $(CITE_STAMP)
	$(PY) -m pytest -q -rs -n 2 --dist worksteal tests $(PYTEST_ARGS)

# make test's first stage: the core tests and, beside them, the figures for the book's
# downloads and the venv that runs the pages alone (one process each, which would
# otherwise leave a core idle while the next stage waits for them).
core: $(EDITABLE)
	$(MAKE) -j2 --no-print-directory --output-sync=line test-core $(FIGURES)/.written $(ALONE_STAMP)

notebooks: $(EDITABLE)
	$(PY) tools/check_notebooks.py check $(PAGES)

notebooks-update: $(EDITABLE)
	$(PY) tools/check_notebooks.py update $(PAGES)

# The drift check of `make test`, on the built book's downloads (run `make book` first).
notebooks-standalone: $(EDITABLE) $(ALONE_STAMP)
	$(link-bytecode)
	$(PY) tools/check_notebooks.py standalone --python $(ALONE_VENV)/bin/python --uv $(UV) $(PAGES)

# Checks of the built book in _build/html (run `make book` first); the browser's checks of
# a page one after the other in one browser, every other page in each of two (test_browser.py).
check-book: $(EDITABLE)
	$(PY) -m pytest -q -rs -n 2 --dist loadscope tests/book --ignore=$(LAB_TESTS) $(PYTEST_ARGS)

# The pages run and opened in JupyterLab, in headless Chromium (no built book needed).
LAB_TESTS := tests/book/test_lab.py
check-lab: $(EDITABLE)
	$(PY) -m pytest -q -rs $(LAB_TESTS) $(PYTEST_ARGS)

figures: $(EDITABLE)
	$(PY) -m depthcore figures --out figures/

# The pages whose Monte Carlo studies and brute-force sums are read from their records
# (depthcore.provenance.records):
# `make records` removes every record, executes these pages once writing the records of the
# studies they compute (DEPTHCORE_RECORDS=write), then once more reading them, to rewrite
# their references. tests/test_study_records.py fails when a record is stale.
RECORD_PAGES := marginals discrepancies beyond_filters beyond_study beyond_sweeps beyond_frames beyond_bound beyond_hard beyond_conjecture
records: $(EDITABLE)
	rm -f depthcore/provenance/study_records/*.json
	DEPTHCORE_RECORDS=write $(PY) tools/check_notebooks.py update $(RECORD_PAGES)
	$(PY) tools/check_notebooks.py update $(RECORD_PAGES)

# The book's pages that show the benchmarks' records (references rewritten by make bench).
BENCH_PAGES := marginals beyond_cost beyond_frames
# make bench: only these benchmarks (e.g. BENCH="bench_bank"), all when empty.
BENCH ?= $(basename $(notdir $(wildcard benchmarks/bench_*.py)))

bench: $(EDITABLE)
	@for b in $(BENCH); do echo "== benchmarks/$$b.py"; \
	  TIMEFORMAT="$$b took %R s"; time $(PY) benchmarks/$$b.py; done
	$(PY) tools/readme.py
	$(PY) tools/check_notebooks.py update $(BENCH_PAGES)

.PHONY: lint
lint: $(EDITABLE)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf _build figures .pytest_cache .hypothesis book/.nbval-check-*
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) *.egg-info

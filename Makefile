# depthcore: the package, its tests and the executable book. `make help` lists the targets a
# reader runs (book and test first); the others, without help text, are steps of those, and
# the book's appendix "Reproducing this book" says more.
#
# Every target runs in .venv/ (Python 3.11 and the pins of requirements.txt), depthcore
# installed editable. Each build executes each page once, through Jupyter Book's cache.

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3 2>/dev/null)
VENV := .venv
PY := $(VENV)/bin/python
UV := $(VENV)/uv/bin/uv
STAMP := $(VENV)/.installed
EDITABLE := $(VENV)/.editable
PYTEST_ARGS ?=
PAGES ?=
CITE_VENV := $(VENV)/cffconvert# cffconvert (checks CITATION.cff) pins jsonschema 3: a venv of its own
ALONE_VENV := $(VENV)/standalone# the pages run alone: requirements.txt and the source archive
SITE := lib/python3.11/site-packages

# Bytecode kept in .venv/pycache/, so that no page's kernel or test worker compiles it again.
unexport PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX := $(CURDIR)/$(VENV)/pycache
# Jupyter runs from .venv/, with the book's kernel (tools/jupyter/), whatever else is set up.
export JUPYTER_PREFER_ENV_PATH := 1
export PYDEVD_DISABLE_FILE_VALIDATION := 1
export PIP_DISABLE_PIP_VERSION_CHECK := 1
export JUPYTER_PATH := $(CURDIR)/tools/jupyter$(if $(JUPYTER_PATH),:$(JUPYTER_PATH))
KERNEL := $(VENV)/share/jupyter/kernels/python3

.PHONY: help venv book book-html pdf pdf-latex builds builds-html builds-xelatex downloads lab test \
  article core core-and-setup lint notebooks notebooks-kernels notebooks-update notebooks-alone \
  check-downloads check-book check-lab figures records atlas bench clean distclean

help: ## this list of the targets a reader runs
	@awk -F ':.*## ' '/^[a-z-]+:.*## /{printf "  make %-21s %s\n", $$1, $$2}' Makefile

$(STAMP): requirements.txt
	tools/make-venv.sh "$(PYTHON)" $(VENV) $(VENV)/uv requirements.txt
	touch $@

$(KERNEL)/.installed: $(STAMP) $(wildcard tools/jupyter/kernels/python3/*)
	mkdir -p $(KERNEL)
	cp tools/jupyter/kernels/python3/kernel.json tools/jupyter/kernels/python3/launch.py $(KERNEL)/
	touch $@

$(EDITABLE): $(STAMP) $(KERNEL)/.installed pyproject.toml depthcore/__init__.py depthbook/pyproject.toml
	$(UV) pip install -q --python $(PY) --no-deps --no-build-isolation -e . -e depthbook
	touch $@

# .venv/ with the pins, depthcore and the book's depthbook installed editable.
venv: $(EDITABLE)

$(CITE_VENV)/.installed: requirements-cite.txt $(STAMP)
	tools/make-venv.sh "$(PYTHON)" $(CITE_VENV) $(VENV)/uv requirements-cite.txt
	touch $@

# .venv/'s packages without depthcore and depthbook: their archives are installed before each run.
$(ALONE_VENV)/.installed: requirements.txt $(STAMP)
	rm -rf $(ALONE_VENV)
	$(PYTHON) -m venv --without-pip $(ALONE_VENV)
	cp -a $(VENV)/$(SITE)/. $(ALONE_VENV)/$(SITE)/
	rm -rf $(ALONE_VENV)/$(SITE)/__editable__*depth{core,book}* $(ALONE_VENV)/$(SITE)/depth{core,book}-*.dist-info
	touch $@

DOWNLOADS := _build/extra/downloads
PDF := _build/latex/depthcore.pdf
FIGURES := _build/figures
LATEX_BUILD := _build/pdf
$(FIGURES)/.written: $(EDITABLE) $(shell find depthcore depthbook -type f ! -path '*/__pycache__/*')
	rm -rf $(FIGURES)
	$(PY) -m depthbook figures --out $(FIGURES)
	touch $@

downloads: $(EDITABLE) $(FIGURES)/.written
	tools/build-downloads.sh $(PY) $(FIGURES) $(DOWNLOADS)

# _build/ without the previous HTML build (the LaTeX build, cache, figures, downloads kept).
define clear-book
find _build -mindepth 1 -maxdepth 1 ! -name latex ! -name pdf ! -name .jupyter_cache ! -name figures \
  ! -name extra ! -name article -exec rm -rf {} + 2>/dev/null || true
endef

book: downloads ## the book, built strictly into _build/html, with its downloads
	$(clear-book)
	@if [[ -f $(PDF) ]]; then cp $(PDF) $(DOWNLOADS)/depthcore.pdf; else \
	  echo "make book: NOTE: no $(PDF), so the book offers no PDF: run \`make pdf\` first" >&2; fi
	@if [[ -f $(ARTICLE_PDF) ]]; then cp $(ARTICLE_PDF) $(DOWNLOADS)/article.pdf; else \
	  echo "make book: NOTE: no $(ARTICLE_PDF), so the book offers no article: run \`make article\` first" >&2; fi
	$(PY) tools/check_notebooks.py cache --execute
	$(MAKE) --no-print-directory book-html

book-html:
	$(VENV)/bin/jupyter-book build . --all -W -n --keep-going 2>&1 | tee _build/book.log

pdf: $(EDITABLE) ## the book as a PDF, _build/latex/depthcore.pdf (needs xelatex)
	tools/xelatex.sh --check
	$(PY) tools/check_notebooks.py cache --execute
	$(MAKE) --no-print-directory pdf-latex

pdf-latex:
	rm -rf _build/latex $(LATEX_BUILD)
	mkdir -p _build
	$(VENV)/bin/jupyter-book build . --builder latex --path-output $(LATEX_BUILD) --all -W -n \
	  --keep-going 2>&1 | tee _build/latex.log
	mv $(LATEX_BUILD)/_build/latex _build/latex
	tools/xelatex.sh _build/latex

# The LaTeX builder reads every page once; xelatex and the HTML builder then share its doctrees
# (and the article is typeset beside them).
SHIPPED_PDFS := depthcore.pdf article.pdf
# make test's builds: the PDF, the article and the book from one reading of the pages.
builds: downloads
	tools/xelatex.sh --check
	$(PY) tools/check_notebooks.py cache --execute
	$(clear-book)
	rm -rf _build/latex
	rm -f $(DOWNLOADS)/depthcore.pdf $(DOWNLOADS)/article.pdf
	DEPTHCORE_DOWNLOADS_PENDING="$(SHIPPED_PDFS)" $(VENV)/bin/jupyter-book build . --builder latex --all \
	  -W -n --keep-going 2>&1 | tee _build/latex.log
	DEPTHCORE_DOWNLOADS_PENDING="$(SHIPPED_PDFS)" $(MAKE) -j2 --no-print-directory --output-sync=target \
	  builds-html builds-xelatex article
	cp $(PDF) $(ARTICLE_PDF) $(DOWNLOADS)/
	cp $(PDF) $(ARTICLE_PDF) _build/html/downloads/

builds-html:
	$(VENV)/bin/jupyter-book build . -W -n --keep-going 2>&1 | tee _build/book.log

builds-xelatex:
	tools/xelatex.sh _build/latex

# The replication article: its numbers checked against the computations, then typeset.
ARTICLE := _build/article
ARTICLE_PDF := $(ARTICLE)/article.pdf
article: $(EDITABLE) ## the replication article, _build/article/article.pdf (needs xelatex)
	tools/xelatex.sh --check
	$(PY) tools/article.py build --out $(ARTICLE)

LAB_ARGS ?=# e.g. --no-browser; the MyST pages open as notebooks (tools/jupyter/lab/settings/)
lab: $(EDITABLE) ## JupyterLab on the book's pages, which open as notebooks
	mkdir -p $(VENV)/share/jupyter/lab/settings
	cp tools/jupyter/lab/settings/overrides.json $(VENV)/share/jupyter/lab/settings/overrides.json
	$(VENV)/bin/jupyter lab --ServerApp.root_dir=. $(if $(filter 0,$(shell id -u)),--allow-root) \
	  $(LAB_ARGS) book/intro.md

# The stages of make test, in order; the checks in JupyterLab run beside them from LAB_BESIDE on.
TEST_STAGES := lint core-and-setup notebooks-alone builds check-book
LAB_BESIDE := builds
test: $(EDITABLE) ## every check: lint, core, pages alone, PDF and book, built book, JupyterLab
	tools/system-packages.sh
	tools/run-stages.sh check-lab $(LAB_BESIDE) $(TEST_STAGES)

core: $(EDITABLE) $(CITE_VENV)/.installed ## the package's tests only, the quick check (PYTEST_ARGS="-k ekf": some)
	$(PY) -m pytest -q -rs -n 2 --dist worksteal tests $(PYTEST_ARGS)

# make test's first stage: core beside the figures and the venv of the pages run alone, which
# the later stages need (both cores busy).
core-and-setup: $(EDITABLE)
	$(MAKE) -j2 --no-print-directory --output-sync=line core $(FIGURES)/.written \
	  $(ALONE_VENV)/.installed

# ruff check and ruff format --check.
lint: $(EDITABLE)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

notebooks: $(EDITABLE) ## re-run the pages, compare with book/_nbval/ (PAGES="fig6": one)
	$(PY) tools/check_notebooks.py check $(PAGES)

# The page checks once per kernel set of another processor (tools/kernel_sets.py: OpenBLAS's
# Nehalem, Haswell and SkylakeX kernels, those this processor can run and are not its own,
# Sandybridge or Prescott standing in where fewer than two can, and NumPy's baseline SIMD),
# the studies read from their records: a reference that holds what only this processor's
# kernels print fails here. .ci/run runs it after make test.
notebooks-kernels: $(EDITABLE)
	DEPTHCORE_RECORDS=require $(PY) tools/kernel_sets.py -- $(PY) tools/check_notebooks.py check $(PAGES)

# The pages re-run, book/_nbval/ rewritten from them (PAGES too).
notebooks-update: $(EDITABLE)
	$(PY) tools/check_notebooks.py update $(PAGES)

# Each page run once, alone as a reader runs a download, into the builds' cache and compared
# with book/_nbval/, its studies read from their records; .venv/'s bytecode linked for its copy.
link-bytecode = tools/link-bytecode.sh $(PYTHONPYCACHEPREFIX)$(CURDIR)/{$(VENV),$(ALONE_VENV)}/$(SITE)
notebooks-alone: $(EDITABLE) $(ALONE_VENV)/.installed downloads
	$(link-bytecode)
	DEPTHCORE_RECORDS=require $(PY) tools/check_notebooks.py cache --execute --python $(ALONE_VENV)/bin/python \
	  --uv $(UV)

# The built book's downloadable notebooks, each run alone (make book first; not in make test,
# which executes each page once, in notebooks-alone).
check-downloads: $(EDITABLE) $(ALONE_VENV)/.installed
	$(link-bytecode)
	$(PY) tools/check_notebooks.py standalone --python $(ALONE_VENV)/bin/python --uv $(UV) $(PAGES)

LAB_TESTS := tests/book/test_lab.py
# Checks of the built book (make book first), in a headless browser.
check-book: $(EDITABLE)
	$(PY) -m pytest -q -rs -n 2 --dist loadscope tests/book --ignore=$(LAB_TESTS) $(PYTEST_ARGS)

# The pages run and opened in JupyterLab, in a headless browser.
check-lab: $(EDITABLE)
	$(PY) -m pytest -q -rs $(LAB_TESTS) $(PYTEST_ARGS)

figures: $(EDITABLE) ## the paper's figures into figures/
	$(PY) -m depthbook figures --out figures/

# The pages that read studies from their records: executed writing them, then reading them.
RECORD_PAGES := marginals discrepancies beyond_filters beyond_particles beyond_study beyond_sweeps beyond_frames beyond_bound beyond_hard beyond_conjecture beyond_atlas related intro conclusions reproducing
# Their studies' chunks run on a local Dask cluster of every core (tools/cluster.py).
# The new records are written beside the committed ones, which they replace only once every
# page has run (tools/records.py): an interrupted run leaves the committed set, and the pages'
# references, as they were.
records: $(EDITABLE) ## every study the book reads from a record, again (and the README and article)
	$(PY) tools/records.py -- $(PY) tools/cluster.py $(PY) tools/check_notebooks.py update $(RECORD_PAGES)
	$(PY) tools/check_notebooks.py update $(RECORD_PAGES)
	$(PY) tools/readme.py
	$(PY) tools/article.py write

# The atlas's record alone (book/beyond_atlas.md; about 80 minutes on 2 cores), the other
# records kept; then the pages, the README and the article that read it.
ATLAS_PAGES := beyond_atlas conclusions reproducing
atlas: $(EDITABLE) ## the atlas's record alone, again (and the pages, README and article)
	$(PY) tools/records.py --keep -- $(PY) tools/cluster.py \
	  $(PY) -c "from depthbook import beyond_atlas; beyond_atlas.runs()"
	$(PY) tools/check_notebooks.py update $(ATLAS_PAGES)
	$(PY) tools/readme.py
	$(PY) tools/article.py write

# The pages that read the benchmarks' records.
BENCH_PAGES := marginals beyond_cost beyond_filters beyond_frames intro conclusions reproducing
BENCH ?= $(basename $(notdir $(wildcard benchmarks/bench_*.py)))
bench: $(EDITABLE) ## every benchmark and its record (BENCH="bench_bank": one)
	@for b in $(BENCH); do echo "== benchmarks/$$b.py"; \
	  TIMEFORMAT="$$b took %R s"; time $(PY) benchmarks/$$b.py; done
	$(PY) tools/readme.py
	$(PY) tools/article.py write
	$(PY) tools/check_notebooks.py update $(BENCH_PAGES)

clean: ## remove the build outputs (make distclean also removes .venv/)
	rm -rf _build figures .pytest_cache .hypothesis book/.nbval-check-*
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV) *.egg-info

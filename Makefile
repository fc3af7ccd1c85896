# coursekit: the two commands a student needs are `make demo` and `make test`.
# Every target installs what a fresh machine lacks (a .venv with environment.txt, and for the
# browser tests Debian's chromium when we are root), so a fresh clone needs nothing else.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup demo lab test test-fast exercises bench clean browser sandbox

# The notebooks' kernel, installed inside .venv (never over the user's own "python3" kernelspec).
KERNEL := coursekit
# nbstripout's output-stripping git filter; --keep-id keeps the notebooks' cell ids, and the extra
# keys are what JupyterLab adds on save, so after a Run All `git status` stays clean.
NBSTRIP_CLEAN := "$(abspath $(PY))" -m nbstripout --keep-id
NBSTRIP_KEYS  := metadata.language_info metadata.jupytext metadata.toc cell.metadata.lines_to_next_cell

# Packages whose bytecode setup writes by importing them once (below).
WARM_IMPORTS := torch matplotlib.pyplot scipy.stats scipy.optimize gymnasium pymunk shapely mujoco meshcat \
  PIL.Image tqdm safetensors.torch psutil pyarrow jupyterlab jupyter_server.serverapp ipywidgets \
  ipykernel.kernelapp nbclient nbformat nbstripout jupytext pytest xdist hypothesis diffusers importlinter \
  anywidget playwright.sync_api

# pip byte-compiles every file it installs (about 16 000, 90 s of one core); the course imports
# about 3 700 of them. So: install without compiling, then import the stack once with bytecode
# writing on (PYTHONDONTWRITEBYTECODE= overrides a user's 1 for this command only), which writes
# exactly the .pyc files every later process reads. Anything else compiles on first import.
$(STAMP): environment.txt pyproject.toml Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q --no-compile -r environment.txt
	$(PY) -m pip install -q --no-compile --no-deps --no-build-isolation -e .
	PYTHONDONTWRITEBYTECODE= $(PY) -c "import importlib, pkgutil, coursekit; \
	  [importlib.import_module(m) for m in '$(WARM_IMPORTS)'.split()]; \
	  [importlib.import_module(m.name) for m in pkgutil.walk_packages(coursekit.__path__, 'coursekit.') \
	   if not m.name.endswith('__main__')]"
	$(PY) -m ipykernel install --sys-prefix --name $(KERNEL) --display-name "Python (coursekit)" >/dev/null
	@if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then \
	  $(VENV)/bin/nbstripout --install && \
	  git config filter.nbstripout.clean '$(NBSTRIP_CLEAN)' && \
	  git config diff.ipynb.textconv '$(NBSTRIP_CLEAN) -t' && \
	  git config filter.nbstripout.extrakeys '$(NBSTRIP_KEYS)'; \
	fi
	@touch $(STAMP)

setup: $(STAMP)

## The end-to-end tour: demonstrations, a replay, a meshcat HTML and a figure under outputs/.
demo: setup
	$(VENV)/bin/coursekit demo

## JupyterLab on the course notebooks.
## Course notebooks are saved without outputs (coursekit/notebook_save.py): git stays clean.
lab: setup
	$(VENV)/bin/jupyter lab notebooks/ --ContentsManager.pre_save_hook=coursekit.notebook_save.strip_before_save \
	  $(if $(filter 0,$(shell id -u)),--allow-root,)

## Debian's chromium for the real-browser tests (only when missing and we are root).
browser:
	@if ! command -v chromium >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = "0" ]; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	      || echo "WARNING: could not install chromium; browser tests will be skipped"; \
	  else echo "WARNING: chromium missing and not root; browser tests will be skipped"; fi; \
	fi

## Debian's bubblewrap, the grader's OS sandbox (only when missing and we are root).
sandbox:
	@if ! command -v bwrap >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = "0" ]; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq bubblewrap >/dev/null) \
	      || echo "WARNING: could not install bubblewrap; grading will run without OS isolation"; \
	  else echo "WARNING: bwrap missing and not root; grading will run without OS isolation"; fi; \
	fi

## Test workers (pytest-xdist): two, one per core of the course's reference laptop; JOBS=1 runs serially.
JOBS ?= 2
XDIST := $(if $(filter 1,$(JOBS)),,-n $(JOBS) --dist loadscope --no-loadscope-reorder)

## The whole suite: library, exercises (both implementations), grader, notebooks, browser.
test: setup browser sandbox
	COURSEKIT_FAST=1 COURSEKIT_EXERCISES=solutions $(PY) -m pytest -q $(XDIST) --durations=25

## Everything but notebooks, real-browser and slow tests (slow: over ~20 s on 2 cores, e.g. the
## shipped-checkpoint reproductions).
test-fast: setup
	COURSEKIT_FAST=1 $(PY) -m pytest -q $(XDIST) -m "not slow and not notebook and not browser"

## Regenerate exercises/ and solutions/ from the marked library code.
exercises: setup
	$(VENV)/bin/coursekit exercises build

## Speed and quality measurements; they write benchmarks/results.json and the README table.
bench: setup
	$(PY) -m benchmarks.run_all

clean:
	rm -rf outputs .pytest_cache

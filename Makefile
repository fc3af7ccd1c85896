# coursekit: the two commands a student needs are `make demo` and `make test`.
# Every target installs what a fresh machine lacks (a .venv with environment.txt, and for the
# browser tests Debian's chromium when we are root), so a fresh clone needs nothing else.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup demo lab test test-fast exercises bench clean browser sandbox

$(STAMP): environment.txt pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r environment.txt
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m ipykernel install --user --name python3 >/dev/null
	@touch $(STAMP)

setup: $(STAMP)

## The end-to-end tour: demonstrations, a replay, a meshcat HTML and a figure under outputs/.
demo: setup
	$(VENV)/bin/coursekit demo

## JupyterLab on the course notebooks.
lab: setup
	$(VENV)/bin/jupyter lab notebooks/ $(if $(filter 0,$(shell id -u)),--allow-root,)

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

## The whole suite: library, exercises (both implementations), grader, notebooks, browser.
test: setup browser sandbox
	COURSEKIT_FAST=1 COURSEKIT_EXERCISES=solutions $(PY) -m pytest -q --durations=15

## Everything but notebooks and slow tests.
test-fast: setup
	COURSEKIT_FAST=1 $(PY) -m pytest -q -m "not slow and not notebook and not browser"

## Regenerate exercises/ and solutions/ from the marked library code.
exercises: setup
	$(VENV)/bin/coursekit exercises build

## Speed and quality measurements; they write benchmarks/results.json and the README table.
bench: setup
	$(PY) -m benchmarks.run_all

clean:
	rm -rf outputs .pytest_cache

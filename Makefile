# Two commands on a fresh machine: `make demo` and `make test` (both install into .venv first).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
DEMO_HOME ?= $(CURDIR)/demo-home
PYTEST_ARGS ?=
# the suite runs a pytest-xdist worker a core (at most 4; each takes its share of the cores for torch,
# tests/conftest.py), a test file to a worker (its module fixtures built once); TEST_WORKERS=0: one process
TEST_WORKERS ?= auto
XDIST := -n $(TEST_WORKERS) --maxprocesses 4 --dist loadfile

.PHONY: install browser demo test test-all lint typecheck bench bench-scale clean serve

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip setuptools wheel
	# torch first and pinned: this machine has the CPU wheel on disk; a looser pin pulls CUDA builds.
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	SITELINE_HOME=$(DEMO_HOME) $(VENV)/bin/siteline demo

# the page tests (release browser, 3D viewer, the Prefect UI) open pages in headless Chromium: Debian's is
# installed where it is missing (a test that cannot start it fails; SITELINE_SKIP_BROWSER=1 skips them)
browser:
	command -v chromium >/dev/null || ! command -v apt-get >/dev/null || { apt-get update -q && apt-get install -y -q chromium; } || true

test: $(STAMP) browser
	$(VENV)/bin/pytest $(XDIST) $(PYTEST_ARGS)

test-all: $(STAMP) browser
	$(VENV)/bin/pytest -m "" $(XDIST) $(PYTEST_ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# mypy over platform/siteline ([tool.mypy] in pyproject.toml)
typecheck: $(STAMP)
	$(VENV)/bin/mypy

bench: $(STAMP)
	for b in bench/*.py; do n=$$(basename $$b .py); [ $$n = paper_scale ] || [ $$n = __init__ ] || $(PY) -m bench.$$n || exit 1; done

# one 2-epoch pair at 1000 points/m2 and at 250, 300 views (tens of minutes on 2 cores)
bench-scale: $(STAMP)
	$(PY) bench/paper_scale.py

clean:
	rm -rf $(VENV) $(DEMO_HOME) .pytest_cache .ruff_cache .hypothesis

serve: $(STAMP)
	deploy/serve.sh

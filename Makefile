# Two commands from a fresh clone: `make run` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/ehss reproduce --out report

test: $(STAMP)
	@# the dashboard's browser test needs Debian's chromium + chromium-driver; install them
	@# when missing and root, quietly; otherwise those tests skip with the reason
	@-if ! command -v chromedriver >/dev/null 2>&1 && [ "$$(id -u)" = 0 ] \
	    && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1 \
	     || (apt-get update -qq >/dev/null 2>&1 \
	         && apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1)) || true; fi
	@# everything but the realtime tests on every core, then those alone (their pacing by
	@# the wall clock must not compete for the cores); one fresh numba cache for both.
	@# Each test goes to whichever core is free (worksteal): a file of long tests on one
	@# core no longer keeps the other idle at the end
	cache=$$(mktemp -d) && trap 'rm -rf "$$cache"' EXIT \
	    && export EHSS_TEST_NUMBA_CACHE="$$cache" \
	    && $(BIN)/python -m pytest -q -n auto --dist worksteal -m "not realtime" \
	    && $(BIN)/python -m pytest -q -m realtime

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/mypy

# The peers (SIPPY, sysidentpy, padasip) pin older numpy: they get a venv of their own.
BENCH := .venv-bench/bin

$(BENCH)/python:
	$(PYTHON) -m venv .venv-bench
	$(BENCH)/python -m pip install --quiet --upgrade pip
	$(BENCH)/python -m pip install --quiet -e '.[dev,bench]'

bench: $(BENCH)/python
	$(BENCH)/python benchmarks/bench_simulation.py
	$(BENCH)/python benchmarks/bench_rels.py
	$(BENCH)/python benchmarks/bench_batch.py
	$(BENCH)/python benchmarks/bench_io.py
	$(BENCH)/python benchmarks/bench_compensation.py
	$(BENCH)/python benchmarks/bench_live.py

clean:
	rm -rf $(VENV) .venv-bench report build src/*.egg-info

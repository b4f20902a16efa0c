# make install: torch (CPU wheel) first, then the package with its dev extras.
# make test:    the whole test suite (what CI runs).
PYTHON ?= python3
PIP = $(PYTHON) -m pip

.PHONY: install test test-fast bench

install:
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"

test:
	$(PYTHON) -m pytest -q -n 2 --max-worker-restart=0 tests

test-fast:
	$(PYTHON) -m pytest -q -m "not slow" tests

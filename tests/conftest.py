"""Shared fixtures (Hydra composition, a built Pendulum task) and the suite's timing: `--store-durations PATH`
writes each test's seconds (make durations: tests/durations.json), and under xdist the tests start longest first
by that file, so that the two workers of make test finish together instead of one running a long test alone
at the end. Tests marked xdist_group (those sharing a module fixture) run on one worker as one unit."""

import atexit
import copy
import functools
import json
import os
import shutil
import tempfile
from collections import defaultdict
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
# before jax is imported (tests compile MJX on the CPU): a compiled MJX loop on the CPU has hung without it. (Without
# XLA's backend optimisations the tiny models' tests compiled in half the time, but FrankaCabinet's took 883 s
# against 122 s: not used.)
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
# JAX's persistent compilation cache, one per process of the suite (its subprocesses inherit it): tests build many
# simulators of the same tiny models, and a new simulator's programs are compiled again where JAX's in-memory cache
# misses (docs/benchmarks.md, "the suite's cheaper parts"). Every program, the small ones too.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="bayessim-tests-jax-")
    atexit.register(shutil.rmtree, os.environ["JAX_COMPILATION_CACHE_DIR"], ignore_errors=True)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")


def _pin_worker() -> None:
    """Each xdist worker (and what it starts) on its own share of the CPUs, so that simulation threads left at 0
    (the process's CPUs, sim/native.py) add up to the machine, not to workers times CPUs: 8 workers on a 64-core
    machine ran 500-800 threads each, a load average above 300."""
    worker, count = os.environ.get("PYTEST_XDIST_WORKER"), int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if not hasattr(os, "sched_setaffinity"):  # Linux only
        return
    cpus = sorted(os.sched_getaffinity(0))
    share = len(cpus) // count if worker and count else 0
    if share:
        index = int(worker.removeprefix("gw"))
        os.sched_setaffinity(0, cpus[index * share:(index + 1) * share])


_pin_worker()

DURATIONS = Path(__file__).with_name("durations.json")


@functools.cache
def _composed(overrides: tuple[str, ...]):
    from bayessim_exp.api import compose

    return compose(list(overrides))


@pytest.fixture
def compose():
    """compose(overrides) -> the config the CLI would build: a copy of the one composed once per process (Hydra
    takes about 0.6 s a composition; many tests compose the same overrides)."""
    return lambda overrides=None: copy.deepcopy(_composed(tuple(overrides or ())))


@pytest.fixture
def pendulum(compose):
    from bayessim_exp import registry

    return registry.build("task", compose([]).task)


def pytest_addoption(parser):
    parser.addoption("--store-durations", metavar="PATH",
                     help="write each test's seconds (setup, call and teardown) to PATH as JSON, by node id")


def _test_id(nodeid: str) -> str:
    """The node id without the @group that xdist's loadgroup appends (as xdist splits it)."""
    return nodeid.rsplit("@", 1)[0] if nodeid.rfind("@") > nodeid.rfind("]") else nodeid


def _unit(item) -> str:
    """What one worker runs in a row: an xdist_group's tests, or the test alone."""
    group = item.get_closest_marker("xdist_group")
    return f"@{group.args[0]}" if group else _test_id(item.nodeid)


def pytest_collection_modifyitems(config, items):
    if not hasattr(config, "workerinput") or not DURATIONS.is_file():  # xdist's workers collect and must agree
        return
    seconds = json.loads(DURATIONS.read_text())
    total = defaultdict(float)
    for item in items:
        total[_unit(item)] += seconds.get(_test_id(item.nodeid), 0.0)
    first = {}
    for i, item in enumerate(items):
        first.setdefault(_unit(item), i)
    # longest unit first (a test not yet timed last); a unit's tests together, in pytest's order
    order = {id(item): (-total[_unit(item)], first[_unit(item)], i) for i, item in enumerate(items)}
    items.sort(key=lambda item: order[id(item)])


_seconds: dict[str, float] = defaultdict(float)


def pytest_runtest_logreport(report):
    _seconds[_test_id(report.nodeid)] += report.duration  # the controller sees every worker's reports


def pytest_sessionfinish(session):
    path = session.config.getoption("--store-durations")
    if path and not hasattr(session.config, "workerinput"):  # the controller writes, once
        Path(path).write_text(json.dumps({k: round(v, 2) for k, v in sorted(_seconds.items())}, indent=1) + "\n")

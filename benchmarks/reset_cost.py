"""Seconds per MjxSimulator reset of every slot, split into the host's share and the compiled reset's.

    python benchmarks/reset_cost.py [--tasks Pendulum,Cartpole] [--envs 131072] [--reps 3] [--host-constants] [--impl jax]

`host s` is the reset's wall time less the compiled reset (new leaves, fresh data and a forward pass,
timed to completion): drawing the initial states, building the slot arrays, any mujoco.batch set_const
and the uploads. `--host-constants` sends every derived constant through mujoco.batch's set_const on the
host and uploads them whole: the path before mjx_constants, kept as its fallback. Run against an older
checkout (PYTHONPATH=<it>/src) to measure its resets the same way. Each figure is the median of `--reps`
resets after a first (compiling) one.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402
import numpy as np  # noqa: E402

from bayessim_exp import api, registry  # noqa: E402
from bayessim_exp.sim import mjx as mjx_sim  # noqa: E402
from bayessim_exp.sim import mjx_constants  # noqa: E402


def timed_resets(sim, params: np.ndarray, reps: int) -> tuple[float, float]:
    """(median wall s, median compiled-reset s) per reset of every slot, after a first one."""
    compiled, inner = [], sim._reset_fn

    def blocking(*args):  # the compiled reset, run to completion and timed
        t0 = time.perf_counter()
        out = jax.block_until_ready(inner(*args))
        compiled.append(time.perf_counter() - t0)
        return out

    sim._reset_fn = blocking
    walls = []
    for _ in range(reps + 1):
        t0 = time.perf_counter()
        sim.reset(params, seed=1)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls[1:]), statistics.median(compiled[1:])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", default="Pendulum,Cartpole")
    ap.add_argument("--envs", type=int, default=131072)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--host-constants", action="store_true")
    ap.add_argument("--impl", default="jax", help="sim.impl: jax, warp or auto")
    args = ap.parse_args()
    if args.host_constants:  # the fallback for every constant
        mjx_constants.host_reasons = lambda m, names: dict.fromkeys(names, "--host-constants")
    base = mjx_sim.MjxConfig(max_abs_qvel=1.0e4, cache_dir=None, nthread=0, native_below=0, impl=args.impl, tuning={})
    print(f"device {jax.devices()[0]}, sim.impl={args.impl}, {args.envs} slots, median of {args.reps} resets"
          f"{' (constants on the host)' if args.host_constants else ''}")
    print(f"{'task':<12} {'impl':<5} {'wall s':>8} {'compiled s':>11} {'host s':>8}")
    for name in args.tasks.split(","):
        composed = api.compose([f"task={name}", "sim=mjx"])
        task = registry.build("task", composed.task)
        cfg = dataclasses.replace(base, tuning=dict(composed.sim.tuning))  # the task's MJX tuning (conf/mjx_tuning)
        params = np.random.default_rng(0).uniform(task.spec.low, task.spec.high, (args.envs, task.spec.dim))
        sim = mjx_sim.MjxSimulator(task, args.envs, cfg)
        wall, compiled = timed_resets(sim, params, args.reps)
        print(f"{name:<12} {sim.impl.name:<5} {wall:8.3f} {compiled:11.3f} {wall - compiled:8.3f}", flush=True)
        jax.clear_caches()


if __name__ == "__main__":
    main()

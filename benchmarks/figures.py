"""What a run's TensorBoard figures cost (logging/plots.py, logging/tensorboard.py), against the way they were drawn
before commit f04e498, in the same call:

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/figures.py [--repeats 5] [--runs 3]

1. Each figure a run draws, to PNG: laid out with fixed margins (now) and with matplotlib's tight_layout on top
   (the layout before), the best of --repeats, in seconds.
2. A `debug=smoke` Pendulum run in a process that may use one CPU (a pinned test worker, a one-core job): its wall
   and CPU seconds (the run's process and its children) with the figures drawn in the run's process (now) and in a
   spawned drawing process (before), the median of --runs each.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np


def figures() -> dict:
    """name -> a function drawing it (the shapes of a Pendulum run's, and of a 24-parameter task's)."""
    from bayessim_exp.logging import plots

    rng = np.random.default_rng(0)

    def pair(d):
        samples, prior = 0.5 + 0.3 * rng.normal(size=(5000, d)), rng.uniform(-3, 3, size=(5000, d))
        return lambda: plots.pair_plot(samples, [f"param_{i}" for i in range(d)], -3 * np.ones(d), 3 * np.ones(d),
                                       np.full(d, 0.4), "posterior, round 1", prior)

    def replay(n, s, steps):
        real, post, prior = (rng.normal(size=shape) for shape in [(n, steps, s), (n, 20, steps, s), (n, 20, steps, s)])
        return lambda: plots.replay_plot(real, post, prior, [f"obs_{j}" for j in range(s)], 0.05, [0.5] * n,
                                         "replayed predictive check, round 1")

    def identifiability(k):
        r2, rms = list(rng.uniform(0, 1, k)), list(10 ** rng.uniform(-7, 1, k))
        return lambda: plots.identifiability_plot([f"finger_link_mass_{i}" for i in range(k)], r2, rms, "round 1")

    return {"pair plot, 2 parameters": pair(2), "pair plot, 6 parameters": pair(6),
            "replay, 1 trajectory x 3 features": replay(1, 3, 21), "replay, 3 trajectories x 6 features": replay(3, 6, 51),
            "identifiability, 2 parameters": identifiability(2), "identifiability, 24 parameters": identifiability(24)}


def draw_seconds(build, tight: bool, repeats: int) -> float:
    from bayessim_exp.logging import plots

    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        figure = build()
        if tight:
            figure.tight_layout()
        figure.savefig(io.BytesIO(), format="png")
        plots.plt.close(figure)
        best = min(best, time.perf_counter() - start)
    return best


def smoke_child(drawing: str) -> None:
    """In a process pinned to one CPU: one smoke run, its figures drawn where `drawing` says; prints JSON."""
    from bayessim_exp import api
    from bayessim_exp.logging import tensorboard
    from bayessim_exp.pipeline import Pipeline

    if drawing == "process":  # as before f04e498: a drawing process whatever the CPUs
        tensorboard.usable_cpus = lambda: 2
    cfg = api.compose(["debug=smoke", "logging.progress=false"])
    start = time.perf_counter()
    Pipeline(cfg, tempfile.mkdtemp()).run()
    wall = time.perf_counter() - start
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    print(json.dumps({"wall": wall, "cpu": own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime}))


def smoke_run(drawing: str) -> dict:
    one_cpu = min(os.sched_getaffinity(0))
    done = subprocess.run([sys.executable, __file__, "--smoke-child", drawing], capture_output=True, text=True,
                          check=True, preexec_fn=lambda: os.sched_setaffinity(0, {one_cpu}))
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--smoke-child", choices=["inprocess", "process"], help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.smoke_child:
        smoke_child(args.smoke_child)
        return
    print(f"{'figure':<38}{'fixed margins s':>16}{'tight_layout s':>16}")
    for name, build in figures().items():
        draw_seconds(build, False, 1)  # fonts and caches warm
        print(f"{name:<38}{draw_seconds(build, False, args.repeats):>16.3f}{draw_seconds(build, True, args.repeats):>16.3f}")
    print(f"\ndebug=smoke Pendulum run on one CPU, median of {args.runs}")
    print(f"{'figures drawn':<38}{'wall s':>16}{'CPU s':>16}")
    for drawing, label in (("inprocess", "in the run's process (now)"), ("process", "in a drawing process (before)")):
        runs = [smoke_run(drawing) for _ in range(args.runs)]
        print(f"{label:<38}{statistics.median(r['wall'] for r in runs):>16.1f}"
              f"{statistics.median(r['cpu'] for r in runs):>16.1f}")


if __name__ == "__main__":
    main()

"""How far a recorded run's results.json moves under float32 noise, and under small real changes: the measurement
behind the float tolerance of tests/integration/test_golden_results.py (bayessim_exp/testing/golden.py's
docstring has the figures).

Variants, each a whole run in a process of its own: the reference with OMP_NUM_THREADS=1; OMP_NUM_THREADS=2
(torch's and numpy's BLAS threads: another summation order); the summaries moved by one float32 rounding each
(x * (1 +- eps), the sign drawn per value) with --perturbations generator seeds; and the small real changes named
by --changes (Hydra overrides). Prints per variant how many floats moved and the largest changes, how many fall
outside the test's tolerance, and which other values (strings, booleans, integers, keys) changed.

    python benchmarks/golden_tolerance.py [--run pendulum_smoke] [--perturbations 3] [--changes OVERRIDE ...]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from tempfile import TemporaryDirectory

import torch

from bayessim_exp.testing.golden import ABS_TOL, REL_TOL, RUNS, leaves, run

CHANGES = ["model.lr=0.00101", "collect.trajectories=299"]  # a 1 % larger step (mdnn); one simulation fewer


class MovedByOneRounding:
    """A summarizer whose every summary x is x * (1 +- eps32), the sign drawn per value."""

    def __init__(self, summarizer, generator: torch.Generator):
        self.summarizer, self.generator = summarizer, generator

    def __getattr__(self, name):
        return getattr(self.summarizer, name)

    def __call__(self, traj):
        x = self.summarizer(traj)
        sign = torch.randint(0, 2, x.shape, generator=self.generator).to(x.dtype) * 2 - 1
        return x * (1 + sign * torch.finfo(torch.float32).eps)


@contextlib.contextmanager
def summaries_moved_by_one_rounding(seed: int):
    from bayessim_exp import registry

    build, generator = registry.build, torch.Generator().manual_seed(seed)

    def moved(group, cfg, **deps):
        built = build(group, cfg, **deps)
        return MovedByOneRounding(built, generator) if group == "summarizer" else built

    registry.build = moved
    try:
        yield
    finally:
        registry.build = build


def one_run(name: str, extra: list[str], threads: int, seed: int | None) -> dict:
    """The run in a process of its own: OMP_NUM_THREADS is read once, at start-up, by torch and by numpy's BLAS."""
    spec = json.dumps({"name": name, "extra": extra, "seed": seed})
    done = subprocess.run([sys.executable, __file__, "--single", spec], env={**os.environ, "OMP_NUM_THREADS": str(threads)},
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def single(spec: dict) -> None:
    with TemporaryDirectory() as tmp, (summaries_moved_by_one_rounding(spec["seed"]) if spec["seed"] is not None
                                       else contextlib.nullcontext()):
        print(json.dumps(run(spec["name"], Path(tmp), spec["extra"], torch.get_num_threads())))


def compare(got: dict, want: dict) -> dict:
    a, b = dict(leaves(got)), dict(leaves(want))
    other = sorted(p for p in set(a) | set(b) if p not in a or p not in b or (
        not (isinstance(b[p], float) and isinstance(a[p], (int, float))) and a[p] != b[p]))
    moved = [(abs(a[p] - b[p]), p) for p in a if p in b and isinstance(b[p], float) and p not in other
             and not (math.isnan(a[p]) and math.isnan(b[p])) and a[p] != b[p]]
    rel = sorted(((d / abs(b[p]) if b[p] else math.inf, d, p) for d, p in moved), reverse=True)
    outside = [p for d, p in moved if not math.isclose(a[p], b[p], rel_tol=REL_TOL, abs_tol=ABS_TOL)]
    return {"moved": len(moved), "floats": sum(isinstance(v, float) for v in b.values()), "not_floats": other,
            "max_abs": max((d for d, _ in moved), default=0.0), "by_rel": rel, "outside": outside,
            "values": (a, b)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", default="pendulum_smoke", choices=sorted(RUNS))
    parser.add_argument("--perturbations", type=int, default=3)
    parser.add_argument("--changes", nargs="*", default=CHANGES)
    parser.add_argument("--single", help=argparse.SUPPRESS)  # one run, in the subprocess
    args = parser.parse_args()
    if args.single:
        return single(json.loads(args.single))
    reference = one_run(args.run, [], 1, None)
    variants = [("OMP_NUM_THREADS=2 (torch and BLAS)", [], 2, None)]
    variants += [(f"summaries +-1 float32 rounding, seed {s}", [], 1, s) for s in range(args.perturbations)]
    variants += [(f"real change: {c}", [c], 1, None) for c in args.changes]
    print(f"{args.run}, reference on OMP_NUM_THREADS=1; the test allows rel {REL_TOL:g} with abs floor {ABS_TOL:g}")
    for label, extra, threads, seed in variants:
        found = compare(one_run(args.run, extra, threads, seed), reference)
        print(f"\n{label}: {found['moved']} of {found['floats']} floats moved, largest |change| "
              f"{found['max_abs']:.3g}; {len(found['outside'])} outside the tolerance; other values changed: "
              f"{len(found['not_floats'])} {found['not_floats'][:3]}")
        got, want = found["values"]
        for rel, d, path in found["by_rel"][:5]:
            print(f"  rel {rel:9.3g}  abs {d:9.3g}  {path}: {got[path]!r} (reference {want[path]!r})")


if __name__ == "__main__":
    main()

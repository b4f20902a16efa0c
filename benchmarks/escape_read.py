"""Seconds of the escape's read (inference/bayessim/escape.py) at ShadowHand's signature size, and of its ridge.

    OMP_NUM_THREADS=2 PYTHONPATH=src python benchmarks/escape_read.py
    OMP_NUM_THREADS=2 PYTHONPATH=src python benchmarks/escape_read.py --rows 4096 --features 11130 --params 32

With more summary features than rows the read's ridge is solved in its rows-by-rows dual for each of the escape's
penalties. models/projection.RidgeSystem forms the rows' Gram matrix once for all of them; the baseline, a
RidgeSystem per penalty, forms it once per penalty, as the read did before, which took most of the mission
command's guard stage on ShadowHand (docs/benchmarks.md). Random summaries of the given size, the real summaries
beyond them; prints the ridge's seconds both ways (same solver, only the Gram's reuse differs) and the whole read's.
"""

from __future__ import annotations

import argparse
import time

import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=4096, help="fitted simulations (escape.MAX_ROWS)")
    ap.add_argument("--features", type=int, default=11130, help="summary features (ShadowHand, signatures of depth 2)")
    ap.add_argument("--params", type=int, default=32, help="parameters (ShadowHand's 32)")
    args = ap.parse_args()

    from bayessim_exp.inference.bayessim import escape
    from bayessim_exp.models.projection import RidgeSystem

    g = torch.Generator().manual_seed(0)
    mixing = torch.randn(args.params, args.features, generator=g) / args.params ** 0.5
    u = torch.randn(args.rows + 1000, args.params, generator=g)
    x = u @ mixing + 0.1 * torch.randn(len(u), args.features, generator=g)
    x_real = (2.5 + u[:2]) @ mixing
    fit, check = slice(0, args.rows), slice(args.rows, None)

    def timed(fn) -> float:
        start = time.perf_counter()
        fn()
        return time.perf_counter() - start

    z = (x[fit].double() - x[fit].double().mean(0)) / x[fit].double().std(0)
    shared = RidgeSystem(z, u[fit])
    ridge = timed(lambda: [shared.solve(p) for p in escape.PENALTIES])
    baseline = timed(lambda: [RidgeSystem(z, u[fit]).solve(p) for p in escape.PENALTIES])
    read = timed(lambda: escape.read_at(x[fit], u[fit], x[check], u[check], x_real, nearest=True))
    print("| rows | features | parameters | ridge, one Gram s | ridge, a Gram per penalty s | speed-up | read_at s |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {args.rows} | {args.features} | {args.params} | {ridge:.1f} | {baseline:.1f} | {baseline / ridge:.1f}x "
          f"| {read:.1f} |")


if __name__ == "__main__":
    main()

"""A finished run's round-k model near the prior box's faces: how often the posterior given one trajectory holds its
own parameters in its 50 % and 90 % HPD regions, in bins of the first parameter's prior CDF (the second drawn from
the prior, or fixed with --length-cdf), in parameter space (as a known-truth study reads it) and in probit space
[brackets], with the truth's mean marginal rank per parameter.

    PYTHONPATH=src python benchmarks/face_coverage.py RUN --round 1 --per-bin 150
    PYTHONPATH=src python benchmarks/face_coverage.py RUN --round 3 --bins 0.5,0.7,0.85,0.95,0.98,1 --length-cdf 0.333

A model calibrated on average over its proposal can under-cover near the faces and over-cover inside
(docs/statistics.md, "Truths near the box's faces"). Written for two-parameter tasks (Pendulum: mass, length).
Parameters outside the round's proposal (later rounds' truncated region) are left out of the shares.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from omegaconf import OmegaConf

from bayessim_exp.artifacts import RunDir
from bayessim_exp.components import build_components, build_method
from bayessim_exp.distributions.hpd import own_level
from bayessim_exp.logging.tensorboard import NO_TENSORBOARD
from bayessim_exp.run_config import check_run_config
from bayessim_exp.stages import RoundContext
from coverage_at_truth import conditioned  # benchmarks/coverage_at_truth.py

RANK_DRAWS = 1000  # posterior draws per trajectory for the truth's marginal ranks (own_level draws its own 500)


def bin_cdfs(edges: list[float], per_bin: int, length_cdf: float | None, seed: int) -> torch.Tensor:
    """[bins * per_bin, 2] prior CDF values: the first uniform within each bin, the second uniform or fixed."""
    generator = torch.Generator().manual_seed(seed)
    cdfs = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        c = torch.rand(per_bin, 2, generator=generator, dtype=torch.float64)
        c[:, 0] = lo + (hi - lo) * c[:, 0]
        if length_cdf is not None:
            c[:, 1] = length_cdf
        cdfs.append(c)
    return torch.cat(cdfs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--round", type=int, default=1)
    ap.add_argument("--per-bin", type=int, default=150)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--bins", default="0,0.05,0.2,0.8,0.95,1", help="edges of the first parameter's prior CDF")
    ap.add_argument("--length-cdf", type=float, help="fix the second parameter's CDF (e.g. 0.98) instead of drawing it")
    args = ap.parse_args()
    cfg = OmegaConf.load(args.run / "config.yaml")
    comp = build_components(cfg, check_run_config(cfg))
    if comp.task.spec.dim != 2:
        raise SystemExit(f"{args.run}: {comp.task.spec.dim} parameters; face_coverage.py reads two-parameter tasks")
    method = build_method(cfg, comp, comp.policy)
    ctx = RoundContext(RunDir(args.run), args.round, comp.rc.seed, NO_TENSORBOARD)
    model = comp.model()
    model.load_state_dict(ctx.output("fit")["model"])
    edges = [float(e) for e in args.bins.split(",")]
    bins = torch.arange(len(edges) - 1).repeat_interleave(args.per_bin)
    theta = comp.prior.marginal_icdf(bin_cdfs(edges, args.per_bin, args.length_cdf, args.seed)).double()
    posteriors, _, kept = conditioned(comp, method, ctx, model, theta, args.seed)
    theta, bins = theta[kept], bins[kept]
    proposal = method.proposal(ctx)
    generator = torch.Generator().manual_seed(args.seed)
    levels, probit_levels, ranks = [], [], []
    for post, t in zip(posteriors, theta):
        levels.append(own_level(post, t, 500, generator))
        if method.probit is not None:  # the same posterior where the model was fitted
            probit_levels.append(own_level(post.in_probit_space(), method.probit.to_probit(t[None]).double()[0], 500,
                                           generator))
        ranks.append((post.sample((RANK_DRAWS,), generator=generator).double() < t).double().mean(0))
    in_proposal = torch.isfinite(proposal.log_prob(theta))
    levels = torch.tensor(levels)
    probit = torch.tensor(probit_levels) if probit_levels else None
    ranks = torch.stack(ranks)
    print(f"run {args.run.name}, round {args.round}: by the first parameter's prior CDF, the share inside the 50 % / "
          "90 % regions in parameter space [probit space], the truth's mean marginal ranks, trajectories")
    for b, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        rows = (bins == b) & in_proposal
        shares = f"{(levels[rows] < 0.5).double().mean():.2f} / {(levels[rows] < 0.9).double().mean():.2f}"
        if probit is not None:
            shares += f" [{(probit[rows] < 0.5).double().mean():.2f} / {(probit[rows] < 0.9).double().mean():.2f}]"
        r = ranks[rows]
        print(f"CDF {lo:.2f}-{hi:.2f}: {shares}; ranks {r[:, 0].mean():.3f} (above 0.95: "
              f"{(r[:, 0] > 0.95).double().mean():.2f}, below 0.05: {(r[:, 0] < 0.05).double().mean():.2f}), "
              f"{r[:, 1].mean():.3f}; n = {int(rows.sum())}")


if __name__ == "__main__":
    main()

"""A finished run's round-k model near the prior box's faces: how often the posterior given one trajectory holds its
own parameters in its 50 % and 90 % HPD regions, in bins of the first parameter's prior CDF (the second drawn from
the prior, or fixed with --length-cdf), in parameter space (as a known-truth study reads it) and in probit space
[brackets], with the truth's mean marginal rank per parameter.

    PYTHONPATH=src python benchmarks/face_coverage.py RUN --round 1 --per-bin 150
    PYTHONPATH=src python benchmarks/face_coverage.py RUN --round 3 --bins 0.5,0.7,0.85,0.95,0.98,1 --length-cdf 0.333

A model calibrated on average over its proposal can under-cover near the faces and over-cover inside
(docs/statistics.md, "Truths near the box's faces"). Written for two-parameter tasks (Pendulum: mass, length).
"""
import argparse
from pathlib import Path

import torch
from omegaconf import OmegaConf

from bayessim_exp.artifacts import RunDir
from bayessim_exp.components import build_components, build_method
from bayessim_exp.distributions.hpd import own_level
from bayessim_exp.inference.bayessim.condition import condition
from bayessim_exp.run_config import check_run_config
from bayessim_exp.stages import RoundContext

ap = argparse.ArgumentParser()
ap.add_argument("run", type=Path)
ap.add_argument("--round", type=int, default=1)
ap.add_argument("--per-bin", type=int, default=150)
ap.add_argument("--seed", type=int, default=7)
ap.add_argument("--bins", default="0,0.05,0.2,0.8,0.95,1")
ap.add_argument("--length-cdf", default=None, help="fix length's CDF (e.g. 0.98) instead of drawing it")
args = ap.parse_args()
cfg = OmegaConf.load(args.run / "config.yaml")
comp = build_components(cfg, check_run_config(cfg))
method = build_method(cfg, comp, comp.policy)
ctx = RoundContext(RunDir(args.run), args.round, comp.rc.seed, None)
model = comp.model()
model.load_state_dict(ctx.output("fit")["model"])
prior = comp.prior
edges = [float(e) for e in args.bins.split(",")]
g = torch.Generator().manual_seed(args.seed)
cdfs = []
for lo, hi in zip(edges[:-1], edges[1:]):
    c = torch.rand(args.per_bin, 2, generator=g, dtype=torch.float64)
    c[:, 0] = lo + (hi - lo) * c[:, 0]
    if args.length_cdf is not None:
        c[:, 1] = float(args.length_cdf)
    cdfs.append(c)
cdf = torch.cat(cdfs)
theta = prior.marginal_icdf(cdf).double()
traj = comp.sims.rollout(theta, comp.policy(args.seed, ctx), comp.rc.collect.horizon, args.seed)
x = comp.summarizer(traj.to(comp.device)).cpu()
kept = ~traj.diverged.cpu() & torch.isfinite(x).all(-1)
proposal = method.proposal(ctx)
gen = torch.Generator().manual_seed(args.seed)
lv, lvu, zm, zl, inprop = [], [], [], [], []
for t, xi in zip(theta, x):
    post = condition(model, xi, prior, proposal=proposal, seed=args.seed, probit=method.probit)[0]
    lv.append(own_level(post, t, 500, gen))
    inner = post.inner if hasattr(post, "inner") else None
    if inner is not None:
        u = method.probit.to_probit(t[None]).double()[0]
        lvu.append(own_level(inner, u, 500, gen))
    s = post.sample((1000,), generator=gen).double()
    zm.append(float(((s[:, 0] - t[0]) < 0).double().mean()))  # marginal rank of truth's mass
    zl.append(float(((s[:, 1] - t[1]) < 0).double().mean()))
    inprop.append(float(proposal.log_prob(t[None].double())[0]))
lv, zm, zl = map(torch.tensor, (lv, zm, zl))
lvu = torch.tensor(lvu) if lvu else None
inprop = torch.tensor(inprop)
print(f"run {args.run.name} round {args.round}; bins of mass CDF; share inside 50/90 % (param space) [probit space]; mean mass rank; mean length rank; n")
i = 0
for lo, hi in zip(edges[:-1], edges[1:]):
    sl = slice(i, i + args.per_bin)
    i += args.per_bin
    k = kept[sl] & torch.isfinite(inprop[sl])
    a = lv[sl][k]
    extra = f" [{(lvu[sl][k]<0.5).double().mean():.2f}/{(lvu[sl][k]<0.9).double().mean():.2f}]" if lvu is not None else ""
    print(f"mass CDF {lo:.2f}-{hi:.2f}: {(a<0.5).double().mean():.2f} / {(a<0.9).double().mean():.2f}{extra}  rank_m {zm[sl][k].mean():.3f} (>0.95: {(zm[sl][k]>0.95).double().mean():.2f}, <0.05: {(zm[sl][k]<0.05).double().mean():.2f})  rank_L {zl[sl][k].mean():.3f}  n={int(k.sum())}")

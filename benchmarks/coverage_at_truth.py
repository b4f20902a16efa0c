"""A finished run's model at its own true parameters: how often q(theta | x) holds the truth in its 50 % and 90 %
HPD regions over trajectories simulated there, beside as many parameters drawn from the prior, and where the
truth's summaries lie among the model's training inputs (diagnostics/extrapolation.py).

    PYTHONPATH=src python benchmarks/coverage_at_truth.py outputs/<run>/<date> --round 1 --sims 200
    PYTHONPATH=src python benchmarks/coverage_at_truth.py RUN --refit model.project_inputs=false   # another model
    PYTHONPATH=src python benchmarks/coverage_at_truth.py RUN --round 2 --refit model.ensemble=3 --train-rounds 2
    PYTHONPATH=src python benchmarks/coverage_at_truth.py RUN --round 2 --per-parameter

`--refit OVERRIDE...` fits the run's model with those overrides (on the training simulations of rounds 1 to
--round, pooled as the run's truncated rounds are, or of the rounds `--train-rounds` names) instead of loading the
round's own, and checks that one; as the run did, its spread is calibrated on the pairs its `method.calibrate_on`
names (`--calibrate-on latest|all`: the last of those rounds' pairs, or every round's). `--per-parameter` adds a table: per parameter, the truth in the space
the model is fitted in (probit: prior quantiles as standard normal scores), and over the trajectories at the truth
the mean and root-mean-square of (q's mean - truth) / q's standard deviation and q's mean standard deviation (q:
the model's conditional alone, before the proposal's truncation).

Held-out coverage averages over the proposal; a Bayesian posterior need not cover every fixed truth, but a
model calibrated over the prior that misses one truth this often extrapolates there (docs/statistics.md, "Real
data outside the simulations"). Each trajectory is conditioned on alone (the round's model and proposal, the
method's parameter space); the summaries come from the run's collect policy (rl-based policies, which need the
round's actor, are not supported here).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from omegaconf import OmegaConf

from bayessim_exp import registry
from bayessim_exp.artifacts import RunDir
from bayessim_exp.components import Components, build_components, build_method
from bayessim_exp.diagnostics.extrapolation import inputs_outside
from bayessim_exp.distributions.hpd import own_level
from bayessim_exp.inference.bayessim.condition import condition
from bayessim_exp.inference.bayessim.method import BayesSim
from bayessim_exp.inference.bayessim.training_data import CALIBRATE_ON, calibration_rows
from bayessim_exp.logging.tensorboard import NO_TENSORBOARD
from bayessim_exp.run_config import check_run_config
from bayessim_exp.stages import RoundContext


def conditioned(comp: Components, method: BayesSim, ctx: RoundContext, model, theta: torch.Tensor,
                seed: int) -> tuple[list, torch.Tensor, torch.Tensor]:
    """One trajectory at each row of theta, each conditioned on alone with the round's model and proposal in the
    method's parameter space: (posteriors and summaries of the rows kept, [N] bool: the rows kept, neither diverged
    nor with non-finite summaries)."""
    traj = comp.sims.rollout(theta, comp.policy(seed, ctx), comp.rc.collect.horizon, seed)
    x = comp.summarizer(traj.to(comp.device)).cpu()
    kept = ~traj.diverged.cpu() & torch.isfinite(x).all(-1)
    proposal = method.proposal(ctx)
    posteriors = [condition(model, x_i, comp.prior, proposal=proposal, seed=seed, probit=method.probit)[0]
                  for x_i in x[kept]]
    return posteriors, x[kept], kept


def coverage(comp: Components, method: BayesSim, ctx: RoundContext, model, theta: torch.Tensor,
             seed: int) -> tuple[dict, torch.Tensor]:
    """Shares of theta's rows inside their own posterior's 50 % / 90 % regions, one trajectory each; the summaries."""
    posteriors, x, kept = conditioned(comp, method, ctx, model, theta, seed)
    generator = torch.Generator().manual_seed(seed)
    levels = torch.tensor([own_level(post, t.double(), 500, generator) for post, t in zip(posteriors, theta[kept])])
    return {f"{level:g}": float((levels < level).double().mean()) for level in (0.5, 0.9)}, x


def per_parameter(model, method: BayesSim, names: list[str], truth: torch.Tensor, x: torch.Tensor) -> str:
    """Per parameter, q's error at the truth over the trajectories x in standard deviations, and q's spread."""
    at = fitted_space(method, truth[None]).double()[0]
    errors, spreads = [], []
    for x_i in x:
        q = model.conditional(x_i.float())
        errors.append((q.mean.double() - at) / q.stddev.double())
        spreads.append(q.stddev.double())
    z, spread = torch.stack(errors), torch.stack(spreads)
    rows = [f"| {n} | {at[i]:+.2f} | {z[:, i].mean():+.2f} | {z[:, i].pow(2).mean().sqrt():.2f} | {spread[:, i].mean():.3f} |"
            for i, n in enumerate(names)]
    return "\n".join(["| parameter | truth, fitted space | mean error / std | rms error / std | q's std |",
                      "|---|---:|---:|---:|---:|", *rows])


def fitted_space(method: BayesSim, theta: torch.Tensor) -> torch.Tensor:
    return theta if method.probit is None else method.probit.to_probit(theta).float()


def refit(comp, cfg, overrides: list[str], theta: torch.Tensor, x: torch.Tensor, calibrated: torch.Tensor):
    """The run's model config with `overrides`, fitted on training simulations (theta in the method's space), its
    spread calibrated on the rows `calibrated`."""
    model_cfg = OmegaConf.merge(cfg.model, OmegaConf.from_dotlist([o.removeprefix("model.") for o in overrides]))
    model = registry.build("model", model_cfg, theta_dim=comp.task.spec.dim, x_dim=comp.x_dim)
    model.fit(theta, x, seed=0, label="refit", calibration_rows=calibrated)
    return model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--round", type=int, default=1)
    ap.add_argument("--sims", type=int, default=200, help="trajectories at the truth and prior draws")
    ap.add_argument("--seed", type=int, default=123)
    ap.add_argument("--refit", nargs="+", metavar="OVERRIDE", help="model overrides to fit instead (model.name=...)")
    ap.add_argument("--train-rounds", nargs="+", type=int, metavar="ROUND",
                    help="the rounds whose simulations --refit trains on (default: 1 to --round)")
    ap.add_argument("--calibrate-on", choices=CALIBRATE_ON,
                    help="the pairs --refit calibrates its spread on: the last training round's or all "
                         "(default: the run's own method.calibrate_on)")
    ap.add_argument("--per-parameter", action="store_true", help="also q's error at the truth per parameter")
    args = ap.parse_args()
    train_rounds = args.train_rounds or list(range(1, args.round + 1))
    if args.train_rounds and not args.refit:
        raise SystemExit("--train-rounds chooses what --refit trains on: give --refit as well")
    if not all(1 <= k <= args.round for k in train_rounds):
        raise SystemExit(f"--train-rounds {train_rounds}: rounds 1 to --round {args.round} only")
    cfg = OmegaConf.load(args.run / "config.yaml")
    # runs from before method.calibrate_on calibrated on the latest round's pairs
    calibrate_on = args.calibrate_on or cfg.method.get("calibrate_on", "latest")
    comp = build_components(cfg, check_run_config(cfg))
    if comp.real.true_params is None:
        raise SystemExit(f"{args.run}: the run's real data carry no true parameters")
    method = build_method(cfg, comp, comp.policy)
    ctx = RoundContext(RunDir(args.run), args.round, comp.rc.seed, NO_TENSORBOARD)
    summaries = [ctx.output("summarize", k) for k in train_rounds]
    cut = [len(s["x"]) - int(comp.rc.diagnostics.held_out_fraction * len(s["x"])) for s in summaries]
    theta_train = fitted_space(method, torch.cat([s["theta"][:c] for s, c in zip(summaries, cut)]))
    x_train = torch.cat([s["x"][:c] for s, c in zip(summaries, cut)])
    if args.refit:
        calibrated = calibration_rows(len(x_train), cut[-1], calibrate_on)
        model = refit(comp, cfg, args.refit, theta_train, x_train, calibrated)
    else:
        model = comp.model()
        model.load_state_dict(ctx.output("fit")["model"])
    truth = torch.as_tensor(comp.real.true_params, dtype=torch.float64)
    at_truth, x_truth = coverage(comp, method, ctx, model, truth[None].repeat(args.sims, 1), args.seed)
    drawn = comp.prior.sample((args.sims,), generator=torch.Generator().manual_seed(args.seed)).double()
    at_prior, _ = coverage(comp, method, ctx, model, drawn, args.seed + 1)

    with torch.no_grad():
        outside = inputs_outside(model.inputs(x_truth), model.inputs(x_train), theta_train,
                                 model.inputs(summaries[-1]["x"][cut[-1]:]), 0.01)
    distances = torch.tensor(outside["distance"])
    label = (" ".join(args.refit) + f", trained on rounds {train_rounds}, calibrated on {calibrate_on}"
             if args.refit else "the run's")
    print(f"| run | round | model | trajectories | at the truth: 50 % / 90 % | prior draws: 50 % / 90 % | truth's summaries: "
          f"median distance (held-out median), share with p < 0.01 |\n|---|---|---|---|---|---|---|\n"
          f"| {args.run} | {args.round} | {label} | {len(x_truth)} | {at_truth['0.5']:.2f} / {at_truth['0.9']:.2f} | "
          f"{at_prior['0.5']:.2f} / {at_prior['0.9']:.2f} | {float(distances.median()):.1f} "
          f"({outside['held_out_median']:.1f}), {sum(p < 0.01 for p in outside['p_value']) / len(distances):.2f} |")

    if args.per_parameter:
        print(per_parameter(model, method, comp.task.spec.names, truth, x_truth))


if __name__ == "__main__":
    main()

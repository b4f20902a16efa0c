"""Held-out coverage of round 1's HPD regions in the model's probit space and in the parameter space.

    PYTHONPATH=src python benchmarks/coverage_spaces.py --task Anymal --out /tmp/coverage_spaces_anymal

The guard and the spread calibration read HPD regions of q(u | x) in probit space (u = the probit map of the
parameters); a known-truth study and the results ask whether the truth lies in the HPD region of the posterior
over the parameters themselves, whose density carries the map's Jacobian. For an exact posterior both regions
cover as their level says; an approximate one can be calibrated in one space and not in the other. Runs the
task's default round 1 up to its fit (kept in --out and reused), then ranks --pairs held-out simulations' own
parameters among --draws posterior draws given their summaries, in both spaces. With --exact-replays (tasks that
replay the real actions, policy=replay) the pairs are fresh prior draws replaying the recorded actions without
the replay's noise, as the surrogate real system executed them: a known-truth study's truths, not its
simulations.

    PYTHONPATH=src python benchmarks/coverage_spaces.py --task FrankaCabinet --exact-replays --out /tmp/cs real.truth=prior
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="Anymal")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pairs", type=int, default=300)
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--exact-replays", action="store_true",
                    help="rank prior draws replaying the recorded actions without noise, not held-out simulations")
    ap.add_argument("overrides", nargs="*", help="added to the run (e.g. sim.nthread=1)")
    args = ap.parse_args()

    from bayessim_exp import api
    from bayessim_exp.components import build_components
    from bayessim_exp.data_files import load_state
    from bayessim_exp.diagnostics.coverage import credibility_ranks
    from bayessim_exp.distributions.hpd import hpd_level
    from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
    from bayessim_exp.pipeline import Pipeline

    cfg = api.compose([f"task={args.task}", f"seed={args.seed}", "sim=native", "logging.progress=false",
                       *args.overrides])
    pipeline = Pipeline(cfg, args.out)
    if not (args.out / "round_001" / "fit.pt").exists():
        pipeline.run(stop_after=(1, "fit"))
    # artifacts this run just wrote (pipeline.RunDir), not files from elsewhere
    fitted = load_state(args.out / "round_001" / "fit.pt")
    summaries = load_state(args.out / "round_001" / "summarize.pt")
    comp = build_components(cfg, pipeline.rc)
    model = comp.model()
    model.load_state_dict(fitted["model"])
    probit = ProbitTransform(comp.prior)
    if args.exact_replays:
        theta, x = exact_replays(comp, args.out, args.pairs, args.seed)
    else:
        held_out = int(cfg.diagnostics.held_out_fraction * len(summaries["theta"]))
        theta = summaries["theta"][-held_out:][: args.pairs].double()
        x = summaries["x"][-held_out:][: args.pairs]

    # probit space: the levels the guard's held-out coverage reads (diagnostics/coverage.py)
    in_probit = credibility_ranks(model, probit.to_probit(theta).double(), x, args.draws, args.seed)[0].numpy()
    generator = torch.Generator().manual_seed(args.seed)
    in_parameters = []
    for theta_i, x_i in zip(theta, x):
        posterior = ProbitPosterior(model.conditional(x_i), probit)
        in_parameters.append(hpd_level(posterior, theta_i[None], posterior.sample((args.draws,), generator=generator)
                                       .double(), generator))
    in_parameters = np.array(in_parameters, dtype=float)
    pairs = "prior draws replaying the recorded actions exactly" if args.exact_replays else "held-out pairs"
    print(f"{args.task}, seed {args.seed}, round 1, {len(theta)} {pairs}, {args.draws} draws each\n")
    print("| region | probit space | parameter space |\n|---|---:|---:|")
    for level in cfg.diagnostics.levels:
        print(f"| HPD {level:.0%} | {(in_probit < level).mean():.3f} | {(in_parameters < level).mean():.3f} |")


def exact_replays(comp, out: Path, count: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """count prior draws and the summaries of their simulations replaying round 1's real trajectories without noise."""
    from bayessim_exp.data_files import load_state
    from bayessim_exp.policies import ReplayPolicy, ReplayPolicyConfig
    from bayessim_exp.sim.trajectories import Trajectories

    recorded = Trajectories(**load_state(out / "round_001" / "real.pt")["traj"])
    theta = comp.prior.sample((count,), generator=torch.Generator().manual_seed(seed)).double()
    replays = comp.sims.rollout(theta, ReplayPolicy(ReplayPolicyConfig(0.0), recorded, comp.task, seed),
                                recorded.horizon, seed=seed)
    kept = ~replays.diverged.cpu()
    return theta[kept], comp.summarizer(replays.to(comp.device)).cpu()[kept]


if __name__ == "__main__":
    main()

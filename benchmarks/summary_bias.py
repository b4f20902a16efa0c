"""A known model error: real data from our own simulator whose summaries carry a known offset, and what it costs.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/summary_bias.py --out /tmp/bias/none --offset 0
    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/summary_bias.py --out /tmp/bias/small --offset 0.2
    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/summary_bias.py --out /tmp/bias/oracle --offset 0.2 --feature-noise 1

One Pendulum trajectory of our simulator at `--truth` (default (1.3, 0.6)) is the real data (20 steps, random
actions); the run's summaries of it (never of a simulation) get `--offset` times the features' spread over 500
prior draws added in `--features` (default 5 and 20) of the 80 the start summarizer gives. The run: `--sims`
(5,000) simulations of 20 steps a round, two rounds, the defaults otherwise. Prints the final posterior's gain at the truth over the prior, the truth's HPD level, the
rounds' temperatures and whether the final round flagged a mismatch (docs/statistics.md, 'The error read feature
by feature'). `--feature-noise K` is an oracle error model: every simulation's summaries (training, held-out,
replays, simulated sets) get Gaussian noise of K times the spread in the offset features, so q learns to read the
parameters without them: what a summary error model that found those features could keep.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="a fresh directory for the log and the run")
    ap.add_argument("--offset", type=float, default=0.2, help="the offset in units of each feature's prior spread")
    ap.add_argument("--truth", type=float, nargs=2, default=[1.3, 0.6], help="the real pendulum's mass and length")
    ap.add_argument("--features", type=int, nargs="+", default=[5, 20], help="the offset features (of 80)")
    ap.add_argument("--sims", type=int, default=5000, help="simulations a round")
    ap.add_argument("--overrides", nargs="*", default=[], help="added to the run (e.g. method.integrators=[model])")
    ap.add_argument("--feature-noise", type=float, default=0.0,
                    help="noise on the simulations' offset features, in units of their prior spread (0: none)")
    args = ap.parse_args()

    from bayessim_exp import api, registry
    from bayessim_exp.inference.bayessim import method
    from bayessim_exp.policies import RandomPolicy
    from bayessim_exp.real import save_trajectories
    from bayessim_exp.testing.independent_pendulum import hpd_level

    args.out.mkdir(parents=True, exist_ok=True)
    cfg = api.compose([])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    native = registry.build("sim", {"name": "native"})
    real = native(task, 1).rollout(np.array([args.truth]), RandomPolicy(1, 7), 20, 7)
    save_trajectories(args.out / "robot.npz", real, args.truth, task.spec.names)
    theta = prior.sample((500,), generator=torch.Generator().manual_seed(0)).numpy()
    spread = summarizer(native(task, 500).rollout(theta, RandomPolicy(1, 1), 20, 1)).double().std(0)
    offset = torch.zeros(len(spread), dtype=torch.float64)
    offset[args.features] = args.offset * spread[args.features]

    # the offset goes on the real trajectories' summaries alone: the run's own real_trajectories, marked
    real_of, summaries = method.real_trajectories, method.BayesSim._summaries

    def marked(ctx):
        traj = real_of(ctx)
        traj.recorded = True
        return traj

    noise = torch.zeros(len(spread), dtype=torch.float64)
    noise[args.features] = args.feature_noise * spread[args.features]
    generator = torch.Generator().manual_seed(99)

    def noisy(x):
        return x + (torch.randn(x.shape, generator=generator, dtype=torch.float64) * noise).to(x.dtype)

    def with_offset(self, traj):
        x = summaries(self, traj)
        return x + offset.to(x.dtype) if getattr(traj, "recorded", False) else noisy(x)

    summarized = method.summarized  # the collect's simulations, as the fit and its held-out checks read them

    def summarized_noisy(collected, summarize, device):
        return summarized(collected, lambda traj: noisy(summarize(traj).cpu().double()).float(), device)

    method.real_trajectories, method.BayesSim._summaries, method.summarized = marked, with_offset, summarized_noisy
    results = api.run(["real=file", f"real.path={args.out / 'robot.npz'}", f"collect.trajectories={args.sims}",
                       "collect.horizon=20", "rounds=2", "diagnostics.predictive_sims=0", "logging.progress=false",
                       *args.overrides],
                      out_dir=args.out / "run")
    posterior = api.load_run(args.out / "run").posterior()
    truth = torch.tensor([args.truth], dtype=torch.float64)
    print(json.dumps({"truth": args.truth, "features": args.features, "offset": args.offset, "feature_noise": args.feature_noise, "overrides": args.overrides,
                      "gain": float(posterior.log_prob(truth) - prior.log_prob(truth)),
                      "level": float(hpd_level(posterior, args.truth)),
                      "temperatures": [r["temperature"] for r in results["rounds"]],
                      "flagged": results["rounds"][-1]["mismatch"]["flagged"],
                      "summary_error": results["rounds"][-1]["summary_error"]}))


if __name__ == "__main__":
    main()

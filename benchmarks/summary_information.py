"""How much a task's default summaries say about each parameter under different ways of driving the simulations.

    PYTHONPATH=src python benchmarks/summary_information.py --task FrankaCabinet --sims 3000
    PYTHONPATH=src python benchmarks/summary_information.py --task Pendulum --sims 2000 --action-noise 0.3

Draws --sims parameter vectors from the task's prior and simulates each under three collect settings: random
(independent uniform actions and reset states, `policy=random`); replayed (one recorded action sequence plus
Gaussian noise of --action-noise, clipped, from random reset states: `policy=replay` where the task cannot restart
from an observation); and replayed from its start (the same, all from the recording's initial state: what
`policy=replay` does where it can). The recording is itself a random-policy trajectory. Per parameter it prints the
held-out R^2 (the last fifth of the draws) of a ridge regression from the standardised summaries to the
parameter's probit coordinate, the best of six ridge strengths (diagnostics/identifiability.linear_read, what a run's
identifiability report reads): near 0, a linear read of these summaries says nothing about the parameter; a density
model may still learn more than a linear one.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="FrankaCabinet")
    ap.add_argument("--sims", type=int, default=3000)
    ap.add_argument("--horizon", type=int, default=50)  # conf/config.yaml collect.horizon
    ap.add_argument("--action-noise", type=float, default=0.5)  # conf/policy/replay.yaml
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from bayessim_exp import api, registry
    from bayessim_exp.diagnostics.identifiability import linear_read
    from bayessim_exp.distributions.probit import ProbitTransform
    from bayessim_exp.policies import OpenLoopPolicy
    from bayessim_exp.sim.pool import SimulatorPool

    cfg = api.compose([f"task={args.task}", "sim=native"])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    pool = SimulatorPool(registry.build("sim", cfg.sim), task, 4096)
    theta = prior.sample((args.sims,), generator=torch.Generator().manual_seed(args.seed)).double()
    u = ProbitTransform(prior).to_probit(theta).double()
    rng = np.random.default_rng(args.seed)
    n, shape = args.sims, (args.sims, args.horizon, task.action_dim)
    recorded_actions = rng.uniform(-1, 1, (1, args.horizon, task.action_dim))
    recorded_start = task.reset_state(rng, 1)

    def replayed() -> np.ndarray:
        return np.clip(recorded_actions + args.action_noise * rng.standard_normal(shape), -1, 1)

    settings = {
        "random": (rng.uniform(-1, 1, shape), task.reset_state(rng, n)),
        "replayed": (replayed(), task.reset_state(rng, n)),
        "replayed from its start": (replayed(), {k: np.repeat(v, n, 0) for k, v in recorded_start.items()}),
    }
    r2 = {}
    for name, (actions, state) in settings.items():
        traj = pool.rollout(theta, OpenLoopPolicy(torch.as_tensor(actions, dtype=torch.float32)), args.horizon,
                            args.seed, state=state)
        x = summarizer(traj).double().cpu()
        keep = ~traj.diverged.cpu() & torch.isfinite(x).all(1)
        r2[name] = np.array(list(linear_read(x[keep], u[keep], task.spec.names)["r2"].values()))

    print(f"{args.task}, summarizer {cfg.summarizer.name}, {n} prior draws, held-out R^2 per parameter:\n")
    print("| parameter | " + " | ".join(settings) + " |")
    print("|---|" + "---:|" * len(settings))
    for k, name in enumerate(task.spec.names):
        print(f"| {name} | " + " | ".join(f"{r2[s][k]:+.2f}" for s in settings) + " |")
    print("| median | " + " | ".join(f"{np.median(r2[s]):+.2f}" for s in settings) + " |")


if __name__ == "__main__":
    main()

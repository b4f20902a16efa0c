"""Real-data benchmark: pendulum logs from an independent implementation, combined over 1 and 5 trajectories.

    OMP_NUM_THREADS=1 PYTHONPATH=src python3 benchmarks/real_data.py [--sims 10000] [--cache /tmp/bench_real]

The "robot" is tests/integration/independent_pendulum.py: the rigid-rod ODE integrated with RK4
(50 substeps per control step), not the project's MJCF, at hidden parameter sets inside the prior;
variants add joint damping (unmodelled: our Pendulum has none) or put the mass in a bob at the tip.
One MDNN (the default conf/model/mdnn.yaml, start summary) is fitted once on `--sims` prior
simulations (round 1 of the default run) and conditioned on every data set with each combination
(inference/bayessim/combination.py). The reference point is the least-squares best fit of our model: the
parameters whose replays (diagnostics/replay.py) of the trajectories' first `--steps` steps from
their recorded initial states under their recorded actions are closest to the recorded states
(a 41 x 41 grid over the prior box, then Nelder-Mead). Reported per case: the HPD level at which the
best fit (and the truth) enters the posterior (inside the 90 % region iff < 0.9), the log-density
gain over the prior there, and the dispersion of the per-trajectory posteriors.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from bayessim_exp import api, registry
from bayessim_exp.inference.bayessim.combination import COMBINATIONS, combine
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.real import load_trajectories
from bayessim_exp.sim.pool import SimulatorPool

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "integration"))
import independent_pendulum
from independent_pendulum import best_fit, hpd_level

PARAMETER_SETS = [(0.7, 0.35), (1.0, 0.5), (1.6, 0.7), (1.3, 0.85), (0.8, 0.6)]
VARIANTS = {"rod": {}, "damped": {"damping": 0.05}, "bob": {"shape": "bob"}}


def fitted_model(cfg, task, prior, summarizer, sims: int, cache: Path):
    model = registry.build("model", cfg.model, theta_dim=2, x_dim=summarizer.output_dim(3, 1, 20))
    path = cache / f"mdnn_{sims}.pt"
    if path.is_file():
        model.load_state_dict(torch.load(path, weights_only=False))
        return model
    torch.manual_seed(0)
    theta = prior.sample((sims,)).double()
    traj = registry.build("sim", cfg.sim)(task, sims).rollout(theta, RandomPolicy(1, 0), 20, seed=0)
    keep = ~traj.diverged
    model.fit(theta[keep].float(), summarizer(traj.select(keep)), seed=0, label="benchmark")
    cache.mkdir(parents=True, exist_ok=True)
    torch.save(model.state_dict(), path)
    return model


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sims", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/bench_real"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = api.compose(["collect.horizon=20"])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    pool = SimulatorPool(registry.build("sim", cfg.sim), task, chunk=cfg.collect.chunk)
    model = fitted_model(cfg, task, prior, summarizer, args.sims, args.cache)
    print("| variant | mass | length | n | best fit | " + " | ".join(
        f"{c}: HPD level best fit / truth, gain best fit" for c in COMBINATIONS) + " | Birge ratio |")
    print("|---|---|---|---|---|" + "---|" * len(COMBINATIONS) + "---|")
    for variant, kwargs in VARIANTS.items():
        for k, (mass, length) in enumerate(PARAMETER_SETS):
            data = independent_pendulum.simulate(mass, length, 5, 20, seed=100 + k, **kwargs)
            full = load_trajectories(data, task, 20, "benchmark")
            for n in (1, 5):
                real = full.select(torch.arange(n))
                fit = best_fit(pool, real, args.steps)
                x = summarizer(real)
                cells, birge = [], "-"
                for method in COMBINATIONS:
                    post, spread = combine(method, [model.conditional(xi) for xi in x], prior, seed=0)
                    lp_fit = float(post.log_prob(torch.as_tensor(fit)[None]) - prior.log_prob(torch.as_tensor(fit)[None]))
                    cells.append(f"{hpd_level(post, fit):.2f} / {hpd_level(post, np.array([mass, length])):.2f}, {lp_fit:+.1f}")
                    birge = "-" if spread is None else f"{spread.birge_ratio:.2f}"
                print(f"| {variant} | {mass} | {length} | {n} | {fit[0]:.3f}, {fit[1]:.3f} | " + " | ".join(cells)
                      + f" | {birge} |", flush=True)


if __name__ == "__main__":
    main()

"""PPO trained on the BayesSim posterior vs on the uniform prior vs on nominal parameters, evaluated on a
surrogate real system away from the prior's centre (docs/results.md).

For each seed: BayesSim rounds on the surrogate real system (the pipeline as `python -m bayessim_exp`),
then rl=ppo's train_policy and evaluate stages on the last round's posterior, on the prior and on the
task's nominal parameters, with the same PPO settings and seed.

    OMP_NUM_THREADS=1 PYTHONPATH=src python scripts/rl_posterior_vs_prior.py --seeds 0 1 2 \
        --out docs/figures/rl_posterior_vs_prior
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="Pendulum")
    parser.add_argument("--real", nargs="*", default=["mass=1.8", "length=0.9"], help="surrogate real name=value")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--rounds", type=int, default=2, help="BayesSim rounds before PPO")
    parser.add_argument("--episodes", type=int, default=32, help="surrogate-real evaluation episodes")
    parser.add_argument("--overrides", nargs="*", default=[], help="more Hydra overrides for BayesSim")
    parser.add_argument("--rl-overrides", nargs="*", default=[], help="more overrides for PPO, e.g. rl.train.total_steps=...")
    parser.add_argument("--out", default="docs/figures/rl_posterior_vs_prior")
    parser.add_argument("--run-dir", default="outputs/rl_posterior_vs_prior",
                        help="parent of the per-seed run dirs (an existing run dir is resumed)")
    args = parser.parse_args()
    torch.set_num_threads(1)

    from bayessim_exp import api
    from bayessim_exp.components import build_components
    from bayessim_exp.rl.standalone import StandaloneRounds
    from bayessim_exp.run_config import check_run_config

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    results: dict = {"task": args.task, "real": args.real, "rounds": args.rounds, "runs": []}
    for seed in args.seeds:
        overrides = [f"task={args.task}", f"seed={seed}", f"rounds={args.rounds}", "logging.progress=false",
                     "diagnostics.predictive_sims=0", *[f"task.real_params.{kv}" for kv in args.real], *args.overrides]
        rl_overrides = ["rl=ppo", f"rl.evaluate.episodes={args.episodes}", "rl.evaluate.video_steps=0", *args.rl_overrides]
        run_dir = Path(args.run_dir) / f"{args.task}_seed{seed}"
        t0 = time.perf_counter()
        api.run(overrides, out_dir=run_dir)  # BayesSim only (rl=none): PPO settings do not touch its run dir
        bayessim_seconds = time.perf_counter() - t0
        posterior = api.load_run(run_dir).posterior()
        row = {"seed": seed, "bayessim_seconds": round(bayessim_seconds, 1),
               "posterior_mean": posterior.mean.tolist(), "posterior_std": posterior.stddev.tolist()}
        for train_on in ("posterior", "prior", "nominal"):
            cfg = api.compose(overrides + rl_overrides + [f"rl.train_on={train_on}"])
            results.setdefault("settings", settings(cfg, run_dir))
            comp = build_components(cfg, check_run_config(cfg))
            rounds = StandaloneRounds(cfg, comp, posterior, run_dir / f"ppo_{train_on}")
            row[train_on] = rounds.rl.record(rounds.run_round(1))
            print(f"seed {seed} {train_on:>9s}: surrogate real return {row[train_on]['surrogate_real_return']['mean']:.1f} "
                  f"({row[train_on]['rl_training']['seconds']:.0f} s of PPO)", flush=True)
        results["runs"].append(row)
        out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    plot(results, out.with_suffix(".png"))


def settings(cfg, run_dir: Path) -> dict:
    """What the figure's text quotes about the set-up, from the composed config and the BayesSim run."""
    bayessim = json.loads((run_dir / "results.json").read_text())
    return {"prior": bayessim["prior"], "trajectories": cfg.collect.trajectories, "summarizer": cfg.summarizer.name,
            "model": cfg.model.name, "proposal": cfg.method.proposal, "ppo_steps": cfg.rl.train.total_steps,
            "ppo_envs": cfg.rl.train.num_envs, "episodes": cfg.rl.evaluate.episodes,
            "episode_length": cfg.task.episode_length}


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["posterior", "prior", "nominal"]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for i, name in enumerate(names):
        means = np.array([r[name]["surrogate_real_return"]["mean"] for r in results["runs"]])
        ax.scatter(np.full(len(means), i) + np.linspace(-0.08, 0.08, len(means)), means, color=f"C{i}", zorder=3,
                   label=None)
        ax.errorbar(i + 0.25, means.mean(), yerr=means.std(ddof=1) if len(means) > 1 else 0, fmt="o", color="k",
                    capsize=4)
    ax.set_xticks(range(len(names)), [f"PPO on {n}" for n in names])
    ax.set_ylabel("surrogate real return (mean of episodes)")
    ax.set_title(f"{results['task']}, real {' '.join(results['real'])}: per seed, and mean ± sd", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()

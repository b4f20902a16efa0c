"""BayesSim's headline on a robot: PPO trained on the posterior (after round 1 and after the last round), on the
uniform prior and on the nominal model, each evaluated on surrogate real systems away from the nominal
(docs/results.md, section rl_on_robots).

    OMP_NUM_THREADS=1 PYTHONPATH=src python scripts/rl_on_robots.py --task Cartpole --settings 0 1 2 \
        --seeds 0 1 2 3 4 --out outputs/rl_on_robots/Cartpole.json

A setting k is one surrogate real system: each hidden parameter sits at a prior quantile drawn (generator seeded
with k) from [0.05, 0.2] or [0.8, 0.95], i.e. in the prior's tails, away from its centre where the MJCF's nominal
values lie. For each setting and seed: the BayesSim rounds on that system (the pipeline as `python -m
bayessim_exp`, rl=none), then rl=ppo's train_policy and evaluate stages with the same settings and seed on the
posterior after round 1 and after the last round. The uniform prior's and the nominal model's policies do not
depend on the system: each is trained once per seed and scored on every setting's. A policy's score is its mean
return over `--episodes` surrogate real episodes. `--trained-on` splits a study into jobs (results.py runs the
baselines of a seed apart from its pairs); scores in `--out` are kept and skipped, and BayesSim and PPO skip the
stages their run dirs hold, so a killed study resumes.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np
import torch

from bayessim_exp.artifacts import RunDir

POSTERIORS = ("posterior_round_1", "posterior")
BASELINES = ("prior", "nominal")  # neither depends on the surrogate real system: trained once per seed
TRAINED_ON = POSTERIORS + BASELINES
TAILS = ((0.05, 0.2), (0.8, 0.95))


def real_values(prior, names: list[str], setting: int) -> dict[str, float]:
    """Setting `setting`'s hidden parameters: per parameter a prior quantile in one of TAILS (each tail equally likely)."""
    rng = np.random.default_rng(setting)
    tails = rng.integers(0, 2, len(names))
    quantiles = np.array([rng.uniform(*TAILS[t]) for t in tails])
    values = prior.marginal_icdf(torch.as_tensor(quantiles, dtype=torch.float64)[None])[0]
    return {n: float(v) for n, v in zip(names, values)}


def pair_overrides(task: str, setting: int, seed: int, args) -> tuple[list[str], dict[str, float]]:
    """The run's overrides on setting `setting`'s surrogate real system (BayesSim's, which PPO's extend), and its
    hidden parameters."""
    from bayessim_exp import api, registry

    base = api.compose([f"task={task}", *args.overrides])
    spec = registry.build("task", base.task).spec
    real = real_values(registry.build("prior", base.prior, spec=spec), list(spec.names), setting)
    overrides = [f"task={task}", f"seed={seed}", f"rounds={args.rounds}", "logging.progress=false",
                 "diagnostics.predictive_sims=0", *[f"task.real_params.{n}={v!r}" for n, v in real.items()],
                 *args.overrides]
    return overrides, real


def train_and_score(overrides: list[str], trained_on: str, distribution, out_dir: Path, args) -> tuple[dict, dict]:
    """PPO on `distribution` (None: what rl.train_on builds, the prior or the nominal model), scored on the
    overrides' surrogate real system; a train_policy already saved in `out_dir` is scored, not retrained."""
    from bayessim_exp import api
    from bayessim_exp.components import build_components
    from bayessim_exp.rl.standalone import StandaloneRounds
    from bayessim_exp.run_config import check_run_config

    train_on = trained_on if trained_on in BASELINES else "posterior"
    cfg = api.compose([*overrides, "rl=ppo", f"rl.evaluate.episodes={args.episodes}", "rl.evaluate.video_steps=0",
                       *args.rl_overrides, f"rl.train_on={train_on}"])
    comp = build_components(cfg, check_run_config(cfg))
    rounds = StandaloneRounds(cfg, comp, distribution or comp.prior, out_dir)
    record = rounds.rl.record(rounds.run_round(1))
    ppo = {"steps": cfg.rl.train.total_steps, "envs": cfg.rl.train.num_envs, "episodes": cfg.rl.evaluate.episodes,
           "episode_length": cfg.task.episode_length}
    return {"return": record["surrogate_real_return"], "training": record["rl_training"]}, ppo


def run_posteriors(task: str, setting: int, seed: int, args) -> dict:
    """BayesSim's rounds on setting `setting` (skipping the stages its run dir has), then PPO on the round-1 and
    the last-round posteriors."""
    from bayessim_exp import api

    overrides, real = pair_overrides(task, setting, seed, args)
    run_dir = Path(args.run_dir) / f"{task}_setting{setting}_seed{seed}"
    t0 = time.perf_counter()
    api.run(overrides, out_dir=run_dir)  # BayesSim only (rl=none): PPO's runs go to directories of their own
    row = {"setting": setting, "seed": seed, "real": real, "bayessim_seconds": round(time.perf_counter() - t0, 1)}
    run = api.load_run(run_dir)
    for trained_on, distribution in (("posterior_round_1", run.posterior(1)), ("posterior", run.posterior())):
        if trained_on in args.trained_on:
            row[trained_on], row["ppo"] = train_and_score(overrides, trained_on, distribution,
                                                          run_dir / f"ppo_{trained_on}", args)
            report(task, row, trained_on)
    return row


def run_baselines(task: str, settings: list[int], seed: int, args) -> list[dict]:
    """PPO on the uniform prior and on the nominal model, trained once for `seed` (neither depends on the
    surrogate real system) and scored on every setting's."""
    rows = []
    for setting in settings:
        overrides, real = pair_overrides(task, setting, seed, args)
        row = {"setting": setting, "seed": seed, "real": real}
        for trained_on in (name for name in BASELINES if name in args.trained_on):
            trained = Path(args.run_dir) / f"{task}_seed{seed}_{trained_on}"  # the policy, trained at the first setting
            out_dir = trained if setting == settings[0] else Path(args.run_dir) / f"{task}_setting{setting}_seed{seed}_{trained_on}"
            if out_dir != trained:
                policy = RunDir(out_dir).stage_file(1, "train_policy")
                policy.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(RunDir(trained).stage_file(1, "train_policy"), policy)
            row[trained_on], row["ppo"] = train_and_score(overrides, trained_on, None, out_dir, args)
            report(task, row, trained_on)
        rows.append(row)
    return rows


def report(task: str, row: dict, trained_on: str) -> None:
    score = row[trained_on]
    print(f"{task} setting {row['setting']} seed {row['seed']} {trained_on:>17s}: surrogate real return "
          f"{score['return']['mean']:.1f} ({score['training']['seconds']:.0f} s of PPO)", flush=True)


def merge(runs: list[dict], fresh: list[dict]) -> list[dict]:
    """`runs` with `fresh`'s scores added, one row per (setting, seed)."""
    by_pair = {(r["setting"], r["seed"]): r for r in runs}
    for row in fresh:
        by_pair.setdefault((row["setting"], row["seed"]), {}).update(row)
    return sorted(by_pair.values(), key=lambda r: (r["setting"], r["seed"]))


def t_interval(values) -> tuple[float, float] | None:
    """Student's t 95 % interval of the mean of `values`; None for fewer than two."""
    from scipy import stats

    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return None
    half = stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values))
    return float(values.mean() - half), float(values.mean() + half)


def plot(results: dict, path: Path) -> None:
    """Each pair's score per training distribution (dots, coloured by setting) and the mean with its 95 % interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = results["runs"]
    settings = sorted({r["setting"] for r in runs})
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for i, name in enumerate(TRAINED_ON):
        scores = np.array([r[name]["return"]["mean"] for r in runs])
        colours = [f"C{settings.index(r['setting'])}" for r in runs]
        ax.scatter(np.full(len(scores), i) + np.linspace(-0.12, 0.12, len(scores)), scores, c=colours, s=12, zorder=3)
        interval = t_interval(scores)
        half = 0.0 if interval is None else (interval[1] - interval[0]) / 2
        ax.errorbar(i + 0.3, scores.mean(), yerr=half, fmt="o", color="k", capsize=4)
    ax.set_xticks(range(len(TRAINED_ON)), ["posterior\nround 1", f"posterior\nround {results['rounds']}",
                                           "uniform\nprior", "nominal"])
    ax.set_ylabel("surrogate real return (mean of episodes)")
    ax.set_title(f"{results['task']}: per pair (colour: setting), mean and 95 % interval", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="Cartpole")
    parser.add_argument("--settings", type=int, nargs="+", default=[0, 1, 2], help="surrogate real systems (their seeds)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--trained-on", nargs="+", choices=TRAINED_ON, default=list(TRAINED_ON),
                        help="the policies: posteriors per (setting, seed), baselines once per seed")
    parser.add_argument("--rounds", type=int, default=3, help="BayesSim rounds")
    parser.add_argument("--episodes", type=int, default=16, help="surrogate real evaluation episodes per policy")
    parser.add_argument("--overrides", nargs="*", default=[], help="more Hydra overrides for BayesSim")
    parser.add_argument("--rl-overrides", nargs="*", default=[], help="more overrides for PPO (e.g. sim=mjx device=cuda)")
    parser.add_argument("--out", default="outputs/rl_on_robots/Cartpole.json")
    parser.add_argument("--run-dir", default="outputs/rl_on_robots/runs", help="parent of the per-pair run dirs")
    args = parser.parse_args()
    torch.set_num_threads(1)

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    results = json.loads(out.read_text()) if out.exists() else {"task": args.task, "rounds": args.rounds, "runs": []}

    def missing(names, setting, seed) -> bool:
        row = next((r for r in results["runs"] if (r["setting"], r["seed"]) == (setting, seed)), {})
        return any(n in args.trained_on and n not in row for n in names)

    def save(fresh: list[dict]) -> None:  # after every job's part: a killed study keeps what finished
        results["runs"] = merge(results["runs"], fresh)
        out.write_text(json.dumps(results, indent=1))

    for seed in args.seeds:
        if any(missing(BASELINES, setting, seed) for setting in args.settings):
            save(run_baselines(args.task, args.settings, seed, args))
        for setting in args.settings:
            if missing(POSTERIORS, setting, seed):
                save([run_posteriors(args.task, setting, seed, args)])


if __name__ == "__main__":
    main()

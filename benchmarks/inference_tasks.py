"""Inference on the robot tasks: does the posterior beat the prior, and is it calibrated?

    OMP_NUM_THREADS=1 PYTHONPATH=src python3 benchmarks/inference_tasks.py --task Ant --summarizer corrdiff \
        --sims 20000 --test 200 --models linear mdnn mdnn:probit:covariance=diagonal

For a task: `--sims` simulations from the prior under the random collect policy (cached by
benchmarks/task_simulations.py) train every model; `--test` further simulations are held out. Per
model, on the held-out pairs (theta*, x*), each posterior is conditioned exactly as the pipeline
conditions one real trajectory, and the table gives

- the mean and median log-density gain log q(theta* | x*) - log p(theta*) (nats; 0 is the prior),
  and the share of held-out cases where it is negative;
- the expected coverage of the 50 % and 90 % highest-density regions (calibrated: 0.5 and 0.9);
- posterior std / prior std per parameter (mean, min, max over parameters, averaged over cases);
- fit seconds and seconds to condition on one trajectory (mean over the held-out cases), one thread;
- the number of held-out cases scored (all `--test`, or fewer where `--eval-seconds` ran out);
- the guard's verdict (diagnostics/guard.py).

A model spec is `name[:space][:key=value,key=value]`: name a conf/model YAML (its values, composed as
`model=name` would be, are the defaults), space `box` (fitted in parameter units, posterior truncated to
the box; taken when no space is named) or `probit` (distributions/probit.py; the pipeline's default
since issue 11). `linear` is the ridge-regression baseline
(models/linear.py); every run should include it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch
import yaml
from omegaconf import OmegaConf

from bayessim_exp import api
from bayessim_exp.diagnostics.guard import check_posterior
from task_simulations import DEFAULT_CACHE, components, load_simulations

LEVELS = (0.5, 0.9)


def parse_spec(spec: str) -> tuple[str, bool, dict]:
    parts = spec.split(":")
    name, space, overrides = parts[0], "box", {}
    for part in parts[1:]:
        if part in ("box", "probit"):
            space = part
        elif part:
            for item in part.split(","):
                key, _, value = item.partition("=")
                overrides[key] = yaml.safe_load(value)
    # composed as the CLI would: a variant (conf/model/mdnn_projected_diagonal.yaml) builds the model it names
    cfg = OmegaConf.to_container(api.compose([f"model={name}"]).model)
    cfg.update(overrides)
    return cfg.pop("name"), space == "probit", cfg


def summaries(task: str, summarizer: str, n: int, horizon: int, cache: Path, nthread: int, seconds: float):
    theta, traj, sim_seconds = load_simulations(task, n, horizon, cache=cache, nthread=nthread, seconds=seconds)
    _, comp = components(task, summarizer=summarizer)
    keep = ~traj.diverged
    x = comp.summarizer(traj.select(keep))
    finite = torch.isfinite(x).all(1)
    return theta[keep][finite], x[finite].double(), comp.prior, comp.task.spec.names, sim_seconds


@torch.no_grad()
def evaluate(fitted, prior, theta_test: torch.Tensor, x_test: torch.Tensor, draws: int, seed: int,
             budget: float) -> dict:
    """Scores the held-out cases in order until `budget` seconds are spent (at least one case)."""
    gains, hpd, std_ratio, seconds = [], [], [], []
    prior_std = prior.stddev.double()
    start = time.perf_counter()
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        for theta_i, x_i in zip(theta_test, x_test):
            if gains and time.perf_counter() - start > budget:
                break
            t0 = time.perf_counter()
            post = fitted.posterior(x_i)
            seconds.append(time.perf_counter() - t0)
            lp_true = post.log_prob(theta_i[None])[0]
            gains.append(float(lp_true - prior.log_prob(theta_i[None])[0]))
            sample = post.sample((draws,)).double()
            hpd.append(float((post.log_prob(sample) > lp_true).double().mean()))
            std_ratio.append(sample.std(0) / prior_std)
    gains, hpd, ratio = torch.tensor(gains), torch.tensor(hpd), torch.stack(std_ratio).mean(0)
    return {"mean_gain": float(gains.mean()), "median_gain": float(gains.median()),
            "worse": float((gains < 0).double().mean()),
            "coverage": {f"{lv:g}": float((hpd < lv).double().mean()) for lv in LEVELS},
            "std_ratio": (float(ratio.mean()), float(ratio.min()), float(ratio.max())),
            "condition_seconds": sum(seconds) / len(seconds), "cases": len(gains)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", required=True)
    parser.add_argument("--summarizer", default="start")
    parser.add_argument("--sims", type=int, default=20000, help="training simulations (the budget)")
    parser.add_argument("--test", type=int, default=200, help="held-out simulations")
    parser.add_argument("--horizon", type=int, default=50)
    parser.add_argument("--draws", type=int, default=500, help="posterior draws per held-out case for coverage")
    parser.add_argument("--models", nargs="+", default=["linear", "mdnn"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--nthread", type=int, default=0, help="simulation threads (0: all CPUs)")
    parser.add_argument("--sim-seconds", type=float, default=float("inf"),
                        help="stop simulating after this long (fewer simulations than asked; the table says how many)")
    parser.add_argument("--eval-seconds", type=float, default=float("inf"),
                        help="per model, stop scoring held-out cases after this long (the table says how many)")
    parser.add_argument("--device", default="cpu", help="where the networks train (cuda: a GPU); linear fits on the CPU")
    parser.add_argument("--fit-threads", type=int, default=1, help="torch CPU threads while fitting (scoring: one)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    # the held-out cases are the `test` simulations after the training ones
    n_total = args.sims + args.test
    theta, x, prior, names, sim_seconds = summaries(args.task, args.summarizer, n_total, args.horizon, args.cache,
                                                    args.nthread, args.sim_seconds)
    n_test = min(args.test, len(theta) // 10)
    theta_train, x_train = theta[:-n_test], x[:-n_test]
    theta_test, x_test = theta[-n_test:], x[-n_test:]
    print(f"{args.task}: {len(names)} parameters, {args.summarizer} summaries of {x.shape[1]} features, "
          f"{len(theta_train)} training / {n_test} held-out simulations (simulation: {sim_seconds:.1f} s per 1000)",
          flush=True)
    rows = []
    for spec in args.models:
        name, probit, cfg = parse_spec(spec)
        torch.set_num_threads(args.fit_threads)
        t0 = time.perf_counter()
        device = "cpu" if name == "linear" else args.device
        fitted = api.fit_posterior_model(name, theta_train, x_train.to(device), prior=prior, seed=args.seed,
                                         probit=probit, **cfg)
        fit_seconds = time.perf_counter() - t0
        torch.set_num_threads(1)
        try:
            result = evaluate(fitted, prior, theta_test, x_test, args.draws, args.seed, args.eval_seconds)
        except ValueError as exc:  # e.g. no posterior mass inside the box: the model failed, report it as such
            print(f"{spec}: conditioning failed: {exc}", flush=True)
            rows.append((spec, None, fit_seconds, fitted.history.get("epochs")))
            continue
        result["guard"] = check_posterior(result["mean_gain"], result["coverage"], result["cases"])
        rows.append((spec, result, fit_seconds, fitted.history.get("epochs")))
        r = result
        print(f"{spec}: gain mean {r['mean_gain']:+.2f} median {r['median_gain']:+.2f} worse {r['worse']:.0%} "
              f"cov50 {r['coverage']['0.5']:.2f} cov90 {r['coverage']['0.9']:.2f} std/prior {r['std_ratio'][0]:.2f} "
              f"fit {fit_seconds:.1f} s ({fitted.history.get('epochs')} epochs) condition {r['condition_seconds']:.3f} s "
              f"({r['cases']} cases)",
              flush=True)
    print("\n| task | summarizer | sims | model | mean gain | median gain | worse than prior | cov 50 % | cov 90 % "
          "| post/prior std mean (min-max) | fit s (epochs) | condition s | cases | guard |")
    print("|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for spec, r, fit_seconds, epochs in rows:
        head = f"| {args.task} | {args.summarizer} | {len(theta_train)} | {spec} "
        if r is None:
            print(head + f"| failed | | | | | | {fit_seconds:.1f} ({epochs}) | | | |")
            continue
        s = r["std_ratio"]
        verdict = "ok" if r["guard"].ok else "; ".join(w.split(":")[0] for w in r["guard"].warnings)
        print(head + f"| {r['mean_gain']:+.2f} | {r['median_gain']:+.2f} | {r['worse']:.0%} | {r['coverage']['0.5']:.2f} "
              f"| {r['coverage']['0.9']:.2f} | {s[0]:.2f} ({s[1]:.2f}-{s[2]:.2f}) | {fit_seconds:.1f} ({epochs}) "
              f"| {r['condition_seconds']:.3f} | {r['cases']} | {verdict} |")


if __name__ == "__main__":
    main()

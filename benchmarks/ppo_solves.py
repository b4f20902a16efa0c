"""How robustly PPO with a task's settings (conf/rl_task) solves its nominal model: the claim of
tests/integration/test_ppo_solves.py over training seeds and step budgets, one process of one thread per run.

    PYTHONPATH=src python benchmarks/ppo_solves.py [--task Cartpole] [--seeds 0 1 2 3] [--steps 80000 120000]
        [--jobs 4]

Prints per budget each seed's mean and minimum return over the 16 evaluation episodes of the deterministic policy
(the test's bar for Cartpole: a mean of 475), and how many seeds reach the bar.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from concurrent.futures import ProcessPoolExecutor

BARS = {"Cartpole": 475.0, "Pendulum": -400.0}  # tests/integration/test_ppo_solves.py's


def train(task: str, seed: int, steps: int) -> tuple[float, float]:
    import torch

    from bayessim_exp import api, registry
    from bayessim_exp.components import build_components
    from bayessim_exp.rl.standalone import StandaloneRounds
    from bayessim_exp.run_config import check_run_config

    torch.set_num_threads(1)
    spec = registry.build("task", api.compose([f"task={task}"]).task).spec
    nominal_is_real = [f"task.real_params.{n}={v}" for n, v in zip(spec.names, spec.nominal)]
    cfg = api.compose([f"task={task}", "rl=ppo", "rl.train_on=nominal", "rl.evaluate.video_steps=0", f"seed={seed}",
                       f"rl.train.total_steps={steps}", *nominal_is_real])
    comp = build_components(cfg, check_run_config(cfg))
    rounds = StandaloneRounds(cfg, comp, comp.prior, tempfile.mkdtemp())
    ret = rounds.rl.record(rounds.run_round(1))["surrogate_real_return"]
    return ret["mean"], ret["min"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="Cartpole", choices=sorted(BARS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--steps", type=int, nargs="+", default=[80000])
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    runs = [(steps, seed) for steps in args.steps for seed in args.seeds]
    with ProcessPoolExecutor(args.jobs) as pool:
        returns = dict(zip(runs, pool.map(train, [args.task] * len(runs), [s for _, s in runs], [n for n, _ in runs])))
    bar = BARS[args.task]
    print(f"{args.task}, torch {torch.__version__}; mean (min) return of 16 episodes per seed; bar {bar:g}")
    for steps in args.steps:
        cells = [f"{returns[steps, s][0]:.1f} ({returns[steps, s][1]:.1f})" for s in args.seeds]
        passed = sum(returns[steps, s][0] >= bar for s in args.seeds)
        print(f"{steps:>8} steps: " + ", ".join(f"seed {s} {c}" for s, c in zip(args.seeds, cells))
              + f"; {passed} of {len(args.seeds)} reach the bar")


if __name__ == "__main__":
    main()

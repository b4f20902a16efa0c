"""PPO training throughput and Cartpole's wall time to 95 % of the maximum return.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/rl.py                      # CPU, native backend
    python benchmarks/rl.py --steps 262144 --overrides sim=mjx device=cuda rl.train.num_envs=4096 \
        rl.train.rollout_steps=16 rl.train.minibatch_size=16384 rl.train.total_steps=3000000  # GPU (docs/benchmarks.md)

Throughput, per task: environment steps per second of (1) `Simulator.rollout` with random actions
(the simulator alone, the baseline), (2) torchrl's Collector over SimulatorEnv with PPO's actor (the
environment wrapper and the policy, no learning) and (3) PPO training, updates included, with the
task's rl=ppo settings (conf/rl/ppo.yaml, conf/rl_task). Then Cartpole's PPO with its own settings
until the mean return of the episodes finished in a batch reaches 95 % of the 500 an episode can earn,
within its budget (its rl.train.total_steps, or one given in --overrides). Step counts are rounded up to
whole PPO batches (num_envs x rollout_steps): with 4,096 environments of 32 steps a batch is 131,072 steps,
more than the 32,768 of a default measurement or Cartpole's budget of 80,000.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch


def components(task: str, overrides: list[str], steps: int | None = None):
    """The task's run with rl=ppo; PPO's total_steps (`steps`, else the configured budget) rounded up to whole
    batches, which PPO's config requires."""
    from bayessim_exp import api
    from bayessim_exp.components import build_components, build_rl
    from bayessim_exp.run_config import check_run_config

    cfg = api.compose([f"task={task}", "rl=ppo", "rl.train_on=nominal", *overrides])
    train = cfg.rl.train
    batch = train.num_envs * train.rollout_steps
    train.total_steps = -(-(steps or train.total_steps) // batch) * batch
    comp = build_components(cfg, check_run_config(cfg))
    return comp, build_rl(cfg, comp, lambda ctx: comp.prior)  # train_on=nominal asks for no distribution


def throughput(task: str, steps: int, overrides: list[str]) -> dict:
    from torchrl.collectors import Collector

    from bayessim_exp.policies import RandomPolicy
    from bayessim_exp.rl.env import SimulatorEnv, fixed_params

    comp, rl = components(task, overrides, steps)
    cfg = rl.train_cfg
    sim = comp.sims.get(cfg.num_envs)
    nominal = np.repeat(comp.task.spec.nominal[None], cfg.num_envs, 0)
    horizon = cfg.total_steps // cfg.num_envs
    # untimed first calls: on MJX they compile the fused rollout and the single step
    sim.rollout(nominal, RandomPolicy(comp.task.action_dim, 0), horizon)
    sim.reset(nominal, None, 0)
    sim.step(torch.zeros(cfg.num_envs, comp.task.action_dim))
    t0 = time.perf_counter()
    sim.rollout(nominal, RandomPolicy(comp.task.action_dim, 0), horizon)
    rollout = cfg.num_envs * horizon / (time.perf_counter() - t0)

    trainer = rl.trainer()
    env = SimulatorEnv(sim, fixed_params(comp.task.spec.nominal), 0)
    collector = Collector(env, trainer.actor, frames_per_batch=cfg.num_envs * cfg.rollout_steps,
                          total_frames=cfg.total_steps, auto_register_policy_transforms=False)
    t0, frames = time.perf_counter(), 0
    for batch in collector:
        frames += batch.numel()
    collect = frames / (time.perf_counter() - t0)
    collector.shutdown()

    t0 = time.perf_counter()
    curve = rl.trainer().train(SimulatorEnv(sim, fixed_params(comp.task.spec.nominal), 0), seed=0)
    train = curve["steps"][-1] / (time.perf_counter() - t0)
    return {"task": task, "envs": cfg.num_envs, "steps": curve["steps"][-1], "rollout": rollout, "collect": collect,
            "train": train, "update_share": sum(curve["update_seconds"]) / curve["seconds"][-1]}


def time_to_95(overrides: list[str]) -> dict:
    from bayessim_exp.rl.env import SimulatorEnv, fixed_params

    comp, rl = components("Cartpole", overrides)
    target = 0.95 * comp.task.cfg.episode_length  # at most 1 per step
    env = SimulatorEnv(comp.sims.get(rl.train_cfg.num_envs), fixed_params(comp.task.spec.nominal), 0)
    curve = rl.trainer().train(env, seed=0)
    reached = [i for i, r in enumerate(curve["episode_return"]) if np.isfinite(r) and r >= target]
    first = reached[0] if reached else None
    return {"target": target, "seconds": None if first is None else curve["seconds"][first],
            "steps": None if first is None else curve["steps"][first], "budget_steps": curve["steps"][-1],
            "best": float(np.nanmax(curve["episode_return"]))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=["Cartpole", "Ant"])
    ap.add_argument("--steps", type=int, default=32768,
                    help="environment steps per throughput measurement, rounded up to whole PPO batches")
    ap.add_argument("--overrides", nargs="*", default=[],
                    help="Hydra overrides, e.g. sim=mjx device=cuda (rl.train.total_steps: the Cartpole run's budget)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)  # network initialisation
    rows = [throughput(task, args.steps, args.overrides) for task in args.tasks]
    print(f"overrides: {' '.join(args.overrides) or '(none)'}; torch threads 1")
    print("| task | envs | steps | Simulator.rollout, random actions (baseline) | Collector + actor "
          "| PPO incl. updates | share of PPO time in updates |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['task']} | {r['envs']} | {r['steps']:,} | {r['rollout']:,.0f} "
              f"| {r['collect']:,.0f} ({r['collect'] / r['rollout']:.2f}x) "
              f"| {r['train']:,.0f} ({r['train'] / r['rollout']:.2f}x) | {r['update_share']:.0%} |")
    t = time_to_95(args.overrides)
    if t["seconds"] is None:
        print(f"Cartpole: 95 % of the maximum return ({t['target']:.0f}) not reached in {t['budget_steps']:,} steps "
              f"(best batch mean {t['best']:.1f})")
    else:
        print(f"Cartpole: mean training episode return >= {t['target']:.0f} (95 % of the maximum) after "
              f"{t['seconds']:.1f} s, {t['steps']:,} steps")


if __name__ == "__main__":
    main()

"""PPO training throughput per collection path, and Cartpole's wall time to 95 % of the maximum return.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/rl.py                  # CPU, native backend, task settings
    python benchmarks/rl.py --tasks Cartpole Ant --overrides sim=mjx device=cuda rl.train.num_envs=8192 \
        rl.train.rollout_steps=16 rl.train.minibatch_size=32768 rl.train.epochs=5   # GPU (docs/benchmarks.md)

Rows per task, environment steps per second:
  simulator   `Simulator.rollout` with open-loop random actions: the simulator alone, the baseline
  compiled    PPO incl. updates, the actor inside MJX's compiled rollout (rl/compiled_collection.py; MJX only)
  stepwise    PPO incl. updates, torchrl's Collector stepping SimulatorEnv (one simulator and one actor call per step)
Each PPO figure is one timed `train` call of `--steps` steps (`--stepwise-steps` for the stepwise path, slow on a
GPU) after an untimed call of one batch on the same simulator: that first call compiles, and its time beyond a
timed batch's is reported as compilation. Cartpole's run to 95 % of the 500 an episode can earn (the mean return
of the training episodes finished in a batch) uses the same settings, within `--solve-steps` steps, on the
collection path `rl.train.collector` picks, after the same untimed first batch. Step counts are rounded up to
whole PPO batches (num_envs x rollout_steps). `--curve TASK` prints TASK's learning curve on its nominal model
instead (how many steps a budget needs), e.g. `python benchmarks/rl.py --curve Ant --solve-steps 25000000
--overrides sim=mjx device=cuda rl.train.num_envs=8192 rl.train.rollout_steps=16 rl.train.minibatch_size=32768
rl.train.epochs=5`.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

PATHS = ("compiled", "stepwise")


def components(task: str, overrides: list[str], steps: int):
    """The task's run with rl=ppo on its nominal model, PPO's total_steps `steps` rounded up to whole batches."""
    from bayessim_exp import api
    from bayessim_exp.components import build_components, build_rl
    from bayessim_exp.run_config import check_run_config

    cfg = api.compose([f"task={task}", "rl=ppo", "rl.train_on=nominal", *overrides])
    train = cfg.rl.train
    batch = train.num_envs * train.rollout_steps
    train.total_steps = -(-steps // batch) * batch
    comp = build_components(cfg, check_run_config(cfg))
    return comp, build_rl(cfg, comp, lambda ctx: comp.prior)  # train_on=nominal asks for no distribution


def train_once(comp, rl, collector: str, steps: int | None = None, seed: int = 0, on_batch=None) -> dict:
    """One PPO train call of `steps` steps (one batch when None) on the nominal model with `collector`."""
    import dataclasses

    from bayessim_exp.rl.env import SimulatorEnv, fixed_params
    from bayessim_exp.rl.ppo import PPOTrainer

    cfg = rl.train_cfg
    batch = cfg.num_envs * cfg.rollout_steps
    cfg = dataclasses.replace(cfg, collector=collector, total_steps=batch if steps is None else -(-steps // batch) * batch)
    sim = comp.sims.get(cfg.num_envs)
    trainer = PPOTrainer(cfg, comp.task.obs_dim, comp.task.action_dim, rl.device)
    env = SimulatorEnv(sim, fixed_params(comp.task.spec.nominal), seed, draw_steps=cfg.rollout_steps)
    t0 = time.perf_counter()
    curve = trainer.train(env, seed=seed, on_batch=on_batch)
    return {"steps": curve["steps"][-1], "seconds": time.perf_counter() - t0, "curve": curve, "batch": batch}


def compiled_available(comp, rl) -> bool:
    return getattr(comp.sims.get(rl.train_cfg.num_envs), "closes_loops", False)


def throughput(task: str, steps: int, stepwise_steps: int, overrides: list[str]) -> dict:
    from bayessim_exp.policies import RandomPolicy

    comp, rl = components(task, overrides, steps)
    cfg = rl.train_cfg
    sim = comp.sims.get(cfg.num_envs)
    nominal = np.repeat(comp.task.spec.nominal[None], cfg.num_envs, 0)
    horizon = max(1, steps // cfg.num_envs)
    sim.rollout(nominal, RandomPolicy(comp.task.action_dim, 0), horizon)  # untimed: compiles on MJX
    t0 = time.perf_counter()
    sim.rollout(nominal, RandomPolicy(comp.task.action_dim, 0), horizon)
    row = {"task": task, "envs": cfg.num_envs, "rollout_steps": cfg.rollout_steps, "epochs": cfg.epochs,
           "minibatch": cfg.minibatch_size, "simulator": cfg.num_envs * horizon / (time.perf_counter() - t0)}
    for path, n in zip(PATHS, (steps, stepwise_steps)):
        if n == 0 or path == "compiled" and not compiled_available(comp, rl):
            continue
        first = train_once(comp, rl, path)
        timed = train_once(comp, rl, path, n)
        per_batch = timed["seconds"] / (timed["steps"] / timed["batch"])
        curve = timed["curve"]
        row[path] = {"steps": timed["steps"], "steps_per_s": timed["steps"] / timed["seconds"],
                     "compile_s": max(0.0, first["seconds"] - per_batch),
                     "update_share": sum(curve["update_seconds"]) / curve["seconds"][-1]}
    return row


def time_to_95(overrides: list[str], solve_overrides: list[str], budget: int) -> dict:
    comp, rl = components("Cartpole", [*overrides, *solve_overrides], budget)
    path = "compiled" if rl.train_cfg.collector != "stepwise" and compiled_available(comp, rl) else "stepwise"
    first = train_once(comp, rl, path)
    run = train_once(comp, rl, path, budget)
    target = 0.95 * comp.task.cfg.episode_length  # at most 1 per step
    curve = run["curve"]
    reached = [i for i, r in enumerate(curve["episode_return"]) if np.isfinite(r) and r >= target]
    first_hit = reached[0] if reached else None
    per_batch = run["seconds"] / len(curve["steps"])
    cfg = rl.train_cfg
    settings = (f"{cfg.num_envs} x {cfg.rollout_steps}, {cfg.epochs} x {cfg.minibatch_size}, lr {cfg.lr}"
                + (f" (overrides: {' '.join(solve_overrides)})" if solve_overrides else ""))
    return {"path": path, "target": target, "budget_steps": curve["steps"][-1], "settings": settings,
            "seconds": None if first_hit is None else curve["seconds"][first_hit],
            "steps": None if first_hit is None else curve["steps"][first_hit],
            "compile_s": max(0.0, first["seconds"] - per_batch), "best": float(np.nanmax(curve["episode_return"]))}


def learning_curve(task: str, overrides: list[str], budget: int, lines: int = 20) -> None:
    """`task`'s PPO on its nominal model for `budget` steps after an untimed first batch, printing about `lines`
    points of its curve as it goes (seconds since the start, steps, mean return of the episodes that batch ended)."""
    comp, rl = components(task, overrides, budget)
    path = "compiled" if rl.train_cfg.collector != "stepwise" and compiled_available(comp, rl) else "stepwise"
    first = train_once(comp, rl, path)
    batch = first["batch"]
    every = max(1, budget // batch // lines)
    t0 = time.perf_counter()
    print(f"{task} on its nominal model, {path} collection, first batch (compilation) {first['seconds']:.1f} s", flush=True)

    def on_batch(steps: int, stats: dict) -> None:
        if steps // batch % every == 0:
            print(f"  {time.perf_counter() - t0:7.1f} s  {steps:>12,} steps  return {stats.get('episode_return', float('nan')):.1f}",
                  flush=True)

    curve = train_once(comp, rl, path, budget, on_batch=on_batch)["curve"]
    print(f"{task}: best batch mean return {np.nanmax(curve['episode_return']):.1f} in {curve['steps'][-1]:,} steps, "
          f"{curve['seconds'][-1]:.1f} s")


def print_tables(rows: list[dict], solve: dict, overrides: list[str]) -> None:
    print(f"overrides: {' '.join(overrides) or '(none)'}; torch threads {torch.get_num_threads()}")
    print("| task | envs x steps, epochs x minibatch | simulator alone (baseline) | PPO, compiled collection "
          "| PPO, stepwise Collector | compilation s (compiled / stepwise) | share in updates (compiled / stepwise) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        paths = [r.get(path) for path in PATHS]
        rates = ["-" if x is None else f"{x['steps_per_s']:,.0f} ({x['steps_per_s'] / r['simulator']:.2f}x)"
                 for x in paths]
        compile_s, share = (" / ".join("-" if x is None else format(x[key], spec) for x in paths)
                            for key, spec in (("compile_s", ".1f"), ("update_share", ".0%")))
        print(f"| {r['task']} | {r['envs']} x {r['rollout_steps']}, {r['epochs']} x {r['minibatch']} "
              f"| {r['simulator']:,.0f} | {rates[0]} | {rates[1]} | {compile_s} | {share} |")
    print(f"Cartpole's run to 95 %: {solve['settings']}")
    if solve["seconds"] is None:
        print(f"Cartpole ({solve['path']}): 95 % of the maximum return ({solve['target']:.0f}) not reached in "
              f"{solve['budget_steps']:,} steps (best batch mean {solve['best']:.1f})")
    else:
        print(f"Cartpole ({solve['path']} collection): mean training episode return >= {solve['target']:.0f} "
              f"(95 % of the maximum) after {solve['seconds']:.1f} s and {solve['steps']:,} steps, compilation "
              f"({solve['compile_s']:.1f} s) before it, not included")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="*", default=["Cartpole", "Ant"], help="throughput rows (none: Cartpole's run alone)")
    ap.add_argument("--steps", type=int, default=32768, help="timed PPO steps, compiled path (and the simulator's)")
    ap.add_argument("--stepwise-steps", type=int, default=None, help="timed PPO steps, stepwise path (default --steps; 0: no stepwise row)")
    ap.add_argument("--solve-steps", type=int, default=80000, help="Cartpole's budget to reach 95 %% of the maximum")
    ap.add_argument("--overrides", nargs="*", default=[], help="Hydra overrides, e.g. sim=mjx device=cuda")
    ap.add_argument("--solve-overrides", nargs="*", default=[], help="more overrides for Cartpole's run to 95 %%")
    ap.add_argument("--curve", default=None, metavar="TASK",
                    help="instead of Cartpole's run to 95 %%: TASK's learning curve over --solve-steps steps")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)  # network initialisation
    if args.curve:
        learning_curve(args.curve, [*args.overrides, *args.solve_overrides], args.solve_steps)
        return
    rows = [throughput(t, args.steps, args.stepwise_steps or args.steps, args.overrides) for t in args.tasks]
    solve = time_to_95(args.overrides, args.solve_overrides, args.solve_steps)
    print_tables(rows, solve, args.overrides)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"overrides": args.overrides, "rows": rows, "cartpole_95": solve}, f, indent=1)


if __name__ == "__main__":
    main()

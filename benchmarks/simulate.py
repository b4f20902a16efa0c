"""Collection throughput of the native backend against a plain per-environment MuJoCo loop.

    python benchmarks/simulate.py [--task Pendulum] [--envs 4096] [--horizon 50]

Prints env-steps/s (control steps) for NativeSimulator.rollout (mujoco.batch, per-env
parameters, observations, rewards, divergence checks) and, as the baseline in the same run, a
Python loop over one MjData per environment stepping the same model with the same frame skip.
"""

import argparse
import time

import mujoco
import numpy as np

from bayessim_exp import api, registry
from bayessim_exp.policies import RandomPolicy


def batched(task, envs, horizon, nthread):
    params = np.repeat(task.true_params[None], envs, 0)
    sim = registry.build("sim", {"name": "native", "nthread": nthread})(task, envs)
    t0 = time.perf_counter()
    sim.rollout(params, RandomPolicy(task.action_dim, 0), horizon, seed=0)
    return envs * horizon / (time.perf_counter() - t0)


def per_env_loop(task, envs, horizon):
    model = task.model
    datas = [mujoco.MjData(model) for _ in range(envs)]
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(horizon):
        for d in datas:
            d.ctrl[:] = task.ctrl(rng.uniform(-1, 1, task.action_dim))
            mujoco.mj_step(model, d, nstep=task.frame_skip)
    return envs * horizon / (time.perf_counter() - t0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="Pendulum")
    ap.add_argument("--envs", type=int, default=4096)
    ap.add_argument("--horizon", type=int, default=50)
    args = ap.parse_args()
    task = registry.build("task", api.compose([f"task={args.task}"]).task)
    rows = [("per-env MjData loop (baseline)", 1, per_env_loop(task, min(args.envs, 512), args.horizon))]
    for nthread in (1, 2):
        rows.append((f"NativeSimulator.rollout, {nthread} thread(s)", nthread, batched(task, args.envs, args.horizon, nthread)))
    base = rows[0][2]
    print(f"task={args.task} envs={args.envs} horizon={args.horizon} frame_skip={task.frame_skip}")
    print(f"{'backend':<40} {'env-steps/s':>12} {'vs baseline':>12}")
    for name, _, rate in rows:
        print(f"{name:<40} {rate:>12,.0f} {rate / base:>11.1f}x")


if __name__ == "__main__":
    main()

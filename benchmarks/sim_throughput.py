"""Simulation throughput of every task on both backends, with and without randomization, in one run.

    python benchmarks/sim_throughput.py [--tasks Pendulum,Humanoid] [--envs 8192,32768] [--horizon 100]
        [--native-envs 8192] [--native-horizon 10] [--baseline-envs 8192,131072] [--json out.json]
        [--compile-only] [--rows mjx-plain,mjx] [--overrides '++sim.tuning.max_geom_pairs=8']
        [--impl auto|jax|warp]

Env-steps/s counts control steps (each `frame_skip` physics steps; the physics rate is the product)
over whole `rollout` calls: resets with per-env parameters (fields and derived constants computed on
the device, mjx_constants; benchmarks/reset_cost.py splits a reset's cost), the open-loop random
policy's actions, observations, rewards, divergence checks and the trajectories handed to torch. Rows per task:
  native      NativeSimulator on all CPU threads, randomized: the baseline in the same run
  native-rk4  the same with its slots alternating the model's integrator and RK4 (what BayesSim simulates with
              recorded data: sim/integrators.py)
  mjx-plain   plain MJX on the nominal model with the task's MJX tuning (conf/mjx_tuning; vmap(mjx.step) in lax.scan,
              random controls, no task code)
  mjx-fixed   MjxSimulator with randomize=False (one model for every slot)
  mjx         MjxSimulator with a parameter set per slot drawn from the prior's box
The MJX rows run the implementation `--impl` resolves to for each task (sim.impl: JAX, or MuJoCo Warp; auto
takes the task's tuning's `impl`), shown in the impl column.
"randomization overhead" = 1 - mjx / mjx-fixed at the same size (sizes in --baseline-envs). Each figure is the median of
`--reps` timed calls after a first call (compilation, or a persistent-cache load, included, reported
as `first s`). `--compile-only` makes the first calls alone, to fill JAX's persistent cache
(`--cache-dir`) from several processes at once before a timed run. benchmarks/auto_choice.py reads the
`--json` file: what sim=auto picks beside the native and mjx rows.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import time

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from bayessim_exp import api, registry  # noqa: E402
from bayessim_exp.policies import Policy  # noqa: E402
from bayessim_exp.sim.integrators import RECORDED_DATA  # noqa: E402
from bayessim_exp.sim.mjx import MjxConfig, MjxSimulator  # noqa: E402
from bayessim_exp.sim.mjx_impl import resolve_impl  # noqa: E402
from bayessim_exp.sim.mjx_setup import jax_setup  # noqa: E402
from bayessim_exp.sim.native import NativeConfig, NativeSimulator  # noqa: E402


class OpenLoopRandom(Policy):
    """Uniform random actions drawn where the simulator runs (the collect policy's distribution)."""

    def __init__(self, action_dim: int, device: torch.device, seed: int = 0):
        self.action_dim, self.device = action_dim, device
        self.generator = torch.Generator(device=device).manual_seed(seed)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.rand(obs.shape[0], self.action_dim, generator=self.generator, device=self.device) * 2 - 1

    def open_loop_actions(self, n: int, horizon: int) -> torch.Tensor:
        return torch.rand(n, horizon, self.action_dim, generator=self.generator, device=self.device) * 2 - 1


def sync() -> None:
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def timed(call, reps: int) -> tuple[float, float | None]:
    """(first call's seconds, median seconds of `reps` more calls or None)."""
    t0 = time.perf_counter()
    call()
    sync()
    first = time.perf_counter() - t0
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        call()
        sync()
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times) if times else None


def prior_params(task, n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(task.spec.low, task.spec.high, (n, task.spec.dim))


def simulator_rollouts(task, envs: int, horizon: int, sim, reps: int) -> tuple[float, float | None]:
    params = prior_params(task, envs)
    policy = OpenLoopRandom(task.action_dim, sim.device)

    def call():
        traj = sim.rollout(params, policy, horizon, seed=1)
        if traj.diverged.float().mean() > 0.01:
            print(f"  note: {int(traj.diverged.sum())} of {envs} {task.name} slots diverged")

    return timed(call, reps)


def plain_mjx(task, envs: int, horizon: int, reps: int, cfg: MjxConfig) -> tuple[float, float | None]:
    import jax

    sim = MjxSimulator(task, envs, cfg, randomize=False)  # its nominal model, data sizes and implementation
    m, mx, data, step = sim.mj_model, sim.nominal, sim.data, sim.mjx.step
    lo, hi = jax.numpy.asarray(m.actuator_ctrlrange.T, jax.numpy.float32)

    @jax.jit
    def run(data, key):
        def control(d, k):
            ctrl = jax.random.uniform(k, (envs, m.nu), minval=lo, maxval=hi)
            d = d.replace(ctrl=ctrl)
            d = jax.lax.fori_loop(0, task.frame_skip, lambda _, x: jax.vmap(step, (None, 0))(mx, x), d)
            return d, d.qpos[:, 0]
        return jax.lax.scan(control, data, jax.random.split(key, horizon))

    return timed(lambda: jax.block_until_ready(run(data, jax.random.PRNGKey(0))), reps)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", default=",".join(registry.names("task")))
    ap.add_argument("--envs", default="8192,32768")
    ap.add_argument("--horizon", type=int, default=100)
    ap.add_argument("--native-envs", type=int, default=8192)
    ap.add_argument("--native-horizon", type=int, default=10)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--baseline-envs", default="8192",
                    help="sizes of the mjx-fixed rows (the first also of the mjx-plain row)")
    ap.add_argument("--overrides", nargs="*", default=[], help="config overrides, e.g. 'sim.tuning.iterations=4'")
    ap.add_argument("--cache-dir", default=None, help="JAX's persistent compilation cache")
    ap.add_argument("--compile-only", action="store_true")
    ap.add_argument("--rows", default="native,mjx-plain,mjx-fixed,mjx",
                    help="which rows (compilation phases split them across processes)")
    ap.add_argument("--impl", default="auto", help="sim.impl: jax, warp or auto")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    jax = jax_setup(args.cache_dir)
    base = MjxConfig(max_abs_qvel=1.0e4, cache_dir=args.cache_dir, nthread=0, native_below=0, impl=args.impl, tuning={})
    reps = 0 if args.compile_only else args.reps
    rows_wanted = set(args.rows.split(","))
    rows = []

    def record(task, backend, envs, horizon, first, median):
        rate = None if median is None else envs * horizon / median
        rows.append({"task": task.name, "impl": "-" if backend.startswith("native") else resolve_impl(args.impl, cfg.tuning), "backend": backend, "envs": envs, "horizon": horizon,
                     "frame_skip": task.frame_skip, "first_s": round(first, 2), "median_s": median,
                     "env_steps_per_s": rate})
        shown = "-" if rate is None else f"{rate:,.0f}"
        print(f"{task.name:<16} {backend:<10} {rows[-1]['impl']:<5} {envs:>8} x {horizon:<4} first {first:7.1f} s  {shown:>14} env-steps/s",
              flush=True)

    for name in args.tasks.split(","):
        composed = api.compose([f"task={name}", "sim=mjx", *args.overrides])
        task = registry.build("task", composed.task)
        cfg = dataclasses.replace(base, tuning=dict(composed.sim.tuning))  # the task's MJX tuning (conf/mjx_tuning)
        task.name = name  # ShadowHand_more shares its class with ShadowHand
        try:
            if "native" in rows_wanted and not args.compile_only:
                sim = NativeSimulator(task, args.native_envs, NativeConfig(nthread=0, max_abs_qvel=1.0e4))
                record(task, "native", args.native_envs, args.native_horizon,
                       *simulator_rollouts(task, args.native_envs, args.native_horizon, sim, reps))
            if "native-rk4" in rows_wanted and not args.compile_only:
                sim = NativeSimulator(task, args.native_envs, NativeConfig(nthread=0, max_abs_qvel=1.0e4))
                sim.alternate_integrators(RECORDED_DATA)
                record(task, "native-rk4", args.native_envs, args.native_horizon,
                       *simulator_rollouts(task, args.native_envs, args.native_horizon, sim, reps))
            baselines = list(map(int, args.baseline_envs.split(",")))
            if "mjx-plain" in rows_wanted:
                record(task, "mjx-plain", baselines[0], args.horizon, *plain_mjx(task, baselines[0], args.horizon, reps, cfg))
            for b in baselines if "mjx-fixed" in rows_wanted else []:
                record(task, "mjx-fixed", b, args.horizon,
                       *simulator_rollouts(task, b, args.horizon, MjxSimulator(task, b, cfg, randomize=False), reps))
            for envs in map(int, args.envs.split(",")) if "mjx" in rows_wanted else []:
                record(task, "mjx", envs, args.horizon,
                       *simulator_rollouts(task, envs, args.horizon, MjxSimulator(task, envs, cfg), reps))
        except Exception as exc:  # one task's failure must not hide the others' figures
            print(f"{name}: FAILED {type(exc).__name__}: {str(exc)[:300]}", flush=True)
            rows.append({"task": name, "error": f"{type(exc).__name__}: {exc}"})
        jax.clear_caches()
        torch.cuda.empty_cache() if torch.cuda.is_available() else None

    if args.json:
        with open(args.json, "w") as f:
            json.dump({"device": str(jax.devices()[0]), "torch": torch.__version__, "jax": jax.__version__,
                       "impl": args.impl, "overrides": args.overrides, "rows": rows}, f, indent=1)
    if args.compile_only:
        return
    print(f"\ndevice {jax.devices()[0]}, sim.impl={args.impl}; control steps/s, median of {args.reps} rollouts after a first call")
    print(f"{'task':<16} {'backend':<10} {'impl':<5} {'envs':>8} {'env-steps/s':>14} {'vs native':>10} {'randomization overhead':>24}")
    for r in rows:
        if "error" in r:
            print(f"{r['task']:<16} FAILED: {r['error'][:100]}")
            continue
        same = {x["backend"]: x for x in rows if x.get("task") == r["task"] and "error" not in x}
        native = same.get("native", {}).get("env_steps_per_s")
        vs = f"{r['env_steps_per_s'] / native:.1f}x" if native else ""
        fixed = next((x for x in rows if x.get("task") == r["task"] and x.get("backend") == "mjx-fixed"
                      and x["envs"] == r["envs"]), None)
        overhead = f"{1 - r['env_steps_per_s'] / fixed['env_steps_per_s']:+.1%}" if r["backend"] == "mjx" and fixed else ""
        print(f"{r['task']:<16} {r['backend']:<10} {r['impl']:<5} {r['envs']:>8} {r['env_steps_per_s']:>14,.0f} {vs:>10} {overhead:>24}")


if __name__ == "__main__":
    main()

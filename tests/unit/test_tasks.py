"""Every registered task: its parameters matter, its MJCF runs under MJX, and a wrong target
in its spec is reported with the closest valid names before anything is simulated."""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.errors import ConfigError
from bayessim_exp.policies import Policy

TASKS = registry.names("task")

HORIZON = 30  # control steps of the sensitivity rollouts
MIN_CHANGE = 1e-3  # max |obs_low - obs_high| over the rollout below which a parameter "does nothing"


def task_cfg(name: str) -> dict:
    return registry.option_defaults("task", name)  # the task's own values, without its defaults list


def make_task(cfg: dict):
    return registry.build("task", cfg)


def fixed_actions(horizon: int, dim: int) -> np.ndarray:
    """A deterministic, varied action sequence in [-1, 1]: [horizon, dim]."""
    t, k = np.arange(horizon)[:, None], np.arange(dim)[None]
    return 0.8 * np.sin(0.7 * t + 1.3 * k)


class Replay(Policy):
    def __init__(self, actions: np.ndarray):
        self.actions = torch.as_tensor(actions, dtype=torch.float32)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[t].expand(obs.shape[0], -1)


@pytest.mark.parametrize("name", TASKS)
def test_every_parameter_changes_the_trajectory(name):
    task = make_task(task_cfg(name))
    spec, d = task.spec, task.spec.dim
    mid = (spec.low + spec.high) / 2
    # row 0: all at mid-range; rows 1+2j, 2+2j: parameter j at its low / high bound
    params = np.repeat(mid[None], 1 + 2 * d, axis=0)
    for j in range(d):
        params[1 + 2 * j, j], params[2 + 2 * j, j] = spec.low[j], spec.high[j]
    # one initial state for every slot, so only the parameters differ
    draw = task.reset_state
    task.reset_state = lambda rng, n: {k: np.repeat(v[:1], n, 0) for k, v in draw(rng, 1).items()}
    sim = registry.build("sim", {"name": "native"})(task, len(params))
    traj = sim.rollout(params, Replay(fixed_actions(HORIZON, task.action_dim)), HORIZON, seed=0)

    assert not traj.diverged.any(), f"diverged at {[spec.names[(i - 1) // 2] for i in np.flatnonzero(traj.diverged)]}"
    assert torch.isfinite(traj.rewards).all() and torch.isfinite(traj.states).all()
    states = traj.states.numpy()
    change = np.abs(states[2::2] - states[1::2]).max(axis=(1, 2))
    dead = {n: float(c) for n, c in zip(spec.names, change) if not c > MIN_CHANGE}
    assert not dead, f"{name}: parameters that barely change the trajectory (max |Δobs|): {dead}"


@pytest.mark.parametrize("name", TASKS)
def test_wrong_target_names_the_closest_valid_body(name):
    cfg = task_cfg(name)
    model = make_task(cfg).model
    body = next(n for i in range(1, model.nbody) if (n := mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i)))
    typo = body + "x"
    first = next(iter(cfg["parameters"].values()))
    first["targets"] = [f"body_mass[{typo}]"] + list(first["targets"])
    with pytest.raises(ConfigError) as err:
        make_task(cfg)  # building the task resolves the spec; no simulator exists yet
    assert typo in str(err.value) and body in str(err.value)


def mjx_env() -> None:
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # before jax is imported (XLA_FLAGS: conftest.py)


MJX_STEPS = 10  # physics steps compared
MJX_ATOL = 1e-3  # qpos and qvel, float32 MJX against float64 MuJoCo
# MJX compiles for about a minute per model on a CPU: make test compares the tiny models, make test-mjx the others
TINY = {"Pendulum", "Cartpole", "mjcf"}


@pytest.mark.slow
@pytest.mark.parametrize("name", [n if n in TINY else pytest.param(n, marks=pytest.mark.mjx) for n in TASKS])
def test_mjx_agrees_with_native(name):
    mjx_env()
    jax = pytest.importorskip("jax")
    from mujoco import mjx

    task = make_task(task_cfg(name))
    m = task.model
    d = mujoco.MjData(m)
    for field, values in task.reset_state(np.random.default_rng(0), 1).items():
        getattr(d, field)[:] = values[0]
    d.ctrl[:] = task.ctrl(fixed_actions(1, task.action_dim)[0])
    mujoco.mj_forward(m, d)

    start = time.perf_counter()
    mx = mjx.put_model(m)
    dx = mjx.put_data(m, d)
    step = jax.jit(mjx.step)
    for _ in range(MJX_STEPS):
        dx = step(mx, dx)
        mujoco.mj_step(m, d)
    qpos, qvel = np.asarray(dx.qpos), np.asarray(dx.qvel)
    print(f"{name}: MJX put_model + compile + {MJX_STEPS} steps took {time.perf_counter() - start:.1f} s; "
          f"max |Δqpos| {np.abs(qpos - d.qpos).max():.2e}, max |Δqvel| {np.abs(qvel - d.qvel).max():.2e}")
    np.testing.assert_allclose(qpos, d.qpos, atol=MJX_ATOL)
    np.testing.assert_allclose(qvel, d.qvel, atol=MJX_ATOL)

"""ShadowHand, ShadowHand_more, Anymal, FrankaCabinet: every parameter moves the trajectory, the
models run under MJX like native MuJoCo, and a wrong target names the closest valid ones."""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from bayessim_exp.errors import ConfigError
from bayessim_exp.registry import build
from bayessim_exp.sim.native import NativeSimulator

CONF = os.path.join(os.path.dirname(__file__), "..", "..", "conf", "task")
TASKS = ["ShadowHand", "ShadowHand_more", "Anymal", "FrankaCabinet"]


def _task(name: str):
    return build("task", OmegaConf.load(os.path.join(CONF, f"{name}.yaml")))


class _Fixed:
    def __init__(self, actions: np.ndarray):
        self.actions = torch.as_tensor(actions, dtype=torch.float32)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[t].expand(obs.shape[0], -1)


@pytest.mark.parametrize("name", TASKS)
def test_every_parameter_moves_the_trajectory(name):
    task = _task(name)
    state = task.reset_state(np.random.default_rng(0), 1)
    task.reset_state = lambda rng, n: {k: np.repeat(v, n, 0) for k, v in state.items()}  # one start for all
    d, horizon = task.spec.dim, 30
    values = np.repeat(task.real_values[None], 2 * d + 2, 0)  # the last two: real twice
    values[np.arange(d) * 2, np.arange(d)] = task.spec.low
    values[np.arange(d) * 2 + 1, np.arange(d)] = task.spec.high
    actions = np.random.default_rng(1).uniform(-1, 1, (horizon, task.action_dim))
    traj = NativeSimulator(task, len(values)).rollout(values, _Fixed(actions), horizon, np.random.default_rng(2))
    assert not traj.diverged.any()
    s = traj.states.numpy()
    assert np.array_equal(s[-1], s[-2])  # same parameters, same trajectory: any difference is the parameter's
    change = np.abs(s[0 : 2 * d : 2] - s[1 : 2 * d : 2]).reshape(d, -1).max(1)
    dead = [f"{n} ({c:.1e})" for n, c in zip(task.spec.names, change) if c < 1e-4]
    assert not dead, f"{name}: parameters that barely move the trajectory: {dead}"


def test_first_observation_after_reset_has_site_positions():
    task = _task("FrankaCabinet")
    obs = NativeSimulator(task, 2).reset(np.repeat(task.real_values[None], 2, 0), None, np.random.default_rng(0))
    to_handle = obs[:, task.obs_names.index("to_handle_x")]
    assert (np.abs(to_handle) > 0.05).all()  # the gripper starts about 0.2 m in front of the handle


@pytest.mark.parametrize("name", TASKS)
def test_wrong_target_names_closest(name):
    cfg = OmegaConf.load(os.path.join(CONF, f"{name}.yaml"))
    first = next(iter(cfg.parameters))
    target = str(cfg.parameters[first].targets[0])
    field, obj = target.split("[")
    cfg.parameters[first].targets[0] = f"{field}[{obj.split(',')[0].rstrip(']')}x]"
    with pytest.raises(ConfigError, match="closest valid"):
        build("task", cfg)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ShadowHand", "Anymal", "FrankaCabinet"])  # ShadowHand_more: same model
def test_mjx_steps_match_native(name):
    """put_model works and 10 physics steps from a reset state agree with MuJoCo within 1e-4."""
    os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    jax = pytest.importorskip("jax")
    from mujoco import mjx

    task = _task(name)
    m = task.model
    d = mujoco.MjData(m)
    for field, value in task.reset_state(np.random.default_rng(0), 1).items():
        getattr(d, field)[:] = value[0]
    d.ctrl[:] = task.ctrl(np.random.default_rng(1).uniform(-1, 1, m.nu))
    start = time.time()
    mx, dx = mjx.put_model(m), mjx.put_data(m, d)
    step = jax.jit(mjx.step)
    for _ in range(10):
        dx = step(mx, dx)
        mujoco.mj_step(m, d)
    err = float(np.abs(np.asarray(dx.qpos) - d.qpos).max())
    print(f"{name}: MJX check {time.time() - start:.1f} s, max |qpos diff| {err:.1e}")
    assert err < 1e-4

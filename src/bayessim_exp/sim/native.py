"""CPU backend: N MuJoCo simulations with per-environment parameters on mujoco.batch.Batch."""

from __future__ import annotations

import dataclasses
import types
from typing import Protocol

import mujoco
import numpy as np
import torch
from mujoco import batch as mjbatch

from ..errors import ConfigError
from ..registry import register
from ..tasks.base import Task
from .trajectories import Trajectories

# warnings that mean the integration broke down (MuJoCo then silently resets the data)
_DIVERGENCE_WARNINGS = [
    int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)
]


class Policy(Protocol):
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor: ...


@dataclasses.dataclass
class NativeConfig:
    nthread: int = 0  # 0: all CPUs
    max_abs_qvel: float = 1.0e4  # a joint speed beyond this counts as diverged

    def validate(self) -> None:
        if self.nthread < 0 or self.max_abs_qvel <= 0:
            raise ConfigError("nthread must be >= 0 and max_abs_qvel > 0")


class NativeSimulator:
    """`rollout` for data collection; `reset`/`step` for RL, each slot with its own parameters."""

    def __init__(self, task: Task, num_envs: int, cfg: NativeConfig | None = None):
        self.task = task
        self.cfg = cfg or NativeConfig()
        self.num_envs = num_envs
        self.batch = mjbatch.Batch(task.model, num_envs, nthread=self.cfg.nthread)
        derived = [f for f in task.data_fields if f not in ("qpos", "qvel", "act", "time")]
        self._stage = mujoco.mjtStage.mjSTAGE_VEL if derived else mujoco.mjtStage.mjSTAGE_NONE
        for field in task.data_fields:  # outputs are copied out only after calls made once they are bound
            self.batch.bind(field)
        self._diverged = np.zeros(num_envs, dtype=bool)

    # parameters ---------------------------------------------------------------------
    def set_params(self, values: np.ndarray, env_ids: np.ndarray | None = None) -> None:
        ids = np.arange(self.num_envs) if env_ids is None else np.asarray(env_ids)
        fields = self.task.spec.field_values(self.task.model, values)
        for name, vals in fields.items():
            target = self.batch.expand(name)
            target[ids] = vals.reshape((len(ids),) + target.shape[1:])
        if self.task.spec.needs_set_const:
            self.batch.set_const(ids)

    # RL interface --------------------------------------------------------------------
    def reset(self, params: np.ndarray, env_ids: np.ndarray | None, rng: np.random.Generator,
              state: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Give the slots new parameters and initial states (drawn by the task, or `state`'s
        MjData fields [n, ...] when given); return their observations."""
        ids = np.arange(self.num_envs) if env_ids is None else np.asarray(env_ids)
        self.set_params(params, ids)
        self.batch.reset(ids, stage=mujoco.mjtStage.mjSTAGE_NONE)
        for field, values in (self.task.reset_state(rng, len(ids)) if state is None else state).items():
            self.batch.bind(field)[ids] = values
        self.batch.forward(ids, stage=mujoco.mjtStage.mjSTAGE_VEL)
        self._diverged[ids] = False
        return self.observe()[ids]

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply normalised actions for one control step; return (observations, diverged)."""
        self.batch.ctrl[:] = self.task.ctrl(actions)
        before = self._warnings()
        try:
            self.batch.step(nstep=self.task.frame_skip, stage=self._stage)
        except mjbatch.SimulationError as exc:
            self._diverged[exc.ids] = True
        self._diverged |= self._warnings() > before
        qvel = self.batch.qvel
        bad = ~np.isfinite(self.batch.qpos).all(1) | ~np.isfinite(qvel).all(1)
        bad |= (np.abs(np.nan_to_num(qvel, nan=np.inf)) > self.cfg.max_abs_qvel).any(1)
        self._diverged |= bad
        return self.observe(), self._diverged.copy()

    def observe(self) -> np.ndarray:
        d = types.SimpleNamespace(**{f: self.batch.bind(f) for f in self.task.data_fields})
        return np.asarray(self.task.observe(d), dtype=np.float64)

    def _warnings(self) -> np.ndarray:
        # per simulation: [warning, (lastinfo, number)]
        return self.batch.warning[:, _DIVERGENCE_WARNINGS, 1].sum(1)

    # data collection -----------------------------------------------------------------
    def rollout(self, params: np.ndarray, policy: Policy, horizon: int, rng: np.random.Generator,
                progress: bool = False, state: dict[str, np.ndarray] | None = None) -> Trajectories:
        """Run one episode of `horizon` control steps in every slot, params [num_envs, D], from the
        task's initial states or from `state` (MjData fields [num_envs, ...])."""
        from tqdm.auto import tqdm

        n, task = self.num_envs, self.task
        obs = self.reset(params, None, rng, state)
        states = np.empty((n, horizon + 1, task.obs_dim))
        actions = np.zeros((n, horizon, task.action_dim))
        rewards = np.zeros((n, horizon))
        valid = np.zeros((n, horizon), dtype=bool)
        alive = np.ones(n, dtype=bool)
        states[:, 0] = obs
        for t in tqdm(range(horizon), desc="simulate", leave=False, disable=None if progress else True, delay=2):
            act = policy.act(torch.as_tensor(obs, dtype=torch.float32), t).numpy().astype(np.float64)
            next_obs, diverged = self.step(act)
            alive &= ~diverged
            valid[:, t] = alive
            actions[alive, t] = act[alive]
            rewards[alive, t] = task.reward(obs[alive], act[alive], next_obs[alive])
            # a terminated or diverged slot holds its last valid state
            states[:, t + 1] = np.where(alive[:, None], next_obs, states[:, t])
            alive &= ~np.asarray(task.terminated(next_obs), dtype=bool)
            obs = next_obs
        return Trajectories(
            states=torch.as_tensor(states, dtype=torch.float32),
            actions=torch.as_tensor(actions, dtype=torch.float32),
            rewards=torch.as_tensor(rewards, dtype=torch.float32),
            valid=torch.as_tensor(valid),
            diverged=torch.as_tensor(self._diverged.copy()),
            dt=task.cfg.control_dt,
        )


@register("sim", "native", NativeConfig)
def native_backend(cfg: NativeConfig) -> "type[NativeSimulator]":
    """The sim group builds a factory: (task, num_envs) -> simulator."""
    return lambda task, num_envs: NativeSimulator(task, num_envs, cfg)


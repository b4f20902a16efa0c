"""The Simulator protocol every backend implements: N environments of one task, each with its own parameters.

Torch tensors in and out, integer seeds. A backend implements four things: `_reset` (write parameters
and initial states into some slots, return their observations), `_step` (advance every slot one
control step, return observations, rewards, terminations and which slots broke down), `check_spec`
(refuse parameters the backend cannot randomize) and `device`. Everything else is written once here:
episode bookkeeping (elapsed steps, truncation at the task's episode length, divergence that sticks
until the slot is reset) and `rollout`, the batched data collection every stage uses.

Divergence has one definition (`broke_down`): non-finite positions or velocities, a joint speed
beyond `max_abs_qvel`, or the backend's own breakdown signal (MuJoCo's warnings on CPU). A diverged
slot keeps its last finite observation, earns no reward, and is flagged in every later result.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from ..errors import ConfigError
from ..policies import Policy
from ..tasks.base import Task
from ..tasks.params import ParamSpec
from .trajectories import Trajectories


@dataclasses.dataclass
class StepResult:
    """One control step of every slot: obs [N, S], reward [N], terminated/truncated/diverged [N] bool."""

    obs: torch.Tensor
    reward: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    diverged: torch.Tensor


def broke_down(qpos: Any, qvel: Any, max_abs_qvel: float, xp: Any = np) -> Any:
    """Per slot: the state is no longer a trustworthy simulation ([N] bool), in the backend's array namespace."""
    finite = xp.isfinite(qpos).all(-1) & xp.isfinite(qvel).all(-1)
    too_fast = (xp.abs(xp.where(xp.isfinite(qvel), qvel, 0.0)) > max_abs_qvel).any(-1)
    return ~finite | too_fast


class Simulator(abc.ABC):
    """N slots of `task`; each slot takes new parameters and an initial state at its own reset."""

    def __init__(self, task: Task, num_envs: int):
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.check_spec(task.spec)
        self.task, self.num_envs = task, num_envs
        self.elapsed = torch.zeros(num_envs, dtype=torch.long)
        self.diverged = torch.zeros(num_envs, dtype=torch.bool)

    def pads(self, num_rows: int) -> bool:
        """Whether a batch of num_rows (< num_envs) runs in this simulator, padded, rather than in one of its own
        size: where each size would be a compilation (MJX)."""
        return False

    def alternate_integrators(self, names: Sequence[str]) -> None:
        """Slot j integrates with names[j % len(names)] (sim/integrators.py); a backend that compiles one
        integrator for every slot (MJX) cannot."""
        raise ConfigError(f"{type(self).__name__} simulates every slot with one integrator; alternating "
                          f"{list(names)} needs native MuJoCo (sim=native)")

    # what a backend implements ------------------------------------------------------
    @classmethod
    @abc.abstractmethod
    def check_spec(cls, spec: ParamSpec) -> None:
        """Raise ConfigError for parameters whose model fields this backend cannot set per slot."""

    @property
    @abc.abstractmethod
    def device(self) -> torch.device:
        """Where observations and rewards live."""

    @abc.abstractmethod
    def _reset(self, params: torch.Tensor, ids: torch.Tensor, state: dict[str, np.ndarray]) -> torch.Tensor:
        """Write params [n, D] (float64) and the initial state into slots `ids`; their observations [n, S]."""

    @abc.abstractmethod
    def _step(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Advance every slot one control step with actions [N, A] in [-1, 1].

        Returns (obs [N, S], reward [N], terminated [N], broke_down [N]) for every slot."""

    # written once for every backend -------------------------------------------------
    def reset(self, params: torch.Tensor | np.ndarray, env_ids: torch.Tensor | None = None, seed: int = 0,
              state: dict[str, np.ndarray] | None = None) -> torch.Tensor:
        """Give slots `env_ids` (all when None) new parameters [n, D] and initial states, drawn from the
        task's reset distribution with `seed` unless `state` gives them (e.g. {"qpos": [n, nq], "qvel": ...});
        return their observations [n, S]."""
        ids = torch.arange(self.num_envs) if env_ids is None else torch.as_tensor(env_ids, dtype=torch.long).cpu()
        params = torch.as_tensor(np.asarray(self.task.spec.check_values(np.asarray(params, dtype=np.float64))))
        if params.shape[0] != len(ids):
            raise ValueError(f"{params.shape[0]} parameter rows for {len(ids)} slots")
        if state is None:
            state = self.task.reset_state(np.random.default_rng(seed), len(ids))
        obs = self._reset(params, ids, state)
        self.elapsed[ids] = 0
        self.diverged[ids] = False
        return obs

    def step(self, actions: torch.Tensor) -> StepResult:
        obs, reward, terminated, broken = self._step(torch.as_tensor(actions).clamp(-1.0, 1.0))
        self.elapsed += 1
        self.diverged |= broken.cpu()
        diverged = self.diverged.to(obs.device)
        return StepResult(
            obs=obs,
            reward=torch.where(diverged, torch.zeros_like(reward), reward),
            terminated=terminated & ~diverged,
            truncated=(self.elapsed >= self.task.cfg.episode_length).to(obs.device),
            diverged=diverged.clone(),
        )

    def rollout(self, params: torch.Tensor | np.ndarray, policy: Policy, horizon: int, seed: int = 0,
                progress: bool = False, state: dict[str, np.ndarray] | None = None) -> Trajectories:
        """One episode of `horizon` control steps in every slot (params [num_envs, D]).

        A slot that terminates or diverges holds its last valid observation, with `valid` False from
        that step on; diverged slots are flagged in the result."""
        from tqdm.auto import tqdm

        obs = self.reset(params, None, seed, state)
        n, dev = self.num_envs, obs.device
        states = torch.empty(n, horizon + 1, self.task.obs_dim, dtype=torch.float32, device=dev)
        actions = torch.zeros(n, horizon, self.task.action_dim, dtype=torch.float32, device=dev)
        rewards = torch.zeros(n, horizon, dtype=torch.float32, device=dev)
        valid = torch.zeros(n, horizon, dtype=torch.bool, device=dev)
        alive = torch.ones(n, dtype=torch.bool, device=dev)
        states[:, 0] = obs
        for t in tqdm(range(horizon), desc="simulate", leave=False, disable=None if progress else True, delay=2):
            act = torch.as_tensor(policy.act(obs.float(), t), dtype=torch.float32).to(dev).clamp(-1.0, 1.0)
            result = self.step(act)
            alive &= ~result.diverged
            valid[:, t] = alive
            actions[:, t] = torch.where(alive[:, None], act, 0.0)
            rewards[:, t] = torch.where(alive, result.reward.float(), 0.0)
            states[:, t + 1] = torch.where(alive[:, None], result.obs.float(), states[:, t])
            alive &= ~result.terminated
            obs = result.obs
        return Trajectories(states=states, actions=actions, rewards=rewards, valid=valid,
                            diverged=self.diverged.clone().to(dev), dt=self.task.cfg.control_dt)

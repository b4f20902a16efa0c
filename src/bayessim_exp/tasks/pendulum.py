"""Pendulum swing-up (gym's Pendulum on MuJoCo): infer the rod's mass and length."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .base import Task, TaskConfig


@dataclasses.dataclass
class PendulumConfig(TaskConfig):
    max_speed_reset: float  # initial angular speed ~ U(-v, v)


class Pendulum(Task):
    name = "Pendulum"
    xml = "pendulum.xml"
    obs_names = ("cos_theta", "sin_theta", "theta_dot")

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        v = self.cfg.max_speed_reset
        return {"qpos": rng.uniform(-np.pi, np.pi, size=(n, 1)), "qvel": rng.uniform(-v, v, size=(n, 1))}

    def state_from_observation(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        return {"qpos": np.arctan2(obs[:, 1:2], obs[:, 0:1]), "qvel": obs[:, 2:3].copy()}

    def observe(self, d: Any, xp: Any = np) -> Any:
        theta, omega = d.qpos[:, 0], d.qvel[:, 0]
        return xp.stack([xp.cos(theta), xp.sin(theta), omega], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        # gym's Pendulum: cost of the state the action is taken in
        theta = xp.arctan2(obs[:, 1], obs[:, 0])
        torque = self._ctrl_mid[0] + self._ctrl_half[0] * xp.clip(action[:, 0], -1.0, 1.0)
        return -(theta**2 + 0.1 * obs[:, 2] ** 2 + 0.001 * torque**2)

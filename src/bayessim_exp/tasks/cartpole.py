"""Cartpole balancing (IsaacGym's Cartpole on dm_control's cart-pole): keep the pole upright.

Observation [cart position, cart velocity, pole angle, pole angular velocity], one action
(force on the cart), IsaacGym's reward 1 - angle^2 - 0.01|cart vel| - 0.005|pole vel| with -2
when the episode ends (cart beyond `reset_dist` or pole past horizontal).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .base import Task, TaskConfig


@dataclasses.dataclass
class CartpoleConfig(TaskConfig):
    reset_dist: float  # |cart position| [m] that ends the episode (the rail ends at 1.8)
    reset_pos: float  # initial cart position and pole angle ~ U(-p, p)
    reset_vel: float  # initial velocities ~ U(-v, v)


class Cartpole(Task):
    name = "Cartpole"
    xml = "cartpole/cartpole.xml"
    obs_names = ("cart_pos", "cart_vel", "pole_angle", "pole_vel")

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        p, v = self.cfg.reset_pos, self.cfg.reset_vel
        return {"qpos": rng.uniform(-p, p, size=(n, 2)), "qvel": rng.uniform(-v, v, size=(n, 2))}

    def state_from_observation(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        return {"qpos": obs[:, [0, 2]].copy(), "qvel": obs[:, [1, 3]].copy()}

    def observe(self, d: Any, xp: Any = np) -> Any:
        return xp.stack([d.qpos[:, 0], d.qvel[:, 0], d.qpos[:, 1], d.qvel[:, 1]], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        cart_vel, angle, pole_vel = next_obs[:, 1], next_obs[:, 2], next_obs[:, 3]
        r = 1.0 - angle**2 - 0.01 * xp.abs(cart_vel) - 0.005 * xp.abs(pole_vel)
        return xp.where(self.terminated(next_obs, xp), -2.0, r)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return (xp.abs(obs[:, 0]) > self.cfg.reset_dist) | (xp.abs(obs[:, 2]) > np.pi / 2)

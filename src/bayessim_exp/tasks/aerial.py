"""IsaacGym's aerial tasks (Ingenuity, Quadcopter): fly a free body to a target and hover there.

Observation, as IsaacGym's: (target - position) / 3, orientation quaternion (w, x, y, z), linear
velocity / 2, world angular velocity / pi, then the height (which IsaacGym's termination reads
from the state) and any joint positions. Reward, as IsaacGym's: p + p * (up_weight * u + s) with
p = 1/(1 + distance^2), u = 1/(1 + (1 - up_z)^2) and s = 1/(1 + yaw rate^2). The episode ends
beyond `max_dist` from the target or below `min_height`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from . import rotations
from .base import Task, TaskConfig


@dataclasses.dataclass
class AerialConfig(TaskConfig):
    up_weight: float
    max_dist: float  # [m] from the target that ends the episode
    min_height: float  # [m] below which the episode ends
    start: list[float]  # mean start position [m]
    reset_pos: float  # start position ~ start + U(-p, p) per axis [m]
    reset_vel: float  # linear and angular velocity ~ U(-v, v) per axis


class Aerial(Task):
    """Subclasses give `target(d, xp)`, the target position [N, 3], and the joint observations."""

    def target(self, d: Any, xp: Any) -> Any:
        raise NotImplementedError

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        p, v = self.cfg.reset_pos, self.cfg.reset_vel
        qpos = np.repeat(self.model.qpos0[None], n, 0)
        qpos[:, 0:3] = np.asarray(self.cfg.start) + rng.uniform(-p, p, size=(n, 3))
        qvel = np.zeros((n, self.model.nv))
        qvel[:, 0:6] = rng.uniform(-v, v, size=(n, 6))
        return {"qpos": qpos, "qvel": qvel}

    def observe(self, d: Any, xp: Any = np) -> Any:
        quat = d.qpos[:, 3:7]
        r = rotations.matrix(quat, xp)
        angvel = xp.sum(r * d.qvel[:, None, 3:6], axis=-1)  # a free joint's angular velocity is in the body frame
        return xp.concatenate([
            (self.target(d, xp) - d.qpos[:, 0:3]) / 3.0, quat, d.qvel[:, 0:3] / 2.0, angvel / np.pi,
            d.qpos[:, 2:3], d.qpos[:, 7:],
        ], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        dist2 = xp.sum((3.0 * next_obs[:, 0:3]) ** 2, axis=-1)
        q = next_obs[:, 3:7]
        up_z = 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2)
        pos = 1.0 / (1.0 + dist2)
        up = 1.0 / (1.0 + (1.0 - up_z) ** 2)
        spin = 1.0 / (1.0 + (np.pi * next_obs[:, 12]) ** 2)
        return pos + pos * (self.cfg.up_weight * up + spin)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        dist = xp.sqrt(xp.sum((3.0 * obs[:, 0:3]) ** 2, axis=-1))
        return (dist > self.cfg.max_dist) | (obs[:, 13] < self.cfg.min_height)

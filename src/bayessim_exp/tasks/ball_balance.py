"""BallBalance (IsaacGym's BallBalance on our own tray MJCF): keep a ball at the tray's centre.

Observation: the tray's lift, roll and pitch positions and velocities, the ball's world position
and velocity (IsaacGym's, less the leg force sensors). Actions are the three servos' position
targets (IsaacGym integrates actions into targets; here they are the targets). Reward, as
IsaacGym's: 1/(1 + distance to the target point) * 1/(1 + ball speed). The episode ends when
the ball falls below the tray.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .base import Task, TaskConfig


@dataclasses.dataclass
class BallBalanceConfig(TaskConfig):
    target_height: float  # ball centre at rest on the level tray [m]
    fall_height: float  # ball centre below this [m]: off the tray, episode over
    reset_max_dist: float  # initial horizontal offset from the centre ~ U(0, d) [m]
    reset_height: list[float]  # drop height [m]
    reset_max_speed: float  # horizontal speed towards the centre, up to this at offset d [m/s]


class BallBalance(Task):
    name = "BallBalance"
    xml = "ball_balance/ball_balance.xml"
    obs_names = ("lift", "roll", "pitch", "lift_vel", "roll_vel", "pitch_vel",
                 "ball_x", "ball_y", "ball_z", "ball_vx", "ball_vy", "ball_vz")

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        cfg = self.cfg
        qpos = np.repeat(self.model.qpos0[None], n, 0)
        qvel = np.zeros((n, self.model.nv))
        frac = rng.uniform(0.0, 1.0, n)
        angle = rng.uniform(-np.pi, np.pi, n)
        direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
        qpos[:, 3:5] = cfg.reset_max_dist * frac[:, None] * direction
        qpos[:, 5] = rng.uniform(*cfg.reset_height, n)
        # thrown towards the centre, faster the further out it starts
        qvel[:, 3:5] = -(cfg.reset_max_speed * frac * rng.uniform(0.0, 1.0, n))[:, None] * direction
        return {"qpos": qpos, "qvel": qvel}

    def observe(self, d: Any, xp: Any = np) -> Any:
        return xp.concatenate([d.qpos[:, 0:3], d.qvel[:, 0:3], d.qpos[:, 3:6], d.qvel[:, 3:6]], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        ball, vel = next_obs[:, 6:9], next_obs[:, 9:12]
        offset = xp.stack([ball[:, 0], ball[:, 1], ball[:, 2] - self.cfg.target_height], axis=-1)
        dist = xp.sqrt(xp.sum(offset**2, axis=-1))
        speed = xp.sqrt(xp.sum(vel**2, axis=-1))
        return 1.0 / (1.0 + dist) / (1.0 + speed)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return obs[:, 8] < self.cfg.fall_height

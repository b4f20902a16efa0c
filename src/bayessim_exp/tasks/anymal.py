"""Anymal: a quadruped tracks a commanded planar velocity and yaw rate (IsaacGym's Anymal).

Observations are IsaacGym's (base linear and angular velocity in the base frame, projected
gravity, the command, joint positions relative to the default stance, joint velocities) plus the
base height, without the previous actions (the trajectory keeps those). Actions are joint targets
within +-0.5 rad of the default stance, tracked by PD drives. Reward: IsaacGym's exponential
velocity-tracking terms and torque penalty, scaled by the control step and clipped at zero.
The episode ends when the base sinks below `min_base_height` (IsaacGym: base or knee contact).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .base import Task, TaskConfig
from .rotations import quat_rotate_inverse

_LEGS = ("LF", "RF", "LH", "RH")
_JOINTS = ("HAA", "HFE", "KFE")


@dataclasses.dataclass
class AnymalConfig(TaskConfig):
    command_lin_x: list[float]  # [m/s]
    command_lin_y: list[float]  # [m/s]
    command_yaw: list[float]  # [rad/s]
    lin_vel_reward_scale: float
    ang_vel_reward_scale: float
    torque_reward_scale: float
    lin_vel_scale: float
    ang_vel_scale: float
    dof_vel_scale: float
    min_base_height: float  # [m]


class Anymal(Task):
    name = "Anymal"
    xml = "anymal/anymal.xml"
    data_fields = ("qpos", "qvel", "userdata")

    def __init__(self, cfg: AnymalConfig):
        super().__init__(cfg)
        m = self.model
        self.default_pos = self._ctrl_mid.copy()  # the stance at action 0
        self._kp = m.actuator_gainprm[:, 0].copy()
        self._kd = -m.actuator_biasprm[:, 2].copy()
        self._force = m.actuator_forcerange[:, 1].copy()
        joints = [f"{leg}_{j}" for leg in _LEGS for j in _JOINTS]
        self.obs_names = tuple(
            [f"base_linvel_{a}" for a in "xyz"] + [f"base_angvel_{a}" for a in "xyz"]
            + [f"gravity_{a}" for a in "xyz"] + ["command_vx", "command_vy", "command_yaw"]
            + [f"{j}_pos" for j in joints] + [f"{j}_vel" for j in joints] + ["base_height"]
        )

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        cfg, m = self.cfg, self.model
        qpos = np.repeat(m.qpos0[None], n, 0)
        qpos[:, 7:] = self.default_pos * rng.uniform(0.5, 1.5, (n, m.nu))
        qvel = np.zeros((n, m.nv))
        qvel[:, 6:] = rng.uniform(-0.1, 0.1, (n, m.nu))
        command = np.stack([rng.uniform(*r, n) for r in (cfg.command_lin_x, cfg.command_lin_y, cfg.command_yaw)], -1)
        return {"qpos": qpos, "qvel": qvel, "userdata": command}

    def observe(self, d: Any, xp: Any = np) -> Any:
        cfg = self.cfg
        quat = d.qpos[:, 3:7]
        lin = quat_rotate_inverse(quat, d.qvel[:, 0:3], xp)  # the free joint's linear velocity is in the world frame
        down = xp.zeros_like(lin) + xp.asarray([0.0, 0.0, -1.0])
        command = d.userdata[:, 0:3] * xp.asarray([cfg.lin_vel_scale, cfg.lin_vel_scale, cfg.ang_vel_scale])
        return xp.concatenate([
            cfg.lin_vel_scale * lin, cfg.ang_vel_scale * d.qvel[:, 3:6], quat_rotate_inverse(quat, down, xp), command,
            d.qpos[:, 7:] - self.default_pos, cfg.dof_vel_scale * d.qvel[:, 6:], d.qpos[:, 2:3],
        ], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        cfg, dt = self.cfg, self.cfg.control_dt
        lin_err = xp.sum((next_obs[:, 9:11] - next_obs[:, 0:2]) ** 2, axis=-1) / cfg.lin_vel_scale**2
        yaw_err = (next_obs[:, 11] - next_obs[:, 5]) ** 2 / cfg.ang_vel_scale**2
        # PD torque the action asked for in the state it was taken in
        target = self._ctrl_mid + self._ctrl_half * xp.clip(action, -1.0, 1.0)
        q = obs[:, 12:24] + self.default_pos
        torque = xp.clip(self._kp * (target - q) - self._kd * obs[:, 24:36] / cfg.dof_vel_scale, -self._force, self._force)
        reward = cfg.lin_vel_reward_scale * xp.exp(-lin_err / 0.25) + cfg.ang_vel_reward_scale * xp.exp(-yaw_err / 0.25)
        reward = reward + cfg.torque_reward_scale * xp.sum(torque**2, axis=-1)
        return xp.clip(reward * dt, 0.0, None)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return obs[:, -1] < self.cfg.min_base_height

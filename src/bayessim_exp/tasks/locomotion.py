"""IsaacGym's locomotion tasks (Ant, Humanoid): run along +x on a free-floating torso.

Observation, as IsaacGym's less its contact-force sensors: torso height, linear velocity in the
heading (yaw) frame, angular velocity in the torso frame (scaled), yaw, roll, angle to the
target, up and heading projections, joint positions scaled to [-1, 1] by their limits, joint
velocities (scaled) and the last actions. The target lies far along +x, so IsaacGym's progress
reward (the drop in distance to it per second) is the torso's world x velocity.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import mujoco
import numpy as np

from . import rotations
from .base import Task, TaskConfig


@dataclasses.dataclass
class LocomotionConfig(TaskConfig):
    heading_weight: float
    up_weight: float
    alive_reward: float
    actions_cost: float
    energy_cost: float
    joints_at_limit_cost: float
    death_cost: float
    termination_height: float  # torso height [m] below which the episode ends
    dof_vel_scale: float
    angvel_scale: float
    reset_noise_pos: float  # joint positions: home pose + U(-p, p), clipped to the limits
    reset_noise_vel: float  # joint velocities ~ U(-v, v)


class Locomotion(Task):
    """Subclasses set name and xml: an MJCF with a free root joint, then hinges, each with a motor."""

    data_fields = ("qpos", "qvel", "ctrl")

    def __init__(self, cfg: LocomotionConfig):
        super().__init__(cfg)
        m = self.model
        hinges = np.flatnonzero(m.jnt_type != mujoco.mjtJoint.mjJNT_FREE)
        self._lo, self._hi = m.jnt_range[hinges].T
        self._home = m.key_qpos[0] if m.nkey else m.qpos0
        # energy is weighted by each motor's share of the strongest motor's effort
        self._effort = m.actuator_gear[:, 0] / m.actuator_gear[:, 0].max()
        # the joint each motor drives, as a column of the joint observations
        self._motor_joint = np.array([list(hinges).index(j) for j in m.actuator_trnid[:, 0]])
        self.nj = len(hinges)

    @property
    def obs_names(self) -> tuple[str, ...]:
        joints = [mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(1, self.model.njnt)]
        return (
            "height", "vel_x", "vel_y", "vel_z", "angvel_x", "angvel_y", "angvel_z", "yaw", "roll",
            "angle_to_target", "up_proj", "heading_proj",
            *(f"pos_{j}" for j in joints), *(f"vel_{j}" for j in joints),
            *(f"action_{joints[k]}" for k in self._motor_joint),  # actions in actuator order
        )

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        p, v = self.cfg.reset_noise_pos, self.cfg.reset_noise_vel
        qpos = np.repeat(self._home[None], n, 0)
        qpos[:, 7:] = np.clip(qpos[:, 7:] + rng.uniform(-p, p, size=(n, self.nj)), self._lo, self._hi)
        qvel = np.zeros((n, self.model.nv))
        qvel[:, 6:] = rng.uniform(-v, v, size=(n, self.nj))
        return {"qpos": qpos, "qvel": qvel}

    def observe(self, d: Any, xp: Any = np) -> Any:
        quat = d.qpos[:, 3:7]
        roll, yaw = rotations.roll_yaw(quat, xp)
        c, s = xp.cos(yaw), xp.sin(yaw)
        vx, vy = d.qvel[:, 0], d.qvel[:, 1]
        r = rotations.matrix(quat, xp)
        joints = d.qpos[:, 7:]
        scaled = (2 * joints - self._hi - self._lo) / (self._hi - self._lo)
        actions = (d.ctrl - self._ctrl_mid) / self._ctrl_half
        cols = [
            d.qpos[:, 2:3],
            xp.stack([c * vx + s * vy, -s * vx + c * vy, d.qvel[:, 2]], axis=-1),
            d.qvel[:, 3:6] * self.cfg.angvel_scale,  # a free joint's angular velocity is in the body frame
            xp.stack([yaw, roll, rotations.wrap(-yaw, xp), r[:, 2, 2], r[:, 0, 0]], axis=-1),
            scaled, d.qvel[:, 6:] * self.cfg.dof_vel_scale, actions,
        ]
        return xp.concatenate(cols, axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        cfg, nj = self.cfg, self.nj
        yaw, up, heading = next_obs[:, 7], next_obs[:, 10], next_obs[:, 11]
        progress = xp.cos(yaw) * next_obs[:, 1] - xp.sin(yaw) * next_obs[:, 2]
        heading_reward = xp.where(heading > 0.8, cfg.heading_weight, cfg.heading_weight * heading / 0.8)
        up_reward = xp.where(up > 0.93, cfg.up_weight, 0.0)
        joints, joint_vel = next_obs[:, 12 : 12 + nj], next_obs[:, 12 + nj : 12 + 2 * nj]
        a = xp.clip(action, -1.0, 1.0)
        energy = xp.sum(xp.abs(a * joint_vel[:, self._motor_joint]) * self._effort, axis=-1)
        at_limit = xp.sum(xp.abs(joints) > 0.99, axis=-1)
        total = (progress + cfg.alive_reward + up_reward + heading_reward - cfg.actions_cost * xp.sum(a**2, axis=-1)
                 - cfg.energy_cost * energy - cfg.joints_at_limit_cost * at_limit)
        return xp.where(self.terminated(next_obs, xp), cfg.death_cost, total)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return obs[:, 0] < self.cfg.termination_height

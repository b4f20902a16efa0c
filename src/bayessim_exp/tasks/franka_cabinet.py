"""FrankaCabinet: a Franka Panda grasps a drawer handle and pulls the drawer open (IsaacGym's FrankaCabinet).

Observations are IsaacGym's 23 (joint positions scaled to [-1, 1], joint velocities, the vector
from the grasp point to the handle, drawer opening and speed) plus what its reward reads from the
simulator state: the gripper's forward and up axes and the heights of both fingertips relative to
the handle. Actions are joint velocities that move the drives' position targets (IsaacGym's
targets += dt * action * action_scale), here intvelocity actuators. Reward, bonuses and the
end of an episode at an open drawer are IsaacGym's compute_franka_reward.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .base import Task, TaskConfig


@dataclasses.dataclass
class FrankaCabinetConfig(TaskConfig):
    default_dof_pos: list[float]
    reset_noise: float  # joint start ~ default + noise * U(-0.5, 0.5)
    dof_vel_scale: float
    dist_reward_scale: float
    rot_reward_scale: float
    around_handle_reward_scale: float
    open_reward_scale: float
    finger_dist_reward_scale: float
    action_penalty_scale: float
    open_distance: float  # [m] drawer opening that ends the episode


class FrankaCabinet(Task):
    name = "FrankaCabinet"
    xml = "franka_cabinet/franka_cabinet.xml"
    data_fields = ("qpos", "qvel", "site_xpos", "site_xmat")

    def __init__(self, cfg: FrankaCabinetConfig):
        super().__init__(cfg)
        m = self.model
        self.narm = m.nu  # 7 arm joints and 2 fingers come first in qpos, then the drawer
        self._lower, self._upper = m.jnt_range[: self.narm].T
        self._grip, self._handle = m.site("grip").id, m.site("handle").id
        self._fingers = np.array([m.site("leftfinger_tip").id, m.site("rightfinger_tip").id])
        self._drawer = m.jnt_qposadr[m.joint("drawer").id]
        joints = [m.joint(j).name for j in range(self.narm)]
        self.obs_names = tuple(
            [f"{j}_pos" for j in joints] + [f"{j}_vel" for j in joints] + [f"to_handle_{a}" for a in "xyz"]
            + ["drawer_pos", "drawer_vel"] + [f"gripper_forward_{a}" for a in "xyz"]
            + [f"gripper_up_{a}" for a in "xyz"] + ["lfinger_dz", "rfinger_dz"]
        )

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        m = self.model
        qpos = np.repeat(m.qpos0[None], n, 0)
        arm = np.asarray(self.cfg.default_dof_pos) + self.cfg.reset_noise * rng.uniform(-0.5, 0.5, (n, self.narm))
        qpos[:, : self.narm] = np.clip(arm, self._lower, self._upper)
        # the drives' targets start where the joints are
        return {"qpos": qpos, "qvel": np.zeros((n, m.nv)), "act": qpos[:, : self.narm].copy()}

    def observe(self, d: Any, xp: Any = np) -> Any:
        q = d.qpos[:, : self.narm]
        scaled = (2.0 * q - (self._upper + self._lower)) / (self._upper - self._lower)
        handle = d.site_xpos[:, self._handle]
        axes = d.site_xmat[:, self._grip].reshape(-1, 3, 3)
        finger_dz = d.site_xpos[:, self._fingers, 2] - handle[:, None, 2]
        return xp.concatenate([
            scaled, self.cfg.dof_vel_scale * d.qvel[:, : self.narm], handle - d.site_xpos[:, self._grip],
            d.qpos[:, self._drawer : self._drawer + 1], d.qvel[:, self._drawer : self._drawer + 1],
            axes[:, :, 2], axes[:, :, 1], finger_dz,
        ], axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        cfg, n = self.cfg, 2 * self.narm
        o = next_obs
        dist = xp.linalg.norm(o[:, n : n + 3], axis=-1)
        dist_reward = (1.0 / (1.0 + dist**2)) ** 2
        dist_reward = xp.where(dist <= 0.02, 2.0 * dist_reward, dist_reward)
        # the drawer opens along -x, so the gripper should point along +x with its fingers spread along z
        dot1, dot2 = o[:, n + 5], o[:, n + 10]
        rot_reward = 0.5 * (xp.sign(dot1) * dot1**2 + xp.sign(dot2) * dot2**2)
        lf, rf = o[:, n + 11], o[:, n + 12]
        around = xp.where((lf > 0) & (rf < 0), 0.5, 0.0)
        finger_dist = xp.where((lf > 0) & (rf < 0), (0.04 - xp.abs(lf)) + (0.04 - xp.abs(rf)), 0.0)
        drawer = o[:, n + 3]
        open_reward = drawer * around + drawer
        reward = (cfg.dist_reward_scale * dist_reward + cfg.rot_reward_scale * rot_reward
                  + cfg.around_handle_reward_scale * around + cfg.open_reward_scale * open_reward
                  + cfg.finger_dist_reward_scale * finger_dist - cfg.action_penalty_scale * xp.sum(action**2, axis=-1))
        reward = reward + xp.where(drawer > 0.01, 0.5, 0.0)
        reward = reward + xp.where(drawer > 0.2, around, 0.0)
        return reward + xp.where(drawer > cfg.open_distance, 2.0 * around, 0.0)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return obs[:, 2 * self.narm + 3] > self.cfg.open_distance

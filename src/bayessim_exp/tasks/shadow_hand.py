"""ShadowHand: reorient a cube in the hand to a goal orientation (IsaacGym's ShadowHand, block).

Observations follow IsaacGym's "full" observation: hand joint positions scaled to [-1, 1], joint
velocities, object pose and velocities, goal orientation, their difference, fingertip positions.
Actions are absolute joint targets of the 20 position actuators (IsaacGym with
useRelativeControl False). Reward and fall termination are IsaacGym's compute_hand_reward.
The goal orientation lives in a mocap body and stays fixed during an episode (IsaacGym draws a
new goal on success; here one success bonus per step holds while the cube stays at the goal).

`ShadowHand_more` is the same task registered a second time: its YAML infers more parameters.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import mujoco
import numpy as np

from .base import Task, TaskConfig
from .rotations import quat_angle, quat_conj, quat_from_angle_axis, quat_mul, quat_rotate

_FINGERTIPS = ("ff", "mf", "rf", "lf", "th")


@dataclasses.dataclass
class ShadowHandConfig(TaskConfig):
    reset_position_noise: float  # cube start position ~ start + U(-n, n) per axis [m]
    reset_dof_pos_interval: float  # joint start ~ interval * U(lower, upper)
    dist_reward_scale: float
    rot_reward_scale: float
    rot_eps: float
    action_penalty_scale: float
    reach_goal_bonus: float
    success_tolerance: float  # [rad]
    fall_distance: float  # [m] from the goal position ends the episode
    fall_penalty: float
    vel_obs_scale: float


class ShadowHand(Task):
    name = "ShadowHand"
    xml = "shadow_hand/shadow_hand.xml"
    data_fields = ("qpos", "qvel", "mocap_quat", "site_xpos")

    def __init__(self, cfg: ShadowHandConfig):
        super().__init__(cfg)
        m = self.model
        hand = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        self.hand_joints = [m.joint(j).name.split(":")[1] for j in hand]
        self.nh = len(hand)
        # the cube's free joint follows the hand's hinges in qpos and qvel
        self._obj_qpos = m.jnt_qposadr[m.joint("object:joint").id]
        self._obj_qvel = m.jnt_dofadr[m.joint("object:joint").id]
        self._lower, self._upper = m.jnt_range[hand].T
        self._tips = np.array([m.site(f"robot0:S_{f}tip").id for f in _FINGERTIPS])
        self.start_pos = m.body("object").pos.copy()
        self.goal_pos = m.body("target").pos.copy()  # where the cube rests on the palm and should stay
        hand_obs = [f"{j}_pos" for j in self.hand_joints] + [f"{j}_vel" for j in self.hand_joints]
        obj = [f"object_pos_{a}" for a in "xyz"] + [f"object_quat_{a}" for a in "wxyz"]
        obj += [f"object_linvel_{a}" for a in "xyz"] + [f"object_angvel_{a}" for a in "xyz"]
        goal = [f"goal_quat_{a}" for a in "wxyz"] + [f"quat_diff_{a}" for a in "wxyz"]
        tips = [f"{f}tip_{a}" for f in _FINGERTIPS for a in "xyz"]
        self.obs_names = tuple(hand_obs + obj + goal + tips)

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        cfg, m = self.cfg, self.model
        qpos = np.repeat(m.qpos0[None], n, 0)
        # IsaacGym: default (zero) pose plus a fraction of the way to a random point in the range
        qpos[:, : self.nh] = cfg.reset_dof_pos_interval * rng.uniform(self._lower, self._upper, (n, self.nh))
        o = self._obj_qpos
        qpos[:, o : o + 3] = self.start_pos + rng.uniform(-1, 1, (n, 3)) * cfg.reset_position_noise
        qpos[:, o + 3 : o + 7] = _random_rotation(rng, n)
        return {"qpos": qpos, "qvel": np.zeros((n, m.nv)), "mocap_quat": _random_rotation(rng, n)[:, None]}

    def observe(self, d: Any, xp: Any = np) -> Any:
        o, v, s = self._obj_qpos, self._obj_qvel, self.cfg.vel_obs_scale
        joints = d.qpos[:, : self.nh]
        scaled = (2.0 * joints - (self._upper + self._lower)) / (self._upper - self._lower)
        quat = d.qpos[:, o + 3 : o + 7]
        goal = d.mocap_quat[:, 0]
        # the free joint's angular velocity is in the cube's frame; IsaacGym reports it in the world's
        angvel = quat_rotate(quat, d.qvel[:, v + 3 : v + 6], xp)
        tips = d.site_xpos[:, self._tips].reshape(-1, 3 * len(_FINGERTIPS))
        return xp.concatenate([
            scaled, s * d.qvel[:, : self.nh], d.qpos[:, o : o + 3], quat, d.qvel[:, v : v + 3], s * angvel,
            goal, quat_mul(quat, quat_conj(goal, xp), xp), tips,
        ], axis=-1)

    def _goal_dist(self, obs: Any, xp: Any) -> Any:
        p = 2 * self.nh
        return xp.linalg.norm(obs[:, p : p + 3] - self.goal_pos, axis=-1)

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        cfg, p = self.cfg, 2 * self.nh + 17
        goal_dist = self._goal_dist(next_obs, xp)
        rot_dist = quat_angle(next_obs[:, p : p + 4], xp)
        reward = goal_dist * cfg.dist_reward_scale + cfg.rot_reward_scale / (xp.abs(rot_dist) + cfg.rot_eps)
        reward = reward + cfg.action_penalty_scale * xp.sum(action**2, axis=-1)
        reward = reward + xp.where(xp.abs(rot_dist) <= cfg.success_tolerance, cfg.reach_goal_bonus, 0.0)
        return reward + xp.where(goal_dist >= cfg.fall_distance, cfg.fall_penalty, 0.0)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        return self._goal_dist(obs, xp) >= self.cfg.fall_distance


class ShadowHandMore(ShadowHand):
    name = "ShadowHand_more"


def _random_rotation(rng: np.random.Generator, n: int) -> np.ndarray:
    """IsaacGym's randomize_rotation: about x by U(-pi, pi), then about y by U(-pi, pi)."""
    qx = quat_from_angle_axis(rng.uniform(-np.pi, np.pi, n), np.array([1.0, 0.0, 0.0]))
    qy = quat_from_angle_axis(rng.uniform(-np.pi, np.pi, n), np.array([0.0, 1.0, 0.0]))
    return quat_mul(qx, qy)

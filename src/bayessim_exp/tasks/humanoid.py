"""Humanoid (IsaacGym's Humanoid on gymnasium's humanoid MJCF): a 17-joint biped runs along +x."""

from __future__ import annotations

import dataclasses

from .locomotion import Locomotion, LocomotionConfig


@dataclasses.dataclass
class HumanoidConfig(LocomotionConfig):
    # IsaacGym's humanoid.yaml values
    alive_reward: float
    actions_cost: float
    joints_at_limit_cost: float
    death_cost: float
    termination_height: float
    dof_vel_scale: float
    angvel_scale: float


class Humanoid(Locomotion):
    name = "Humanoid"
    xml = "humanoid/humanoid.xml"

"""Humanoid (IsaacGym's Humanoid on gymnasium's humanoid MJCF): a 17-joint biped runs along +x."""

from __future__ import annotations

import dataclasses

from ..registry import register
from .locomotion import Locomotion, LocomotionConfig


@dataclasses.dataclass
class HumanoidConfig(LocomotionConfig):
    # IsaacGym's humanoid.yaml values
    alive_reward: float = 2.0
    actions_cost: float = 0.01
    joints_at_limit_cost: float = 0.25
    death_cost: float = -1.0
    termination_height: float = 0.8
    dof_vel_scale: float = 0.1
    angvel_scale: float = 0.25


@register("task", "Humanoid", HumanoidConfig)
class Humanoid(Locomotion):
    name = "Humanoid"
    xml = "humanoid/humanoid.xml"

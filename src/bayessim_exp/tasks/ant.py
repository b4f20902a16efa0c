"""Ant (IsaacGym's Ant on gymnasium's ant MJCF): a four-legged torso runs along +x."""

from __future__ import annotations

import dataclasses

from ..registry import register
from .locomotion import Locomotion, LocomotionConfig


@dataclasses.dataclass
class AntConfig(LocomotionConfig):
    pass


@register("task", "Ant", AntConfig)
class Ant(Locomotion):
    name = "Ant"
    xml = "ant/ant.xml"

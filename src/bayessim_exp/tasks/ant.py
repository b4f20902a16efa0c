"""Ant (IsaacGym's Ant on gymnasium's ant MJCF): a four-legged torso runs along +x."""

from __future__ import annotations

import dataclasses

from .locomotion import Locomotion, LocomotionConfig


@dataclasses.dataclass
class AntConfig(LocomotionConfig):
    pass


class Ant(Locomotion):
    name = "Ant"
    xml = "ant/ant.xml"

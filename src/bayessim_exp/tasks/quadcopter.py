"""Quadcopter (IsaacGym's Quadcopter on our own MJCF): hover at a fixed target.

Twelve actions: position targets of each rotor's two tilt joints (arm pitch, rotor roll) and the
four rotors' thrusts (IsaacGym integrates actions into targets and thrusts; here they are the
targets and thrusts). The observation ends with the eight tilt-joint positions.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .aerial import Aerial, AerialConfig


@dataclasses.dataclass
class QuadcopterConfig(AerialConfig):
    target_pos: list[float]  # [m]


class Quadcopter(Aerial):
    name = "Quadcopter"
    xml = "quadcopter/quadcopter.xml"
    obs_names = ("to_target_x", "to_target_y", "to_target_z", "quat_w", "quat_x", "quat_y", "quat_z",
                 "vel_x", "vel_y", "vel_z", "angvel_x", "angvel_y", "angvel_z", "height",
                 *(f"{part}_{i}" for i in range(4) for part in ("arm_pitch", "rotor_roll")))

    def target(self, d: Any, xp: Any) -> Any:
        return xp.zeros_like(d.qpos[:, 0:3]) + xp.asarray(self.cfg.target_pos)

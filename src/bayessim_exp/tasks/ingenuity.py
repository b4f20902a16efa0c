"""Ingenuity (IsaacGym's Ingenuity on our own MJCF): the Mars helicopter flies to a random target.

Six actions: per coaxial rotor a vertical thrust and two lateral forces (IsaacGym's six thrust
components, here each its own actuator), in Mars gravity. The target is a mocap body placed at
every reset.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .aerial import Aerial, AerialConfig


@dataclasses.dataclass
class IngenuityConfig(AerialConfig):
    up_weight: float
    max_dist: float
    min_height: float
    start: list[float]  # legs clear of min_height
    reset_pos: float
    target_low: list[float]  # target ~ U(low, high) [m]
    target_high: list[float]


class Ingenuity(Aerial):
    name = "Ingenuity"
    xml = "ingenuity/ingenuity.xml"
    obs_names = ("to_target_x", "to_target_y", "to_target_z", "quat_w", "quat_x", "quat_y", "quat_z",
                 "vel_x", "vel_y", "vel_z", "angvel_x", "angvel_y", "angvel_z", "height")
    data_fields = ("qpos", "qvel", "mocap_pos")

    def target(self, d: Any, xp: Any) -> Any:
        return d.mocap_pos[:, 0]

    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        state = super().reset_state(rng, n)
        state["mocap_pos"] = rng.uniform(self.cfg.target_low, self.cfg.target_high, size=(n, 1, 3))
        return state

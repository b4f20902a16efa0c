"""Quaternion helpers for task observations, batched and written against an array namespace.

Quaternions are MuJoCo's (w, x, y, z), shape [N, 4]; vectors are [N, 3].
"""

from __future__ import annotations

from typing import Any

import numpy as np


def matrix(q: Any, xp: Any = np) -> Any:
    """Rotation matrices [N, 3, 3] (body frame -> world) of unit quaternions."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def roll_yaw(q: Any, xp: Any = np) -> tuple[Any, Any]:
    """Roll (about x) and yaw (about z) of the x-y-z Euler decomposition, in (-pi, pi]."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    roll = xp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    yaw = xp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, yaw


def wrap(angle: Any, xp: Any = np) -> Any:
    """Angles wrapped into (-pi, pi]."""
    return xp.arctan2(xp.sin(angle), xp.cos(angle))

"""Quaternion helpers for task observations, batched and written against an array namespace `xp`
(numpy on CPU, jax.numpy on the GPU backend).

Quaternions are MuJoCo's (w, x, y, z), shape [..., 4]; vectors are [..., 3].
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


def quat_conj(q: Any, xp: Any = np) -> Any:
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_mul(a: Any, b: Any, xp: Any = np) -> Any:
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return xp.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_rotate(q: Any, v: Any, xp: Any = np) -> Any:
    """Rotate vectors v from the frame of q into the parent frame."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_rotate_inverse(q: Any, v: Any, xp: Any = np) -> Any:
    """Express parent-frame vectors v in the frame of q."""
    return quat_rotate(quat_conj(q, xp), v, xp)


def quat_angle(q: Any, xp: Any = np) -> Any:
    """Rotation angle of unit quaternions, in [0, pi] (IsaacGym's 2 asin |q_xyz|)."""
    return 2.0 * xp.arcsin(xp.clip(xp.linalg.norm(q[..., 1:], axis=-1), 0.0, 1.0))


def quat_from_angle_axis(angle: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Quaternions [n, 4] for rotations by angle [n] about one unit axis [3]."""
    half = 0.5 * np.asarray(angle)[:, None]
    return np.concatenate([np.cos(half), np.sin(half) * np.asarray(axis)[None]], axis=-1)

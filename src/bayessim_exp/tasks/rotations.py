"""Batched quaternion algebra in MuJoCo's (w, x, y, z) order, written against an array namespace
`xp` (numpy on CPU, jax.numpy under MJX) so task observations and rewards run on both backends."""

from __future__ import annotations

from typing import Any

import numpy as np


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
    """Rotate vectors v [..., 3] from the frame of q into the parent frame."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_rotate_inverse(q: Any, v: Any, xp: Any = np) -> Any:
    """Express parent-frame vectors v [..., 3] in the frame of q."""
    return quat_rotate(quat_conj(q, xp), v, xp)


def quat_angle(q: Any, xp: Any = np) -> Any:
    """Rotation angle of unit quaternions, in [0, pi] (IsaacGym's 2 asin |q_xyz|)."""
    return 2.0 * xp.arcsin(xp.clip(xp.linalg.norm(q[..., 1:], axis=-1), 0.0, 1.0))


def quat_from_angle_axis(angle: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Quaternions [n, 4] for rotations by angle [n] about one unit axis [3]."""
    half = 0.5 * np.asarray(angle)[:, None]
    return np.concatenate([np.cos(half), np.sin(half) * np.asarray(axis)[None]], axis=-1)

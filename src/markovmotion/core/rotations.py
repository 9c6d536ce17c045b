"""Vectorised Euler-angle to quaternion conversion.

SciPy's ``Rotation.from_euler`` converts about a million rotations a second,
which made it the slowest step of reading a long BVH take; composing the three
axis quaternions with NumPy does the same in a fraction of the time. Everything
else (products, inverses, exponential maps, slerp) uses
``scipy.spatial.transform.Rotation``.
"""

from __future__ import annotations

import numpy as np


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions in scalar-last order, broadcast over leading axes."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def euler_to_quat(order: str, angles: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles ``(..., len(order))`` to unit quaternions ``(..., 4)``.

    ``order`` is upper case as in SciPy (``"ZXY"``: R = Rz Rx Ry), one to three axes.
    Agrees with ``Rotation.from_euler(order, angles).as_quat()`` up to sign.
    """
    angles = np.asarray(angles, dtype=float)
    half = (np.radians(angles) if degrees else angles) * 0.5
    out = None
    for k, axis in enumerate(order):
        q = np.zeros(half.shape[:-1] + (4,))
        q[..., "XYZ".index(axis.upper())] = np.sin(half[..., k])
        q[..., 3] = np.cos(half[..., k])
        out = q if out is None else quat_multiply(out, q)
    return out

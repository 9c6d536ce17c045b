"""Compiled forward-kinematics kernels of :class:`markovmotion.core.motion.Motion`.

Kept apart from ``motion.py`` so that reading a file, listing the command line or
importing the package does not import numba (half a second); ``Motion`` imports this
module on its first forward kinematics. Compiled once per machine (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def quat_matrices_into(q, out):  # pragma: no cover - compiled
    for i in range(q.shape[0]):
        x, y, z, w = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        n = x * x + y * y + z * z + w * w
        if n == 0.0:
            return False
        s = 2.0 / n
        out[i, 0, 0] = 1.0 - s * (y * y + z * z)
        out[i, 0, 1] = s * (x * y - z * w)
        out[i, 0, 2] = s * (x * z + y * w)
        out[i, 1, 0] = s * (x * y + z * w)
        out[i, 1, 1] = 1.0 - s * (x * x + z * z)
        out[i, 1, 2] = s * (y * z - x * w)
        out[i, 2, 0] = s * (x * z - y * w)
        out[i, 2, 1] = s * (y * z + x * w)
        out[i, 2, 2] = 1.0 - s * (x * x + y * y)
    return True


@numba.njit(cache=True)
def chain(local, trans, parents):  # pragma: no cover - compiled
    """Compose local rotations (F, J, 3, 3) and translations (F, J, 3) down the tree.

    A compiled loop: the per-joint NumPy version spent most of its time in call
    overhead, which dominated the one-frame calls of online partners.
    """
    f, n = local.shape[0], local.shape[1]
    rot = np.empty_like(local)
    pos = np.empty((f, n, 3))
    for t in range(f):
        rot[t, 0] = local[t, 0]
        pos[t, 0] = trans[t, 0]
        for j in range(1, n):
            p = parents[j]
            for a in range(3):
                pos[t, j, a] = pos[t, p, a]
                for b in range(3):
                    pos[t, j, a] += rot[t, p, a, b] * trans[t, j, b]
                    acc = 0.0
                    for c in range(3):
                        acc += rot[t, p, a, c] * local[t, j, c, b]
                    rot[t, j, a, b] = acc
    return rot, pos

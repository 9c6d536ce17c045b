"""Dynamic time warping: distance, alignment path and open-end (partial) alignment.

Local cost is the Euclidean distance between frames; steps are the usual
(1, 0), (0, 1), (1, 1) with equal weights. The open-end variant aligns a whole
observation with the best *prefix* of a template, as needed to find "the
position tau within a template" of the structured VLMM (§4.4).
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial.distance import cdist


@numba.njit(cache=True)
def _accumulate(local):  # pragma: no cover - numba
    n, m = local.shape
    acc = np.full((n, m), np.inf)
    acc[0, 0] = local[0, 0]
    for i in range(n):
        for j in range(m):
            if i == 0 and j == 0:
                continue
            best = np.inf
            if i > 0 and acc[i - 1, j] < best:
                best = acc[i - 1, j]
            if j > 0 and acc[i, j - 1] < best:
                best = acc[i, j - 1]
            if i > 0 and j > 0 and acc[i - 1, j - 1] < best:
                best = acc[i - 1, j - 1]
            acc[i, j] = local[i, j] + best
    return acc


def _as_2d(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x[:, None] if x.ndim == 1 else x


def accumulated_cost(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m) accumulated DTW cost: entry (i, j) aligns ``a[:i+1]`` with ``b[:j+1]``."""
    a, b = _as_2d(a), _as_2d(b)
    if len(a) == 0 or len(b) == 0:
        raise ValueError("DTW needs two non-empty sequences")
    return _accumulate(cdist(a, b))


def dtw_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Total cost of the best alignment of two sequences of vectors (rows)."""
    return float(accumulated_cost(a, b)[-1, -1])


def dtw_path(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Best alignment: its cost and the (L, 2) index pairs from (0, 0) to (n-1, m-1)."""
    acc = accumulated_cost(a, b)
    i, j = acc.shape[0] - 1, acc.shape[1] - 1
    path = [(i, j)]
    while i > 0 or j > 0:
        moves = [(i - 1, j - 1), (i - 1, j), (i, j - 1)]
        i, j = min((m for m in moves if m[0] >= 0 and m[1] >= 0), key=lambda m: acc[m])
        path.append((i, j))
    return float(acc[-1, -1]), np.array(path[::-1])


def open_end_dtw(observed: np.ndarray, template: np.ndarray) -> tuple[float, int]:
    """Align all of ``observed`` with the best prefix of ``template``.

    Returns:
        ``(cost, tau)``: the least cost over prefixes and the number of template
        frames ``tau`` (1 <= tau <= len(template)) of that prefix.
    """
    last = accumulated_cost(observed, template)[-1]
    tau = int(np.argmin(last))
    return float(last[tau]), tau + 1


def dtw_distance_matrix(sequences: list[np.ndarray]) -> np.ndarray:
    """Symmetric (n, n) matrix of DTW distances between sequences."""
    n = len(sequences)
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            out[i, j] = out[j, i] = dtw_distance(sequences[i], sequences[j])
    return out

"""Vector quantisation: prototypes, tokenisation to the nearest prototype, collapsed repeats.

Prototypes are found by k-means (scikit-learn) or by the robust competitive
learning of Johnson and Hogg that the VLMM and interaction papers use (§2 of
both): online winner-take-all learning where each unit's distance is weighted
by how often it has won, so that no unit starves and the prototypes spread
over the data's support rather than its densest region only.
"""

from __future__ import annotations

import numba
import numpy as np
from sklearn.cluster import KMeans
from sklearn.metrics import pairwise_distances_argmin

from markovmotion.errors import TooLittleDataError


def kmeans_prototypes(x: np.ndarray, k: int, seed: int = 0, n_init: int = 3) -> np.ndarray:
    """(k, d) k-means centres of the rows of ``x`` (k-means++ starts, best of ``n_init``)."""
    x = np.asarray(x, dtype=float)
    if not 1 <= k <= len(x):
        raise TooLittleDataError(
            f"cannot find {k} prototypes in {len(x)} vectors: train on more takes or ask "
            "for fewer prototypes"
        )
    return KMeans(n_clusters=k, n_init=n_init, random_state=seed).fit(x).cluster_centers_


@numba.njit(cache=True)
def _competitive_epochs(x, protos, order, wins, lr0, lr1, n_epochs):  # pragma: no cover - numba
    n, d = x.shape
    k = protos.shape[0]
    total = n_epochs * n
    step = 0
    for _ in range(n_epochs):
        for i in order:
            lr = lr0 * (lr1 / lr0) ** (step / max(total - 1, 1))
            best = 0
            best_cost = np.inf
            for j in range(k):
                dist = 0.0
                for c in range(d):
                    diff = x[i, c] - protos[j, c]
                    dist += diff * diff
                cost = dist * wins[j]
                if cost < best_cost:
                    best_cost = cost
                    best = j
            wins[best] += 1.0
            for c in range(d):
                protos[best, c] += lr * (x[i, c] - protos[best, c])
            step += 1
    return protos


def competitive_learning(
    x: np.ndarray,
    k: int,
    n_epochs: int = 5,
    learning_rate: tuple[float, float] = (0.2, 0.002),
    seed: int = 0,
) -> np.ndarray:
    """(k, d) prototypes by frequency-sensitive (robust) competitive learning.

    Units start on ``k`` random data vectors; each presented vector (shuffled,
    ``n_epochs`` passes) moves the winning unit towards it by a learning rate
    decaying geometrically from ``learning_rate[0]`` to ``learning_rate[1]``.
    The winner minimises squared distance times the unit's win count, which
    keeps every unit in use (the robustness of Johnson and Hogg's method).
    """
    x = np.ascontiguousarray(x, dtype=float)
    if not 1 <= k <= len(x):
        raise TooLittleDataError(
            f"cannot find {k} prototypes in {len(x)} vectors: train on more takes or ask "
            "for fewer prototypes"
        )
    rng = np.random.default_rng(seed)
    protos = x[rng.choice(len(x), k, replace=False)].copy()
    order = rng.permutation(len(x))
    wins = np.ones(k)
    return _competitive_epochs(x, protos, order, wins, *learning_rate, n_epochs)


def nearest_prototype(x: np.ndarray, prototypes: np.ndarray) -> np.ndarray:
    """Index of the nearest prototype (Euclidean) for each row of ``x`` (§2, eq. 3)."""
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return np.zeros(0, dtype=np.intp)
    return pairwise_distances_argmin(x, prototypes).astype(np.intp)


def collapse_repeats(tokens: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Replace runs of one token by a single occurrence (§2).

    Returns:
        ``(collapsed, starts)``: the tokens with repeats removed and the index
        in ``tokens`` at which each run starts.
    """
    tokens = np.asarray(tokens)
    if len(tokens) == 0:
        return tokens.copy(), np.zeros(0, dtype=np.intp)
    starts = np.flatnonzero(np.r_[True, tokens[1:] != tokens[:-1]])
    return tokens[starts], starts

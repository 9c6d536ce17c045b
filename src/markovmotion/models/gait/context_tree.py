"""Decision-tree context clustering of Gaussian densities, stopped by MDL (gait paper §5.1.1).

For each state position separately, the contexts start in one cluster; the
split of a leaf by a yes/no question on the contexts that raises the
log-likelihood of the data most is taken, as long as that gain exceeds the
minimum-description-length cost of the extra Gaussian (Shinoda & Watanabe:
``mdl_factor * (k / 2) log N`` for k = 2 O new parameters and N frames at
the root). Contexts without data follow the questions like any other, so
every context, seen or not, ends in a leaf (HTK book, tree-based clustering).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.algorithms.gaussian import LOG_2PI


def _log_like(occ: float, s1: np.ndarray, s2: np.ndarray, floor: np.ndarray) -> float:
    """Log-likelihood of the frames of a cluster under its own ML diagonal Gaussian."""
    if occ <= 0:
        return 0.0
    mean = s1 / occ
    var = np.maximum(s2 / occ - mean**2, floor)
    return float(-0.5 * occ * (np.sum(np.log(var)) + len(mean) * (1 + LOG_2PI)))


def cluster_state(
    occ: np.ndarray,
    sums: np.ndarray,
    sumsq: np.ndarray,
    questions: Sequence[np.ndarray],
    floor: np.ndarray,
    mdl_factor: float = 1.0,
    min_occupancy: float = 1.0,
) -> np.ndarray:
    """Leaf index (C,) of every context for one state position.

    Args:
        occ: (C,) frames per context; sums, sumsq: (C, O) first and second moments.
        questions: boolean masks (C,), each a set of contexts ("is the step a left step?").
        floor: (O,) variance floor.
    """
    n_contexts, dims = sums.shape
    stats = lambda m: (occ[m].sum(), sums[m].sum(axis=0), sumsq[m].sum(axis=0))  # noqa: E731
    threshold = mdl_factor * dims * np.log(max(occ.sum(), 2.0))
    leaves = [np.ones(n_contexts, dtype=bool)]
    scores = [_log_like(*stats(leaves[0]), floor)]
    while True:
        best = (threshold, None, None, None)
        for i, leaf in enumerate(leaves):
            for q in questions:
                yes, no = leaf & q, leaf & ~q
                if occ[yes].sum() < min_occupancy or occ[no].sum() < min_occupancy:
                    continue
                ly, ln = _log_like(*stats(yes), floor), _log_like(*stats(no), floor)
                gain = ly + ln - scores[i]
                if gain > best[0]:
                    best = (gain, i, (yes, no), (ly, ln))
        if best[1] is None:
            break
        _, i, (yes, no), (ly, ln) = best
        leaves[i], scores[i] = yes, ly
        leaves.append(no)
        scores.append(ln)
    out = np.empty(n_contexts, dtype=int)
    for k, leaf in enumerate(leaves):
        out[leaf] = k
    return out


def cluster(
    occ: np.ndarray,
    sums: np.ndarray,
    sumsq: np.ndarray,
    questions: Sequence[np.ndarray],
    floor: np.ndarray,
    mdl_factor: float = 1.0,
) -> np.ndarray:
    """Density index (C, S) of every (context, state): one tree per state position, ids numbered across states."""
    n_contexts, n_states = occ.shape
    out = np.empty((n_contexts, n_states), dtype=int)
    offset = 0
    for s in range(n_states):
        leaf = cluster_state(occ[:, s], sums[:, s], sumsq[:, s], questions, floor, mdl_factor)
        out[:, s] = leaf + offset
        offset += leaf.max() + 1
    return out

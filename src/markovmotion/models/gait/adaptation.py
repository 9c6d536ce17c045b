"""Style adaptation of HSMMs: CMLLR / CSMAPLR then MAP (gait paper §5.1.3, eqs. 5-6).

A constrained linear transform maps the features, ``o' = A o + b`` with
likelihood ``N(A o + b; mu, Sigma) |A|`` (Gales 1998). In model space this is
the paper's eq. 5, one matrix for means and covariances:
``mu' = A^-1 (mu - b)``, ``Sigma' = A^-1 Sigma A^-T`` (kept diagonal, as
HTS does for synthesis); durations get their own transforms (eq. 6), one
per state position, exact in one dimension.

The rows of ``W = [A b]`` are re-estimated in turn by Gales' closed form.
CSMAPLR (Yamagishi et al. 2009) adds a prior: each node of a regression-class
tree over the output densities is estimated with its parent's transform as
the mean of a Gaussian prior (the root's prior is the identity) of weight
``tau`` in frames, so that a node with little data stays near its parent.
MAP adaptation of the means follows (``tau_map`` frames of prior weight).
Transforms act on blocks of dimensions (static, delta, delta-delta: the
``"stream"`` structure) or on each dimension alone (``"diagonal"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markovmotion.algorithms.gaussian import log_gaussian_diag
from markovmotion.models.gait.hsmm import HSMM, hard_posteriors

STRUCTURES = ("stream", "diagonal")
METHODS = ("csmaplr", "cmllr")


# ------------------------------------------------------------------ transforms
def identity_transform(n_dims: int) -> np.ndarray:
    """W = [I 0], (O, O + 1)."""
    return np.hstack([np.eye(n_dims), np.zeros((n_dims, 1))])


def transform_blocks(n_dims: int, structure: str) -> list[np.ndarray]:
    """Dimension blocks sharing one full transform: three streams, or every dimension alone."""
    if structure == "stream":
        if n_dims % 3:
            raise ValueError("the stream structure needs static, delta and delta-delta blocks")
        return list(np.arange(n_dims).reshape(3, -1))
    if structure == "diagonal":
        return [np.array([d]) for d in range(n_dims)]
    raise ValueError(f"structure must be one of {STRUCTURES}")


def apply_features(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x + b for frames x (T, O)."""
    return x @ w[:, :-1].T + w[:, -1]


def log_abs_det(w: np.ndarray) -> float:
    return float(np.linalg.slogdet(w[:, :-1])[1])


def apply_model(
    w: np.ndarray, means: np.ndarray, variances: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Model-space form of a feature transform (eq. 5): A^-1 (mu - b) and diag(A^-1 Sigma A^-T)."""
    inv = np.linalg.inv(w[:, :-1])
    return (means - w[:, -1]) @ inv.T, variances @ (inv**2).T


def cmllr_rows(
    w: np.ndarray,
    g: np.ndarray,
    k: np.ndarray,
    beta: float,
    prior: np.ndarray | None = None,
    prior_weight: np.ndarray | None = None,
    n_sweeps: int = 3,
) -> np.ndarray:
    """Row-by-row maximisation of the CMLLR auxiliary function for one block (Gales 1998).

    ``beta log|A| - 1/2 sum_i (w_i G_i w_i' - 2 w_i k_i')``, plus with a
    prior ``-1/2 sum_i (w_i - h_i) P_i (w_i - h_i)'`` (CSMAPLR) where
    ``P_i = diag(prior_weight[i])``. Each row is ``w_i = (alpha p_i + k_i) G_i^-1``
    with ``p_i`` the cofactor row of A (extended by 0) and alpha the root of
    ``alpha^2 p G^-1 p' + alpha p G^-1 k' - beta = 0`` that maximises the objective.

    Args:
        w: (n, n + 1) starting transform.
        g: (n, n + 1, n + 1) and k: (n, n + 1) statistics; beta: frames.
        prior: (n, n + 1) prior mean H; prior_weight: (n, n + 1) diagonal precisions.
    """
    w = np.array(w, dtype=float)
    n = w.shape[0]
    if prior is not None:
        g = g + prior_weight[:, :, None] * np.eye(n + 1)
        k = k + prior_weight * prior
    ridge = 1e-9 * np.einsum("iaa->i", g)[:, None, None] * np.eye(n + 1)
    g = g + ridge  # keeps G invertible for degenerate data (a duration seen at one value)
    g_inv = np.linalg.inv(g)
    a_inv = np.linalg.inv(w[:, :-1])
    for _ in range(n_sweeps):
        for i in range(n):
            cof = np.append(a_inv[:, i], 0.0)  # cofactor row of A, up to the factor det(A)
            gp = g_inv[i] @ cof
            e1 = cof @ gp
            e2 = k[i] @ gp
            disc = np.sqrt(e2**2 + 4 * e1 * beta)
            roots = np.array([(-e2 + disc) / (2 * e1), (-e2 - disc) / (2 * e1)])
            score = beta * np.log(np.abs(roots * e1 + e2)) - 0.5 * roots**2 * e1
            alpha = roots[np.argmax(score)]
            new = (alpha * cof + k[i]) @ g_inv[i]
            # Sherman-Morrison: A changes by e_i (new - old) in row i
            delta = new[:-1] - w[i, :-1]
            u = a_inv[:, i]
            v = delta @ a_inv
            a_inv -= np.outer(u, v) / (1.0 + v[i])
            w[i] = new
    return w


# ------------------------------------------------------------------ regression classes
@dataclass(frozen=True)
class RegressionTree:
    """Nodes of a binary tree over densities: ``parents`` (nodes,), ``members`` (nodes, P)."""

    parents: np.ndarray
    members: np.ndarray

    def leaves(self) -> np.ndarray:
        """Leaf node of each density (P,)."""
        is_parent = np.zeros(len(self.parents), bool)
        is_parent[self.parents[self.parents >= 0]] = True
        out = np.empty(self.members.shape[1], dtype=int)
        for node in np.flatnonzero(~is_parent):
            out[self.members[node]] = node
        return out


def regression_tree(points: np.ndarray, depth: int, seed: int = 0) -> RegressionTree:
    """Binary tree of depth ``depth`` by recursive 2-means of the densities' (scaled) means."""
    rng = np.random.default_rng(seed)
    parents = [-1]
    members = [np.ones(len(points), dtype=bool)]
    frontier = [0]
    for _ in range(depth):
        nxt = []
        for node in frontier:
            idx = np.flatnonzero(members[node])
            if len(idx) < 2:
                continue
            labels = _two_means(points[idx], rng)
            if labels.all() or not labels.any():
                continue
            for side in (False, True):
                mask = np.zeros(len(points), dtype=bool)
                mask[idx[labels == side]] = True
                parents.append(node)
                members.append(mask)
                nxt.append(len(parents) - 1)
        frontier = nxt
    return RegressionTree(np.array(parents), np.array(members))


def _two_means(x: np.ndarray, rng: np.random.Generator, n_iter: int = 20) -> np.ndarray:
    centres = x[rng.choice(len(x), 2, replace=False)]
    labels = np.zeros(len(x), dtype=bool)
    for _ in range(n_iter):
        dist = ((x[:, None] - centres[None]) ** 2).sum(axis=2)
        labels = dist[:, 1] < dist[:, 0]
        if labels.all() or not labels.any():
            break
        centres = np.array([x[~labels].mean(axis=0), x[labels].mean(axis=0)])
    return labels


# ------------------------------------------------------------------ statistics
@dataclass
class Transforms:
    """Feature transforms ``w`` (R, O, O + 1) and the class of each density ``classes`` (P,)."""

    w: np.ndarray
    classes: np.ndarray

    @classmethod
    def identity(cls, n_dims: int, n_densities: int) -> Transforms:
        return cls(identity_transform(n_dims)[None], np.zeros(n_densities, dtype=int))

    def model_space(
        self, means: np.ndarray, variances: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each density's means and (diagonal) variances under its class's transform (eq. 5)."""
        m, v = means.copy(), variances.copy()
        for r, w in enumerate(self.w):
            sel = self.classes == r
            if sel.any():
                m[sel], v[sel] = apply_model(w, means[sel], variances[sel])
        return m, v


@dataclass
class AdaptationStats:
    """Per density: occupancy (P,), sums (P, O) and per block sums of xi xi' (P, n+1, n+1), xi = [x 1]."""

    occ: np.ndarray
    sums: np.ndarray
    second: list[np.ndarray]

    def first(self, block: np.ndarray) -> np.ndarray:
        """(P, n+1) sums of xi over the block."""
        return np.hstack([self.sums[:, block], self.occ[:, None]])


def adaptation_statistics(
    hsmm: HSMM,
    sequences: Sequence[np.ndarray],
    contexts: Sequence[np.ndarray],
    blocks: list[np.ndarray],
    transforms: Transforms | None = None,
    boundaries: Sequence[np.ndarray] | None = None,
) -> tuple[AdaptationStats, AdaptationStats, float]:
    """E-step statistics of outputs and durations, with outputs seen through feature transforms.

    With ``transforms``, density m scores ``N(A x + b; mu_m, Sigma_m) |A|`` for
    its class's (A, b): the exact CMLLR likelihood. Statistics are of the
    untransformed data; durations are one-dimensional observations d. With
    ``boundaries`` (first frame of each unit, then T, per sequence) the states
    are not inferred: each unit is split evenly among its states, as HSMM
    training starts (:func:`~markovmotion.models.gait.hsmm.hard_posteriors`), and
    the log-likelihood is 0. Returns (output stats, duration stats, log-likelihood).
    """
    n_pdf, dims = hsmm.means_.shape
    n_dur = len(hsmm.dur_means_)
    out = AdaptationStats(
        np.zeros(n_pdf),
        np.zeros((n_pdf, dims)),
        [np.zeros((n_pdf, len(b) + 1, len(b) + 1)) for b in blocks],
    )
    dur = AdaptationStats(np.zeros(n_dur), np.zeros((n_dur, 1)), [np.zeros((n_dur, 2, 2))])
    d = np.arange(1.0, hsmm.max_duration_ + 1)
    xi_d = np.stack([np.outer([v, 1.0], [v, 1.0]) for v in d])  # (Dmax, 2, 2)
    total = 0.0
    for i, (x, c) in enumerate(zip(sequences, contexts, strict=True)):
        c = np.asarray(c)
        if boundaries is None:
            ll, gamma, dur_post = hsmm.posteriors(
                x, c, log_out=transformed_log_likelihood(hsmm, x, transforms)
            )
            if not np.isfinite(ll):
                continue
            total += ll
        else:
            gamma, dur_post = hard_posteriors(
                len(x), boundaries[i], hsmm.n_states, hsmm.max_duration_
            )
        pdf_out, pdf_dur = hsmm.chain(c)
        g = np.zeros((n_pdf, len(x)))
        np.add.at(g, pdf_out, gamma.T)
        out.occ += g.sum(axis=1)
        out.sums += g @ x
        for b, sec in zip(blocks, out.second, strict=True):
            xi = np.hstack([x[:, b], np.ones((len(x), 1))])
            sec += np.einsum("pt,ta,tb->pab", g, xi, xi)
        np.add.at(dur.occ, pdf_dur, dur_post.sum(axis=1))
        np.add.at(dur.sums[:, 0], pdf_dur, dur_post @ d)
        np.add.at(dur.second[0], pdf_dur, np.einsum("nd,dab->nab", dur_post, xi_d))
    return out, dur, total


def transformed_log_likelihood(
    hsmm: HSMM, x: np.ndarray, transforms: Transforms | None
) -> np.ndarray:
    """(T, P) output log densities of frames x, each density seeing x through its class's transform."""
    if transforms is None:
        return log_gaussian_diag(x, hsmm.means_, hsmm.variances_)
    out = np.empty((len(x), len(hsmm.means_)))
    for r, w in enumerate(transforms.w):
        sel = transforms.classes == r
        if sel.any():
            out[:, sel] = log_gaussian_diag(
                apply_features(w, x), hsmm.means_[sel], hsmm.variances_[sel]
            ) + log_abs_det(w)
    return out


# ------------------------------------------------------------------ estimation
def estimate_transforms(
    stats: AdaptationStats,
    means: np.ndarray,
    variances: np.ndarray,
    blocks: list[np.ndarray],
    tree: RegressionTree,
    tau: float,
    min_occupancy: float,
    start: np.ndarray | None = None,
) -> Transforms:
    """One transform per tree node, estimated top-down (CSMAPLR) and used at the leaves.

    Each node's prior mean is its parent's transform (the root's, the
    identity) with weight ``tau`` frames: the prior precision of row i is
    ``tau`` times the node's per-frame average of diag(G_i). ``tau = 0`` is
    plain CMLLR. A node with fewer than ``min_occupancy`` frames keeps its
    parent's transform; with a prior (``tau > 0``) the root is estimated
    from any data, its identity prior standing in for the missing frames
    (SMAPLR), so that a step or two still moves the model.
    """
    n_nodes = len(tree.parents)
    dims = means.shape[1]
    ident = identity_transform(dims)
    w_nodes = np.empty((n_nodes, dims, dims + 1))
    prec = 1.0 / variances
    for node in range(n_nodes):
        parent = tree.parents[node]
        prior = ident if parent < 0 else w_nodes[parent]
        mem = tree.members[node]
        beta = stats.occ[mem].sum()
        if beta <= 0 or (beta < min_occupancy and (parent >= 0 or tau <= 0)):
            w_nodes[node] = prior
            continue
        w = prior.copy() if start is None else start[node].copy()
        for b, sec in zip(blocks, stats.second, strict=True):
            cols = np.append(b, dims)
            g = np.einsum("pab,pi->iab", sec[mem], prec[mem][:, b])
            k = np.einsum("pa,pi->ia", stats.first(b)[mem], (means * prec)[mem][:, b])
            h = prior[np.ix_(b, cols)]
            weight = None
            if tau > 0:
                weight = tau * np.einsum("iaa->ia", g) / beta
            w[np.ix_(b, cols)] = cmllr_rows(
                w[np.ix_(b, cols)], g, k, beta, h if tau > 0 else None, weight
            )
        w_nodes[node] = w
    return Transforms(w_nodes, tree.leaves())


def state_position_tree(dur_map: np.ndarray) -> RegressionTree:
    """Duration classes: the root, then one node per state position (diagonal A_d of eq. 6)."""
    n_dur = int(dur_map.max()) + 1
    n_states = dur_map.shape[1]
    members = np.zeros((n_states + 1, n_dur), dtype=bool)
    members[0] = True
    for s in range(n_states):
        members[s + 1, np.unique(dur_map[:, s])] = True
    return RegressionTree(np.array([-1] + [0] * n_states), members)


def map_means(prior: np.ndarray, occ: np.ndarray, sums: np.ndarray, tau: float) -> np.ndarray:
    """MAP means: (tau mu_prior + sum x) / (tau + occupancy)."""
    return (tau * prior + sums) / (tau + occ[:, None])


def adapt(
    hsmm: HSMM,
    sequences: Sequence[np.ndarray],
    contexts: Sequence[np.ndarray],
    method: str = "csmaplr",
    structure: str = "stream",
    n_iter: int = 3,
    tau: float = 20.0,
    tau_dur: float = 5.0,
    tau_map: float = 5.0,
    tau_dur_map: float = 5.0,
    tree_depth: int = 3,
    min_occupancy: float = 40.0,
    map_step: bool = True,
    max_duration: int | None = None,
    boundaries: Sequence[np.ndarray] | None = None,
) -> HSMM:
    """A copy of ``hsmm`` adapted to the sequences: linear transforms (eqs. 5-6), then MAP.

    Args:
        method: ``"csmaplr"`` (regression-class tree with structural MAP
            priors of weight ``tau`` frames) or ``"cmllr"`` (one transform
            per block, no prior).
        structure: ``"stream"`` (full transforms of the static, delta and
            delta-delta blocks) or ``"diagonal"`` (a scale and bias per dimension).
        n_iter: E-step / transform re-estimation rounds.
        tau_dur: CSMAPLR prior weight of the duration transforms, in state visits.
        tau_map, tau_dur_map: MAP prior weights, in frames and in state visits.
        map_step: follow the transforms by MAP adaptation of the means (§5.1.3).
        max_duration: longest state duration to consider, if the new data
            need more than the model's.
        boundaries: first frame of each unit, then T, per sequence. The
            first transforms are then estimated from these units split evenly
            among their states (as training starts), before ``n_iter`` rounds
            of forward-backward; without them, the unadapted model's own
            alignment of the new data starts, which can misplace units badly.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}")
    dims = hsmm.means_.shape[1]
    blocks = transform_blocks(dims, structure)
    if method == "csmaplr":
        scaled = hsmm.means_ / np.sqrt(hsmm.variances_.mean(axis=0))
        tree = regression_tree(scaled, tree_depth)
        prior_tau = tau
    else:
        tree = RegressionTree(np.array([-1]), np.ones((1, len(hsmm.means_)), dtype=bool))
        prior_tau = 0.0
    dur_tree = state_position_tree(hsmm.dur_map_)
    work = _copy(hsmm)
    work.max_duration_ = max(hsmm.max_duration_, max_duration or 0)
    out_t = dur_t = None
    rounds = [None] * n_iter if boundaries is None else [boundaries] + [None] * n_iter
    for bounds in rounds:
        stats, dstats, _ = adaptation_statistics(work, sequences, contexts, blocks, out_t, bounds)
        out_t = estimate_transforms(
            stats,
            hsmm.means_,
            hsmm.variances_,
            blocks,
            tree,
            prior_tau,
            min_occupancy,
            None if out_t is None else out_t.w,
        )
        dur_t = estimate_transforms(
            dstats,
            hsmm.dur_means_[:, None],
            hsmm.dur_variances_[:, None],
            [np.array([0])],
            dur_tree,
            tau_dur if method == "csmaplr" else 0.0,
            1.0,
        )
        m, v = dur_t.model_space(hsmm.dur_means_[:, None], hsmm.dur_variances_[:, None])
        work.dur_means_, work.dur_variances_ = (
            np.maximum(m[:, 0], 1.0),
            np.maximum(v[:, 0], hsmm.dur_var_floor),
        )
    adapted = _copy(work)
    adapted.means_, v = out_t.model_space(hsmm.means_, hsmm.variances_)
    adapted.variances_ = np.maximum(v, hsmm.var_floor_)
    if map_step:
        stats, dstats, _ = adaptation_statistics(adapted, sequences, contexts, blocks[:0])
        adapted.means_ = map_means(adapted.means_, stats.occ, stats.sums, tau_map)
        dur = map_means(adapted.dur_means_[:, None], dstats.occ, dstats.sums, tau_dur_map)
        adapted.dur_means_ = np.maximum(dur[:, 0], 1.0)
    return adapted


def _copy(hsmm: HSMM) -> HSMM:
    out = HSMM(**hsmm.get_params())
    for k, v in vars(hsmm).items():
        if k.endswith("_"):
            setattr(out, k, np.copy(v) if isinstance(v, np.ndarray) else v)
    return out


def walker_adaptive_training(
    hsmm: HSMM,
    sequences: Sequence[np.ndarray],
    contexts: Sequence[np.ndarray],
    units: Sequence[str],
    n_rounds: int = 2,
    structure: str = "stream",
    tau: float = 20.0,
) -> dict[str, np.ndarray]:
    """Walker-adaptive training (§5.1.2; speaker-adaptive training with CMLLR).

    Each round estimates one feature transform per adaptation unit (a take, a
    walker, a dataset) against the current model, then re-trains the model by
    EM on the transformed features, so that differences between units go into
    the transforms rather than into the model's variances. ``hsmm`` is updated
    in place; returns the transform (O, O + 1) of each unit.
    """
    dims = hsmm.means_.shape[1]
    blocks = transform_blocks(dims, structure)
    root = RegressionTree(np.array([-1]), np.ones((1, len(hsmm.means_)), dtype=bool))
    names = sorted(set(units))
    transforms = {u: identity_transform(dims) for u in names}
    for _ in range(n_rounds):
        for u in names:
            idx = [i for i, name in enumerate(units) if name == u]
            stats, _, _ = adaptation_statistics(
                hsmm,
                [sequences[i] for i in idx],
                [contexts[i] for i in idx],
                blocks,
                Transforms(transforms[u][None], np.zeros(len(hsmm.means_), dtype=int)),
            )
            transforms[u] = estimate_transforms(
                stats, hsmm.means_, hsmm.variances_, blocks, root, tau, 1.0, transforms[u][None]
            ).w[0]
        hsmm.em(
            [apply_features(transforms[u], x) for u, x in zip(units, sequences, strict=True)],
            contexts,
        )
    return transforms

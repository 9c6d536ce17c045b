"""Dual HMM: the responsive motion of person B from the motion of person A (dual-HMM paper).

The model (§2, eqs. 1-2) is one chain -- initial distribution pi and
transition matrix T -- with two emission sets: lambda_A = (T, B_A, pi) over
A's poses and lambda_B = (T, B_B, pi) over B's, each pose reduced by PCA to
95 % of its energy. Two ways to learn it:

- ``mode="paper"``: EM on A alone; B's state Gaussians are B's frames
  weighted by A's state posteriors.
- ``mode="joint"``: EM on the concatenated [A, B] vectors; B_A and B_B are
  the marginals of each state's Gaussian.

Generation (§3): A's states by standard Viterbi over the whole input, or by
the windowed Viterbi decoder frame by frame (:mod:`.windowed_viterbi`); then
B's poses through the trellis of §3.2. Column t of the trellis holds
``candidates`` training frames of B from state q_t, those whose paired A
frames are nearest the input A pose; D4 is that Mahalanobis distance (under
B_A of q_t) and D1..DK the Mahalanobis distances (under B_B of q_t) from a
candidate to the candidates of column t - 1. A step into candidate j costs
(D_k) x D4, so the error of a path is a sum of (D1 + D2 + D3)-type terms
weighted by D4, with E = D4 in the first column; the lowest-error path is
back-tracked. Online, the trellis runs over each slice of the windowed
decoder, from the B frame already shown, and its first step is taken
(:class:`Partner`). Where B stands relative to A is then averaged over the
path's neighbouring frames (``placement_window``; our addition, README).

Features. A is seen as body-centred joint positions (mm), as the paper's
marker positions, by default with their change and A's travel
(``observation="motion"``: on salsa, where A goes says as much about B as
A's pose), + PCA. B is modelled as joint positions *in A's ground
frame* (A's pelvis on the floor, A's heading) + PCA, so that B_B and D1..DK
measure what the evaluation measures: where B's joints are relative to A, in
mm. The trellis picks real training frames of B, kept as exponential maps
(with B's root relative to A), so the output is a Motion on B's skeleton
without inverse kinematics; it is put back into the world through A's own
ground frame.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from sklearn.base import BaseEstimator

from markovmotion.algorithms.gaussian import (
    gaussian_log_density,
    precision_cholesky,
    weighted_gaussians,
)
from markovmotion.algorithms.hmm_recursions import viterbi
from markovmotion.algorithms.windowed_viterbi import (
    INITIAL,
    WindowedViterbi,
    leavable,
    start_distribution,
)
from markovmotion.core.motion import Motion
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features import PCA, BodyMotion, ExpMaps, FeaturePipeline, JointPositions
from markovmotion.features.body_motion import ground_frame
from markovmotion.models.hmm.gaussian import GaussianHMM, check_sequences, safe_log
from markovmotion.persist import load_npz, save_npz
from markovmotion.progress import err_console
from markovmotion.state import estimator_state, register, restore_estimator

KIND = "dual_hmm"
MODES = ("paper", "joint")
OBSERVATIONS = ("pose", "motion")
METHODS = ("standard", "windowed")


# ------------------------------------------------------------------ A's ground frame
def into_frame(motion: Motion, origin: np.ndarray, yaw: np.ndarray) -> Motion:
    """``motion`` seen from the per-frame ground frame (origin, yaw): a rigid move of its root."""
    out = motion.copy()
    out.rotations[:, 0], out.translations[:, 0] = _turn_root(
        motion.rotations[:, 0], motion.translations[:, 0] - origin, -yaw
    )
    return out


def out_of_frame(motion: Motion, origin: np.ndarray, yaw: np.ndarray) -> Motion:
    """Inverse of :func:`into_frame`: back to world coordinates."""
    out = motion.copy()
    out.rotations[:, 0], out.translations[:, 0] = _turn_root(
        motion.rotations[:, 0], motion.translations[:, 0], yaw
    )
    out.translations[:, 0] += origin
    return out


def _turn_root(
    quat: np.ndarray, position: np.ndarray, yaw: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Root rotations (F, 4) and positions (F, 3) turned by ``yaw`` (F,) about +Y: the
    quaternion product (0, sin(yaw / 2), 0, cos(yaw / 2)) q, written out (one online frame
    is ~10x faster than through SciPy's Rotation)."""
    s, c = np.sin(yaw / 2), np.cos(yaw / 2)
    x, y, z, w = quat.T
    turned = np.stack([c * x + s * z, c * y + s * w, c * z - s * x, c * w - s * y], axis=1)
    s, c = np.sin(yaw), np.cos(yaw)
    px, py, pz = position.T
    return turned, np.stack([c * px + s * pz, py, c * pz - s * px], axis=1)


def finite_frames(motion: Motion) -> np.ndarray:
    """(F,) whether each frame's rotations and translations are all finite numbers."""
    return np.isfinite(motion.rotations).all(axis=(1, 2)) & np.isfinite(motion.translations).all(
        axis=(1, 2)
    )


# ------------------------------------------------------------------ the trellis of §3.2
@dataclass
class _Trellis:
    """Training frames grouped by state, pre-whitened for the Mahalanobis distances of §3.2."""

    members: list[np.ndarray]  # per state: indices of its training frames
    white_a: list[np.ndarray]  # per state: their A vectors @ P_A[k]
    prec_a: np.ndarray  # (N, Da, Da)
    prec_b: np.ndarray  # (N, Db, Db)
    train_b: np.ndarray  # (frames, Db)
    size: int
    motion_b: Motion  # B's training frames relative to A, decoded once

    def candidates(self, state: int, xa: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Column entries (K,) for one frame and their D4; a missing A frame gives D4 = 1."""
        wa = self.white_a[state]
        k = min(self.size, len(wa))
        if xa is None:
            d4 = np.linalg.norm(wa - wa.mean(axis=0), axis=1)
        else:
            d4 = np.linalg.norm(wa - xa @ self.prec_a[state], axis=1)
        pick = np.argpartition(d4, k - 1)[:k] if k < len(wa) else np.arange(len(wa))
        return self.members[state][pick], (np.ones(k) if xa is None else d4[pick])

    def distances(self, state: int, idx: np.ndarray, prev: np.ndarray) -> np.ndarray:
        """(K, K') Mahalanobis distances D1..DK' between B candidates, under B_B of ``state``."""
        p = self.prec_b[state]
        return np.linalg.norm(
            (self.train_b[idx] @ p)[:, None, :] - (self.train_b[prev] @ p)[None, :, :], axis=-1
        )

    def columns(self, states: Sequence[int], xa: Sequence[np.ndarray | None]) -> list[tuple]:
        """The trellis columns (:meth:`candidates`) of frames in ``states`` seen as ``xa``."""
        return [self.candidates(q, x) for q, x in zip(states, xa, strict=True)]

    def best_path(
        self,
        states: Sequence[int],
        cols: list[tuple],
        previous: int | None = None,
        steps: list[np.ndarray] | None = None,
    ) -> np.ndarray:
        """Training frame per column on the lowest-error path; E = D4 in the first column, or
        D x D4 from the frame ``previous`` already shown. ``steps[t - 1]``: the
        :meth:`distances` from column t - 1 to column t, if already computed."""
        idx, cost = cols[0]
        if previous is not None:
            cost = cost * self.distances(states[0], idx, np.array([previous]))[:, 0]
        if steps is None:
            steps = [
                self.distances(states[t], cols[t][0], cols[t - 1][0]) for t in range(1, len(cols))
            ]
        k = len(idx)  # every column holds K = min(size, training frames) (see DualHMM._trellis)
        d4 = np.array([c[1] for c in cols[1:]]).reshape(-1, k)
        pick = _lowest_error_path(cost, d4, np.array(steps).reshape(-1, k, k))
        return np.array([c[0][j] for c, j in zip(cols, pick, strict=True)], dtype=int)

    def placement(self, path: np.ndarray, half: int, before: Sequence[int] = ()) -> np.ndarray:
        """(F, 3) B's root in A's ground frame along ``path``: the mean over frames t - half ..
        t + half (those that exist; ``before``: frames shown before the path's first)."""
        roots = self.motion_b.translations[np.concatenate([before, path]).astype(int), 0]
        csum = np.vstack([np.zeros((1, 3)), np.cumsum(roots, axis=0)])
        t = np.arange(len(before), len(roots))
        lo, hi = np.maximum(t - half, 0), np.minimum(t + half + 1, len(roots))
        return (csum[hi] - csum[lo]) / (hi - lo)[:, None]


@numba.njit(cache=True)
def _lowest_error_path(cost, d4, steps):  # pragma: no cover - numba
    """Entry per column (T,) on the lowest-error path through the trellis: E_t(i) =
    min_j E_{t-1}(j) + D_t(i, j) D4_t(i), from E_0 = ``cost`` (K,), ``d4`` (T - 1, K) and
    ``steps`` D_t (T - 1, K, K); ties go to the first entry, as with ``argmin``. Compiled:
    in NumPy each column cost several calls, most of an online step's trellis time."""
    n, k = len(d4) + 1, len(cost)
    back = np.zeros((n, k), dtype=np.int64)
    cost, new = cost.copy(), np.empty(k)
    for t in range(1, n):
        for i in range(k):
            best, arg = np.inf, 0
            for j in range(k):
                e = cost[j] + steps[t - 1, i, j] * d4[t - 1, i]
                if e < best:
                    best, arg = e, j
            new[i], back[t, i] = best, arg
        cost[:] = new
    path = np.empty(n, dtype=np.int64)
    path[-1] = np.argmin(cost)
    for t in range(n - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


# ------------------------------------------------------------------ the model
@register
class DualHMM(BaseEstimator):
    """Dual HMM of two interacting people; generates B from A offline or online.

    Args:
        n_states: hidden states N.
        mode: ``"paper"`` or ``"joint"`` (module docstring).
        observation: what A's observations hold: ``"pose"``, body-centred joint
            positions as in the paper, or ``"motion"``, those plus their change
            and A's travel (:class:`~markovmotion.features.BodyMotion`).
        energy: PCA energy kept per person (the paper's 95 %).
        fps: the model's frame rate; motions at other rates are resampled.
        window: windowed-Viterbi slice length T (the paper's 10).
        initial: first slice's pi, ``"middle"`` (eq. 3) or ``"prior"`` (learnt pi).
        candidates: trellis entries per column (the paper's figure has 3; more
            lets the trellis follow A more closely: README, "Virtual partner").
        placement_window: B's place relative to A (its root position in A's
            ground frame) is the mean over this many frames of the chosen path,
            centred on the frame (1: each frame's own). Online, at most
            ``2 * lag + 1`` frames: the slice the decoder looks ahead anyway.
            The default, 2 x 9 + 1 for the paper's window, was chosen by
            nested leave-one-pair-out on salsa (README).
        n_iter, tol, var_floor, random_state, n_jobs: EM settings (:class:`GaussianHMM`).

    Learnt: ``lambda_a_`` and ``lambda_b_`` (:class:`GaussianHMM` sharing pi
    and T), ``pipeline_a_`` / ``pipeline_b_`` (features), ``expmaps_b_`` and
    ``frames_b_`` (B's training frames), ``train_a_`` / ``train_b_`` (their
    features), ``train_states_``, ``skeleton_a_`` / ``skeleton_b_``.
    """

    def __init__(
        self,
        n_states: int = 32,
        mode: str = "paper",
        observation: str = "motion",
        energy: float = 0.95,
        fps: float = 30.0,
        window: int = 10,
        initial: str = "middle",
        candidates: int = 10,
        placement_window: int = 19,
        n_iter: int = 50,
        tol: float = 1e-2,
        var_floor: float = 1e-3,
        random_state: int | None = 0,
        n_jobs: int | None = None,
    ):
        self.n_states = n_states
        self.mode = mode
        self.observation = observation
        self.energy = energy
        self.fps = fps
        self.window = window
        self.initial = initial
        self.candidates = candidates
        self.placement_window = placement_window
        self.n_iter = n_iter
        self.tol = tol
        self.var_floor = var_floor
        self.random_state = random_state
        self.n_jobs = n_jobs

    # ---------------------------------------------------------------- fitting
    def fit(self, pairs: Sequence[tuple[Motion, Motion]]) -> DualHMM:
        """Learn from two-person takes ``(A, B)`` (same frames; B responds to A)."""
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {self.observation!r}")
        if self.initial not in INITIAL:
            raise ValueError(f"initial must be one of {INITIAL}, got {self.initial!r}")
        if not pairs:
            raise ValueError("no two-person takes to learn from")
        a_list, b_rel = [], []
        for a, b in pairs:
            if a.n_frames != b.n_frames:
                raise ValueError(f"{a.name} and {b.name} differ in length")
            a, b = self._rate(a), self._rate(b)
            a_list.append(a)
            b_rel.append(into_frame(b, *ground_frame(a)))
        self.skeleton_a_ = a_list[0].skeleton
        self.skeleton_b_ = b_rel[0].skeleton
        first = BodyMotion() if self.observation == "motion" else JointPositions()
        self.pipeline_a_ = FeaturePipeline([first, PCA(self.energy)])
        self.pipeline_b_ = FeaturePipeline([JointPositions(body_centred=False), PCA(self.energy)])
        self.expmaps_b_ = ExpMaps(root_position="full")
        xa, lengths = check_sequences(
            np.vstack(self.pipeline_a_.fit_transform(a_list)), [len(m) for m in a_list]
        )
        xb = np.vstack(self.pipeline_b_.fit_transform(b_rel))
        self.frames_b_ = np.vstack(self.expmaps_b_.fit_transform(b_rel)).astype(np.float32)
        self.train_a_, self.train_b_ = xa, xb
        hmm = GaussianHMM(
            self.n_states,
            self.n_iter,
            self.tol,
            self.var_floor,
            random_state=self.random_state,
            n_jobs=self.n_jobs,
        )
        da = xa.shape[1]
        if self.mode == "paper":
            self.lambda_a_ = hmm.fit(xa, lengths)
            hmm.transmat_ = leavable(hmm.transmat_)
            gamma = hmm.predict_proba(xa, lengths)
            floor = self.var_floor * np.var(xb, axis=0).mean()
            means_b, covars_b, _ = weighted_gaussians(xb, gamma, floor)
            self.lambda_b_ = _sharing_chain(hmm, means_b, covars_b, floor)
            self.train_states_ = hmm.decode(xa, lengths)[1]
        else:
            xab = np.hstack([xa, xb])
            joint = hmm.fit(xab, lengths)
            joint.transmat_ = leavable(joint.transmat_)
            self.train_states_ = joint.decode(xab, lengths)[1]
            m, c, floor = joint.means_, joint.covars_, joint.covar_floor_
            self.lambda_a_ = _sharing_chain(joint, m[:, :da], c[:, :da, :da], floor)
            self.lambda_b_ = _sharing_chain(joint, m[:, da:], c[:, da:, da:], floor)
        self.history_ = hmm.history_
        self._trellis_cache = None
        return self

    def _rate(self, motion: Motion) -> Motion:
        return motion if np.isclose(motion.fps, self.fps) else motion.resample(self.fps)

    # ---------------------------------------------------------------- generation
    def check_input(self, motion: Motion, source: str | os.PathLike[str] | None = None) -> None:
        """Raise :class:`SkeletonMismatchError` (naming ``source``) unless A's skeleton is the model's."""
        try:
            self.skeleton_a_.check_compatible(motion.skeleton, "input")
        except SkeletonMismatchError as exc:
            where = source or motion.name or "input motion"
            raise SkeletonMismatchError(
                f"{where}: person A's skeleton is not the model's ({exc})"
            ) from None

    def features_a(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """A's model features (F, Da) at the model's rate and which frames are missing (NaN)."""
        missing = ~finite_frames(motion)
        return self.pipeline_a_.transform([_fill_missing(motion, missing)])[0], missing

    def generate(self, motion_a: Motion, method: str = "standard") -> Motion:
        """B's responsive motion to ``motion_a`` (at the model's rate, in A's world).

        ``method="standard"``: Viterbi over all of A, lowest-error trellis path.
        ``method="windowed"``: exactly what :meth:`partner` streams, frame by frame.
        Frames of A with NaN values count as missing observations.
        """
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.check_input(motion_a)
        motion_a = self._rate(motion_a)
        xa, missing = self.features_a(motion_a)
        log_b = self.lambda_a_.log_frameprob(xa)
        log_b[missing] = 0.0
        trellis = self._trellis()
        seen = [None if m else x for x, m in zip(xa, missing, strict=True)]
        if method == "standard":
            states = self.decode(log_b)
            idx = trellis.best_path(states, trellis.columns(states, seen))
            root = trellis.placement(idx, self.placement_window // 2)
        else:
            partner = self.partner()
            chosen = [
                partner.step_log_frameprob(row, x) for row, x in zip(log_b, seen, strict=True)
            ]
            chosen = [c for c in chosen if c is not None] + partner.finish_frames()
            idx = np.array([i for i, _ in chosen], dtype=int)
            root = np.array([r for _, r in chosen])
        return self.frames_to_motion(idx, *ground_frame(_fill_missing(motion_a, missing)), root)

    def decode(self, log_frameprob: np.ndarray) -> np.ndarray:
        """Standard Viterbi states of A's frames from their log emission probabilities."""
        hmm = self.lambda_a_
        return viterbi(safe_log(hmm.startprob_), safe_log(hmm.transmat_), log_frameprob)[0]

    def frames_to_motion(
        self,
        idx: np.ndarray,
        origin: np.ndarray,
        yaw: np.ndarray,
        root: np.ndarray | None = None,
    ) -> Motion:
        """B's training frames ``idx`` as a Motion placed by A's ground frame (origin, yaw);
        ``root`` (F, 3): B's root positions in A's ground frame instead of the frames' own."""
        frames = self._trellis().motion_b
        rel = Motion(self.skeleton_b_, frames.rotations[idx], frames.translations[idx], self.fps)
        if root is not None:
            rel.translations[:, 0] = root
        out = out_of_frame(rel, origin, yaw)
        out.fps = self.fps
        return out

    def partner(self, window: int | None = None) -> Partner:
        """An online virtual partner (windowed Viterbi; ``window`` defaults to the model's)."""
        return Partner(self, window or self.window)

    def _trellis(self) -> _Trellis:
        cache = getattr(self, "_trellis_cache", None)
        if cache is not None:
            return cache
        prec_a, _ = precision_cholesky(self.lambda_a_.covars_)
        prec_b, _ = precision_cholesky(self.lambda_b_.covars_)
        members, white = [], []
        for k in range(self.n_states):
            idx = np.flatnonzero(self.train_states_ == k)
            if len(idx) < self.candidates:  # a state no training frame decodes to: nearest frames
                d = np.linalg.norm((self.train_a_ - self.lambda_a_.means_[k]) @ prec_a[k], axis=1)
                idx = np.argsort(d)[: self.candidates]
            members.append(idx)
            white.append(self.train_a_[idx] @ prec_a[k])
        motion_b = self.expmaps_b_.inverse_transform([self.frames_b_.astype(float)])[0]
        self._trellis_cache = _Trellis(
            members, white, prec_a, prec_b, self.train_b_, self.candidates, motion_b
        )
        return self._trellis_cache

    # ---------------------------------------------------------------- files
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model (pipelines and skeletons in the header) to an ``.npz``."""
        arrays: dict[str, np.ndarray] = {}
        save_npz(path, KIND, {"model": estimator_state(self, "model", arrays)}, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> DualHMM:
        """Read a model written by :meth:`save` (:class:`ModelFormatError` if it is not one)."""
        header, arrays = load_npz(path, KIND)
        return restore_estimator(header["model"], arrays)


def _sharing_chain(
    hmm: GaussianHMM, means: np.ndarray, covars: np.ndarray, floor: float
) -> GaussianHMM:
    """lambda = (T, B, pi) with ``hmm``'s pi and T and the Gaussians given (eqs. 1-2)."""
    out = GaussianHMM(hmm.n_components, hmm.n_iter, hmm.tol, hmm.var_floor, n_jobs=hmm.n_jobs)
    out.startprob_, out.transmat_ = hmm.startprob_, hmm.transmat_
    out.means_, out.covars_, out.covar_floor_ = means, covars, floor
    out.history_, out.n_iter_, out.converged_ = hmm.history_, hmm.n_iter_, hmm.converged_
    return out


def _fill_missing(motion: Motion, missing: np.ndarray) -> Motion:
    """Missing frames replaced by the last finite one (the first finite one before it; the
    rest pose if none is finite): A's place for the B frames shown then, and no jump in A's
    motion features."""
    if not missing.any():
        return motion
    out = motion.copy()
    if missing.all():
        out.rotations[:] = [0.0, 0.0, 0.0, 1.0]
        out.translations[:] = motion.skeleton.offsets
        return out
    keep = np.maximum.accumulate(np.where(missing, 0, np.arange(len(missing))))
    keep[: int(np.argmin(missing))] = int(np.argmin(missing))
    out.rotations, out.translations = motion.rotations[keep], motion.translations[keep]
    return out


class Partner:
    """The virtual partner online: one frame of A in, one frame of B out, ``lag`` frames late.

    ``lag = window - 1`` frames (0.30 s at 30 fps with the paper's window of
    10). When frame t + lag arrives, the windowed decoder's latest slice
    covers frames t .. t + lag: its q_1 is frame t's state, decided (§3.1),
    the rest are that slice's best path. B's frame for t is the first step of
    the lowest-error trellis path (§3.2) over the slice, starting from the B
    frame shown last: the trellis run the windowed way, as §3.1 runs Viterbi,
    so it looks as far ahead as the decoder; B's place relative to A is
    averaged over the frames shown last and the path ahead
    (``placement_window``). :meth:`step` returns None until the first B frame
    is due; :meth:`finish` returns the last ``lag`` frames.
    A frame that is None or holds NaN is a missing observation: a warning,
    and the partner goes on from the dynamics alone.
    """

    def __init__(self, model: DualHMM, window: int):
        self.model = model
        hmm = model.lambda_a_
        start = start_distribution(safe_log(hmm.startprob_), model.initial)
        self.decoder = WindowedViterbi(start, safe_log(hmm.transmat_), window)
        self.lag = window - 1
        self._trellis = model._trellis()
        prec, log_det = precision_cholesky(hmm.covars_)
        self._emission = (hmm.means_, prec, log_det)
        self._slice: deque = deque(maxlen=window)  # (A's features or None, columns by state)
        self._places: deque = deque(maxlen=window)  # where A stood in the slice's frames
        self._half = min(model.placement_window // 2, self.lag)
        self._history: deque = deque(maxlen=max(self._half, 1))  # B's training frames shown
        self._frames_in = 0
        self._place = (np.zeros(3), 0.0)
        self._checked = None  # A's skeleton, once checked against the model's
        self._last: tuple | None = None  # A's last finite frame (pose, origin, yaw), for its motion

    def step_features(
        self, xa: np.ndarray | None, place: tuple[np.ndarray, float]
    ) -> tuple[int, np.ndarray] | None:
        """Feed A's features (None: missing) and place (origin, yaw); for the frame ``lag``
        frames ago, once one is due, B's training frame and B's root in A's ground frame."""
        if xa is None:
            log_b = np.zeros(len(self._emission[0]))
        else:
            log_b = gaussian_log_density(xa[None], *self._emission)[0]
        self._places.append(place)
        return self.step_log_frameprob(log_b, xa)

    def step_log_frameprob(
        self, log_b: np.ndarray, xa: np.ndarray | None
    ) -> tuple[int, np.ndarray] | None:
        """:meth:`step_features` from A's log emission probabilities (N,), already computed."""
        self._slice.append((xa, {}))
        self.decoder.push(log_b)
        self._frames_in += 1
        if self._frames_in <= self.lag:
            return None
        states = self.decoder.path
        cols = self._columns(states, self._slice)
        path = self._trellis.best_path(states, cols, self._shown, self._steps(states, cols))
        return self._show(path, 1)[0]

    @property
    def _shown(self) -> int | None:
        """B's training frame shown last."""
        return self._history[-1] if self._history else None

    def _show(self, path: np.ndarray, count: int) -> list[tuple[int, np.ndarray]]:
        """Show the first ``count`` B frames of ``path``, each with its averaged place."""
        before = list(self._history) if self._half else []  # the last ``half`` shown
        roots = self._trellis.placement(path, self._half, before)[:count]
        self._history.extend(int(i) for i in path[:count])
        return [(int(i), r) for i, r in zip(path[:count], roots, strict=True)]

    def finish_frames(self) -> list[tuple[int, np.ndarray]]:
        """B's training frames and places still owed at the end of the stream."""
        if self._frames_in == 0:
            return []
        entries = list(self._slice)
        if self._frames_in < self.decoder.window:
            states = self.decoder.flush()
        else:
            states, entries = list(self.decoder.path[1:]), entries[1:]
        if not entries:
            return []
        path = self._trellis.best_path(states, self._columns(states, entries), self._shown)
        return self._show(path, len(path))

    def _columns(self, states: Sequence[int], entries: Sequence[tuple]) -> list[tuple]:
        cols = []
        for q, (xa, cache) in zip(states, entries, strict=True):
            if q not in cache:
                cache[q] = self._trellis.candidates(q, xa)
            cols.append(cache[q])
        return cols

    def _steps(self, states: Sequence[int], cols: list[tuple]) -> list[np.ndarray]:
        """Distances between consecutive columns of the slice, each computed once per pair of
        states (a slice shares all but its last column with the one before)."""
        out = []
        for t in range(1, len(cols)):
            cache = self._slice[t][1]
            key = (states[t], states[t - 1])
            if key not in cache:
                cache[key] = self._trellis.distances(states[t], cols[t][0], cols[t - 1][0])
            out.append(cache[key])
        return out

    def step(self, frame: Motion | None) -> Motion | None:
        """One frame of A (a one-frame Motion) in; B's frame of ``lag`` frames ago out."""
        if frame is None or not finite_frames(frame)[0]:
            err_console.print(
                f"[yellow]warning:[/] frame {self._frames_in} of A is missing or holds NaN: skipped",
                highlight=False,
            )
            return self.skip()
        if frame.skeleton is not self._checked:
            self.model.check_input(frame)
            self._checked = frame.skeleton
        pos = frame.positions()
        origin, yaw = ground_frame(frame, pos)
        self._place = (origin[0], float(yaw[0]))
        return self._motion(
            self.step_features(self._features(frame, pos, origin, yaw), self._place)
        )

    def _features(
        self, frame: Motion, pos: np.ndarray, origin: np.ndarray, yaw: np.ndarray
    ) -> np.ndarray:
        """A's model features of ``frame`` from its joint positions and ground frame: with A's
        motion in the observation, :meth:`BodyMotion.rows` of the last finite frame and this
        one (what :meth:`DualHMM.features_a` gives for this frame of the whole stream)."""
        first, *rest = self.model.pipeline_a_.steps
        if not isinstance(first, BodyMotion):
            return self.model.features_a(frame)[0][-1]
        now = (frame.body_centred_positions(pos), origin, yaw)
        last, self._last = self._last, now
        if last is not None:
            now = tuple(np.concatenate(p) for p in zip(last, now, strict=True))
        x = first.rows(*now, frame.fps)
        for step in rest:
            x = step.transform([x])[0]
        return x[-1]

    def skip(self) -> Motion | None:
        """A frame the caller could not deliver (dropped): no observation, no warning."""
        return self._motion(self.step_features(None, self._place))

    def finish(self) -> list[Motion]:
        """B's frames still owed at the end of the stream."""
        frames = self.finish_frames()
        places = list(self._places)[len(self._places) - len(frames) :]
        return [self._motion(i, p) for i, p in zip(frames, places, strict=True)]

    def _motion(
        self, shown: tuple[int, np.ndarray] | None, place: tuple[np.ndarray, float] | None = None
    ) -> Motion | None:
        """B's frame ``shown`` (training frame, root) placed by A's place for it (default: the
        slice's first)."""
        if shown is None:
            return None
        origin, yaw = place or self._places[0]
        return self.model.frames_to_motion(
            np.array([shown[0]]), origin[None], np.array([yaw]), shown[1][None]
        )

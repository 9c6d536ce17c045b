"""Dual HMM: the responsive motion of person B from the motion of person A (dual-HMM paper).

The model (§2, eqs. 1-2) is one chain -- initial distribution pi and
transition matrix T -- with two emission sets: lambda_A = (T, B_A, pi) over
A's poses and lambda_B = (T, B_B, pi) over B's, each pose reduced by PCA to
95 % of its energy. Two ways to learn it:

- ``mode="paper"``: EM on A alone; B's state Gaussians are B's frames
  weighted by A's state posteriors.
- ``mode="joint"``: EM on the concatenated [A, B] vectors; B_A and B_B are
  the marginals of each state's Gaussian.

Responding (§3): A's states by standard Viterbi over the whole input, or by
the windowed Viterbi decoder frame by frame
(:mod:`markovmotion.algorithms.windowed_viterbi`); then B's poses, real
training frames of B, through the trellis of §3.2 (:mod:`.trellis`: its
equations and how ours differs). Online, the trellis runs over each slice
of the windowed decoder, from the B frame already shown, and its first step
is taken (:class:`~markovmotion.models.hmm.partner.Partner`, from
:meth:`DualHMM.partner`). Where B stands relative to A is then averaged
over the path's neighbouring frames (``placement_window``; our addition).

The verbs (:mod:`markovmotion.models.base`): ``respond`` (B for the whole of
A), ``score`` (log-likelihood of A under lambda_A), ``partner()`` (online).

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

Markers (the paper's own data: 30 PhaseSpace markers, 90 numbers a pose).
Given pairs of :class:`~markovmotion.core.markers.Markers` (C3D files), or
skeleton takes with ``markers=N`` (N virtual markers placed on each person,
:func:`~markovmotion.features.markers.virtual_markers`), the model learns
and answers on markers: A is its markers relative to A's own centroid and
heading (:class:`~markovmotion.features.markers.MarkerFeatures`, with
``observation="motion"`` their change and A's travel) + PCA; B is B's
markers in A's ground frame (A's marker centroid on the floor, A's heading)
+ PCA; the trellis and windowed decoder are the same, and the output is
real training frames of B's markers (``markers_b_``), B's centroid averaged
over ``placement_window`` and B's shape about it over ``blend_window``,
placed through A's ground frame: ``respond`` returns Markers. A model learnt
from C3D markers that name body points (``TORSO``, ``R_HAND``...) answers a skeleton too
(:func:`~markovmotion.features.markers.named_body_points`), lifted to the training people's
height (:class:`~markovmotion.features.markers.Lift`). A marker of A unseen (NaN) for a
moment is held where the others say it is
(:class:`~markovmotion.features.markers.HeldMarkers`), and a frame still with a marker
unseen is a missing observation; gaps in training takes are filled by interpolation
(:func:`~markovmotion.features.markers.fill_gaps`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence

import numba
import numpy as np

from markovmotion.algorithms.gaussian import (
    check_covariance_type,
    compact_of_full,
    covariance_floor,
    floor_covariances,
    gaussian_m_step,
    precision_cholesky,
    state_regressions,
)
from markovmotion.algorithms.hmm_recursions import forward_backward, viterbi
from markovmotion.algorithms.windowed_viterbi import INITIAL, leavable
from markovmotion.core.markers import Markers
from markovmotion.core.motion import GROUND, Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features import PCA, BodyMotion, ExpMaps, FeaturePipeline, JointPositions
from markovmotion.features.body_motion import ground_frame
from markovmotion.features.body_points import BODY_POINTS, body_point_index, body_points
from markovmotion.features.markers import (
    HOLD_SECONDS,
    HeldMarkers,
    Lift,
    MarkerFeatures,
    fill_gaps,
    into_marker_frame,
    named_body_points,
    out_of_marker_frame,
    seen_in_every,
    virtual_markers,
)
from markovmotion.features.person import RunningCentre, body_radius, on_average_body, size_scale
from markovmotion.models.base import Model, check_motion, finite_frames, flatten
from markovmotion.models.hmm.contact import HandContact, contact_shifts, right_hand
from markovmotion.models.hmm.gaussian import GaussianHMM, check_sequences, safe_log
from markovmotion.models.hmm.partner import Partner
from markovmotion.models.hmm.trellis import (
    TRELLISES,
    Trellis,
    blend_positions,
    build_trellis,
    smooth_place,
    successors,
)
from markovmotion.progress import note, say, track
from markovmotion.state import (
    StateError,
    check_count,
    check_index,
    check_shape,
    is_fitted,
    require,
    require_types,
)

__all__ = ["DualHMM", "Partner", "finite_frames", "into_frame", "out_of_frame"]

MODES = ("paper", "joint")
OBSERVATIONS = ("pose", "motion")
POINTS = ("body", "all")
FRAMES = ("auto", "heading", "world")
NORMALISE = ("none", "person")
OUTPUTS = ("frames", "regression")
PLACE_SCALES = ("none", "size")
#: Where a marker model's A stands up and down (``DualHMM(heights=...)``).
HEIGHTS = ("capture", "lifted")
#: A marker A whose mean centroid height is further than this (mm) from the training
#: people's gets a note (another vertical origin?): the training people span about 200 mm.
HEIGHT_NOTE_MM = 250.0
#: The ground plane's axes (y is up).
#: The learnt parts of ``output="regression"`` (:func:`state_regressions`).
_REGRESSION = ("reg_means_a_", "reg_means_b_", "reg_gains_")
#: Its ridge, in units of A's features' mean variance: chosen by leaving one pair of people
#: out on the Bütepage handshakes and waves among 1e-3, 0.1, 1 and 10 (docs/hmm.md).
RIDGE = 1.0
METHODS = ("standard", "windowed")
#: The learnt parts of ``contact_weight`` above 0 (:class:`.contact.HandContact`; a hand of -1:
#: the training takes held no contact).
_CONTACT = ("contact_hand_", "contact_offset_", "contact_coef_")


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


@numba.njit(cache=True)
def _turn_root(quat, position, yaw):  # pragma: no cover - numba
    """Root rotations (F, 4) and positions (F, 3) turned by ``yaw`` (F,) about +Y: the
    quaternion product (0, sin(yaw / 2), 0, cos(yaw / 2)) q, written out, and the positions
    as :func:`~markovmotion.features.markers.turn_about_up` turns them. Compiled: online
    it runs on one frame per frame, where NumPy's calls cost 20x the arithmetic."""
    turned, moved = np.empty((len(yaw), 4)), np.empty((len(yaw), 3))
    for f in range(len(yaw)):
        s, c = np.sin(yaw[f] / 2), np.cos(yaw[f] / 2)
        x, y, z, w = quat[f, 0], quat[f, 1], quat[f, 2], quat[f, 3]
        turned[f, 0], turned[f, 1] = c * x + s * z, c * y + s * w
        turned[f, 2], turned[f, 3] = c * z - s * x, c * w - s * y
        s, c = np.sin(yaw[f]), np.cos(yaw[f])
        x, y, z = position[f, 0], position[f, 1], position[f, 2]
        moved[f, 0], moved[f, 1], moved[f, 2] = c * x + s * z, y, c * z - s * x
    return turned, moved


# ------------------------------------------------------------------ the model
#: What a fitted DualHMM holds (``check_state``), and the types of its parts.
_LEARNT = (
    "skeleton_a_",
    "skeleton_b_",
    "pipeline_a_",
    "pipeline_b_",
    "expmaps_b_",
    "frames_b_",
    "train_a_",
    "train_b_",
    "lambda_a_",
    "lambda_b_",
    "train_states_",
    "train_files_",
)
_LEARNT_TYPES = {
    "skeleton_a_": Skeleton,
    "skeleton_b_": Skeleton,
    "pipeline_a_": FeaturePipeline,
    "pipeline_b_": FeaturePipeline,
    "expmaps_b_": ExpMaps,
    "lambda_a_": GaussianHMM,
    "lambda_b_": GaussianHMM,
}
#: What a DualHMM fitted on markers holds instead of skeletons and exponential maps.
_LEARNT_MARKERS = (
    "marker_names_b_",
    "markers_b_",
    *(k for k in _LEARNT if k not in ("skeleton_a_", "skeleton_b_", "expmaps_b_", "frames_b_")),
)


class DualHMM(Model):
    """Dual HMM of two interacting people; responds to A with B, offline or online.

    Args:
        n_states: hidden states N.
        mode: ``"paper"`` or ``"joint"`` (module docstring).
        observation: what A's observations hold: ``"pose"``, body-centred joint
            positions as in the paper, or ``"motion"``, those plus their change
            and A's travel (:class:`~markovmotion.features.BodyMotion`).
        energy: PCA energy kept per person (the paper's 95 %; nested leave-one-pair-out
            on the CMU 18/19 interactions picks it over 99 % in 3 folds of 4: docs/hmm.md).
        fps: the model's frame rate; motions at other rates are resampled.
        window: windowed-Viterbi slice length T (the paper's 10).
        initial: the windowed decoder's first slice's pi: ``"prior"``, the learnt pi (as
            standard Viterbi's), or ``"middle"``, one-hot on the middle state (eq. 3 as
            printed). With eq. 4's one-hot restarts a decoder started in the wrong part
            of the chain may never leave it: on the CMU 18/19 training takes the windowed
            states agreed with standard Viterbi's in 100 % of frames from the learnt pi,
            and in 0-99 % (0 % on 3 of 24 takes) from the middle state
            (docs/hmm.md, "The windowed decoder's start").
        candidates: trellis entries per column (the paper's figure has 3; more
            lets the trellis follow A more closely: README, "Virtual partner").
        placement_window: B's place relative to A (its root position in A's
            ground frame) is the mean over this many frames of the chosen path,
            centred on the frame (1: each frame's own). Online, at most
            ``2 * lag + 1`` frames: the slice the decoder looks ahead anyway.
            The default, 2 x 9 + 1 for the paper's window, was chosen by
            nested leave-one-pair-out on salsa (README).
        place_memory: A's ground frame, through which B is placed, is averaged over this
            many frames before each frame (and ``placement_window // 2`` after, at most the
            decoder's lag online), in training and in generation; 0 (the default): over
            ``placement_window`` frames centred on it. People who wave or shake hands turn
            their shoulders, not their feet: on the Bütepage takes B's bearing from A's
            facing wobbles by 5-19 degrees within a take while B stands still (docs/hmm.md,
            "New people"); a long memory places B by where A has stood and faced.
        blend_window: B's joint rotations are blended over this many frames of
            the chosen path, centred on the frame (:meth:`Trellis.blend`; 1:
            none), so that a cut between training frames becomes a short
            transition; online, at most ``2 * lag + 1`` frames, no added lag.
            The default 9 was chosen by leave-one-pair-out on the interaction
            and salsa takes (docs/hmm.md, "Smooth partner").
        trellis: ``"path"`` (ours: the lowest-error path through the columns,
            each step measured from the training frame that followed the one
            before) or ``"paper"`` (§3.2 as printed: E = (D1 + ... + DK) x D4,
            the lowest per column); :mod:`.trellis`.
        points: what both people are seen as: ``"body"``, the common body points
            found by joint names (:data:`~markovmotion.features.body_points.BODY_POINTS`),
            so A may come on any skeleton that has them; or ``"all"``, every
            joint of the training skeleton (A must then come on that skeleton).
            Not used on markers.
        markers: 0, or N virtual markers (13 to 200; the paper's suit has 30) placed
            on skeleton takes (:func:`~markovmotion.features.markers.virtual_markers`),
            on which the model then learns and answers (module docstring, "Markers").
            Pairs of Markers (C3D) make a marker model whatever this says.
        frame: how B's place relative to A is measured: ``"heading"``, in A's ground
            frame (A's pelvis on the floor, A's facing: right for partners who turn
            with each other, as in salsa, and for A captured in any room);
            ``"world"``, from A's pelvis along the world's axes (right when the
            training and test takes share one room and B does not turn with A: in
            CMU's pulls A turns side-on while B stays in front); ``"auto"`` (the
            default) picks, by cross-validation on the training takes (one pair of
            people, or one take, left out at a time), the one in which the others' mean
            tells B's place better (:func:`choose_frame`), kept in ``frame_``.
        normalise: ``"none"`` (the paper's) or ``"person"``: A's features relative to A's
            own running mean (:class:`~markovmotion.features.person.RunningCentre`, online)
            and, on markers, B's training frames on the average training body
            (:func:`~markovmotion.features.person.on_average_body`), so that states learn
            how people move rather than who they are: a partner for people the model has
            never seen (docs/hmm.md, "New people").
        output: ``"frames"`` (the paper's §3.2: B's real training frames through the
            trellis) or ``"regression"`` (a marker model only): B's markers as the
            state-conditional regression on A's features
            (:func:`~markovmotion.algorithms.gaussian.state_regressions`, Gaussian mixture
            regression with one component per state), the states decoded by the same
            standard or windowed Viterbi, blended over ``blend_window`` frames.
        contact_weight: 0 (the paper's placement) to 1: where A's right hand is out to B's,
            B is moved (horizontally) this much of the way to where B's hand meets A's, as
            the training pairs' hands met (:mod:`.contact`, our addition): a new pair of
            people that stands further apart than the training pairs shows it in A's reach.
            A model whose training takes hold no contact (waves) learns none and moves
            nothing.
        place_scale: ``"none"`` (the paper's) or ``"size"`` (a marker model only; our
            addition): how far B stands from A scales with the pair's size. Each training
            take's B place (its centroid's horizontal offset in A's ground frame) is taken
            to the average pair by ``2 r / (r_A + r_B)``, with ``r_A``, ``r_B`` the two
            people's mean :func:`~markovmotion.features.person.body_radius` and ``r``
            (``place_size_``) the training people's mean; B's answer is taken back by
            ``(r_A(t) + r) / (2 r)``, with ``r_A(t)`` the running mean of the real A's radius
            (:func:`~markovmotion.features.person.size_scale`, online) and B of the average
            size. On the Bütepage pairs the separation over the pair's summed radius varies
            less than the separation (docs/hmm.md, "B's place and the pair's size").
        heights: ``"capture"`` (the default) or ``"lifted"`` (a C3D marker model; our
            addition): where A stands up and down. ``"capture"`` takes A's markers at the
            heights they come with, as the training capture's (right for the same sensor:
            on the Bütepage pairs a person's centroid height varies by 33 mm across people,
            the partners' difference by 38); ``"lifted"`` lifts every A, as a skeleton is
            always lifted, to the training people's mean centroid height by the causal
            running mean of its own (:class:`~markovmotion.features.markers.Lift`) and
            moves B's answer down as much: for markers whose vertical origin is another
            (another lab's floor, a sensor at another height), where B would otherwise
            stand as far off in height. A marker A further than :data:`HEIGHT_NOTE_MM` from
            the training height with ``"capture"`` gets a note saying so.
        var_floor: each state's variance along PCA feature j is kept at or above this
            fraction of feature j's variance over the training frames (and at least
            ``GaussianHMM``'s absolute ``min_covar``); :class:`GaussianHMM`. The default 0.3
            was chosen by leave-one-pair-out on the CMU 18/19 interactions and on salsa
            (docs/hmm.md, "The variance floor"): with a few hundred frames for 32 states a
            state's own estimate of a minor PCA feature's variance is unreliable.
        covariance_type: the states' Gaussians, ``"full"`` (the paper's), ``"diag"``,
            ``"spherical"`` or ``"tied"`` (:class:`GaussianHMM`).
        n_iter, tol, random_state, n_jobs: EM settings (:class:`GaussianHMM`).

    Learnt: ``lambda_a_`` and ``lambda_b_`` (:class:`GaussianHMM` sharing pi
    and T), ``pipeline_a_`` / ``pipeline_b_`` (features), ``expmaps_b_`` and
    ``frames_b_`` (B's training frames), ``train_a_`` / ``train_b_`` (their
    features), ``train_states_``, ``train_lengths_`` (frames per training
    take, so the trellis knows which frame follows which), ``skeleton_a_`` / ``skeleton_b_``,
    ``labels_`` (the training takes' labels, if given), ``train_files_``
    (both people's files, :meth:`Model.record_training`). On markers, instead of the
    skeletons, ``expmaps_b_`` and ``frames_b_``: ``marker_names_b_`` and ``markers_b_``
    (T, M, 3) float32, B's training markers in A's ground frame.
    """

    KIND = "dual_hmm"
    VERBS = ("respond", "score", "partner")
    SCORES_ONE = True  # log P(A) of one motion of A
    FITS_PAIRS = True
    TAKES_MISSING = True  # a frame holding NaN is a missing observation

    def __init__(
        self,
        n_states: int = 32,
        mode: str = "paper",
        observation: str = "motion",
        energy: float = 0.95,
        fps: float = 30.0,
        window: int = 10,
        initial: str = "prior",
        candidates: int = 10,
        placement_window: int = 19,
        place_memory: int = 0,
        blend_window: int = 9,
        trellis: str = "path",
        points: str = "body",
        frame: str = "auto",
        markers: int = 0,
        normalise: str = "none",
        output: str = "frames",
        contact_weight: float = 0.0,
        place_scale: str = "none",
        heights: str = "capture",
        n_iter: int = 50,
        tol: float = 1e-2,
        var_floor: float = 0.3,
        covariance_type: str = "full",
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
        self.place_memory = place_memory
        self.blend_window = blend_window
        self.trellis = trellis
        self.points = points
        self.frame = frame
        self.markers = markers
        self.normalise = normalise
        self.output = output
        self.contact_weight = contact_weight
        self.place_scale = place_scale
        self.heights = heights
        self.n_iter = n_iter
        self.tol = tol
        self.var_floor = var_floor
        self.covariance_type = covariance_type
        self.random_state = random_state
        self.n_jobs = n_jobs

    # ---------------------------------------------------------------- fitting
    def check_params(self) -> None:
        """Raise ValueError (one line, naming the parameter) for a hyper-parameter out of its
        choices or range: :meth:`fit` checks first, and ``--choose`` every setting before
        anything is learnt."""
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {self.observation!r}")
        if self.initial not in INITIAL:
            raise ValueError(f"initial must be one of {INITIAL}, got {self.initial!r}")
        if self.points not in POINTS:
            raise ValueError(f"points must be one of {POINTS}, got {self.points!r}")
        if self.trellis not in TRELLISES:
            raise ValueError(f"trellis must be one of {TRELLISES}, got {self.trellis!r}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {self.frame!r}")
        if self.normalise not in NORMALISE:
            raise ValueError(f"normalise must be one of {NORMALISE}, got {self.normalise!r}")
        if not (
            isinstance(self.place_memory, int | np.integer) and 0 <= self.place_memory <= 100_000
        ):
            raise ValueError(f"place_memory must be 0 to 100000 frames, got {self.place_memory!r}")
        if self.output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {self.output!r}")
        if self.place_scale not in PLACE_SCALES:
            raise ValueError(f"place_scale must be one of {PLACE_SCALES}, got {self.place_scale!r}")
        if self.heights not in HEIGHTS:
            raise ValueError(f"heights must be one of {HEIGHTS}, got {self.heights!r}")
        counts = ("n_states", "window", "candidates", "placement_window", "blend_window", "n_iter")
        for name in counts:
            value = getattr(self, name)
            if not (isinstance(value, int | np.integer) and not isinstance(value, bool)) or (
                value < 1
            ):
                raise ValueError(f"{name} must be a whole number of at least 1, got {value!r}")
        if not 0.0 < float(self.energy) <= 1.0:
            raise ValueError(f"energy must be above 0 and at most 1, got {self.energy!r}")
        if not (float(self.fps) > 0.0 and np.isfinite(float(self.fps))):
            raise ValueError(f"fps must be above 0, got {self.fps!r}")
        if not (
            isinstance(self.contact_weight, int | float | np.number)
            and 0.0 <= float(self.contact_weight) <= 1.0
        ):
            raise ValueError(f"contact_weight must be 0 to 1, got {self.contact_weight!r}")
        if not float(self.var_floor) >= 0.0:
            raise ValueError(f"var_floor must be 0 or more, got {self.var_floor!r}")
        check_covariance_type(self.covariance_type)

    def fit(
        self,
        pairs: Sequence[tuple[Motion, Motion]] | Sequence[tuple[Markers, Markers]],
        labels: Sequence[str] | None = None,
        groups: Sequence[str] | None = None,
    ) -> DualHMM:
        """Learn from two-person takes ``(A, B)`` (same frames; B responds to A): Motions,
        or Markers (or Motions with ``markers=N``: virtual markers) for a marker model.

        ``labels``: the takes' interaction labels (INDEX.csv's ``label``), kept
        in ``labels_`` (sorted, distinct) so that evaluation on another index
        picks takes of the same interactions; empty if not given. ``groups``: the takes'
        pairs of people (INDEX.csv's ``subject``), which ``frame="auto"`` leaves out one at a
        time (:func:`choose_frame`); one take at a time if not given.
        """
        markers_in = self.markers or isinstance(pairs[0][0], Markers)  # pairs: checked
        if self.output == "regression" and not markers_in:
            raise SkeletonMismatchError(
                "output 'regression' generates B's markers: train on markers (C3D takes, or "
                "virtual markers placed on skeletons: markers=N, --markers N), or give "
                "--output frames (--preset new-people sets regression)"
            )
        if self.heights == "lifted" and (self.markers or not markers_in):
            note(
                "heights 'lifted' moves a C3D marker model's A: a model of skeletons or of "
                "virtual markers places B by A's own floor (nothing to lift)"
            )
        if self.place_scale == "size" and not markers_in:
            raise SkeletonMismatchError(
                "place_scale 'size' measures people by their markers: train on markers (C3D "
                "takes, or virtual markers placed on skeletons: markers=N, --markers N)"
            )
        if labels is not None and len(labels) != len(pairs):
            raise ValueError(f"{len(labels)} labels for {len(pairs)} two-person takes")
        if groups is not None and len(groups) != len(pairs):
            raise ValueError(f"{len(groups)} groups for {len(pairs)} two-person takes")
        kinds = {Markers if isinstance(x, Markers) else type(x) for pair in pairs for x in pair}
        if len(kinds) > 1 or not all(issubclass(k, (Motion, Markers)) for k in kinds):
            raise TypeError("a dual HMM learns from pairs of all Motions or all Markers")
        if self.markers:
            check_count("markers", self.markers, 1)
        elif not isinstance(pairs[0][0], Markers):
            _check_one_skeleton_b(pairs, labels)
            for i, pair in enumerate(pairs):  # features of joints: whole frames only
                for role, m in zip("AB", pair, strict=True):
                    check_motion(m, f"DualHMM.fit: take {i} ({role})", missing=False)
        for k in (
            *_LEARNT,
            *_LEARNT_MARKERS,
            *_REGRESSION,
            *_CONTACT,
            "contact_bounds_",
            "place_size_",
        ):
            self.__dict__.pop(k, None)
        if self.markers or isinstance(pairs[0][0], Markers):
            xa, xb, lengths = self._marker_features(pairs, groups)  # gaps filled
        else:
            xa, xb, lengths = self._motion_features(pairs, groups)
        self._fit_chains(xa, xb, lengths)
        if self.output == "regression":
            gamma = self.lambda_a_.predict_proba(xa, lengths)
            self.reg_means_a_, self.reg_means_b_, self.reg_gains_ = state_regressions(
                xa, xb, gamma, RIDGE
            )
        if self.contact_weight > 0:
            self._fit_contact(pairs)
        self.labels_ = sorted(set(labels or ()))
        self.record_training(flatten(pairs))
        self._trellis_cache = None
        return self

    def _fit_contact(self, pairs) -> None:
        """Learn :class:`~.contact.HandContact` from the training takes (``contact_weight``)."""
        hand = right_hand(self.compared_names())
        if hand is None:
            raise SkeletonMismatchError(
                "contact_weight needs a right hand by name (R_HAND, RightHand, right_wrist ...) "
                "among the points people are compared by"
            )
        a_pts, b_pts, yaws = [], [], []
        for a, b in pairs:
            a, b = self._rate(a), self._rate(b)
            a_pts.append(self.body_positions(a))
            b_pts.append(self.body_positions(b))
            yaws.append(self.placing(a)[1])
        found = HandContact.learn(a_pts, b_pts, yaws, hand)
        if found is None:
            self.contact_hand_ = -1
            self.contact_offset_, self.contact_coef_ = np.zeros(3), np.zeros(4)
            self.contact_bounds_ = np.zeros((4, 2))
        else:
            self.contact_hand_ = found.hand
            self.contact_offset_ = found.offset
            self.contact_coef_ = np.r_[found.coef, found.intercept]
            self.contact_bounds_ = np.asarray(found.bounds, float)

    @property
    def contact(self) -> HandContact | None:
        """What the model learnt of the hands' contact (``contact_weight`` above 0 and
        contact in the training takes), else None."""
        if not self.contact_weight or getattr(self, "contact_hand_", -1) < 0:
            return None
        coef = np.asarray(self.contact_coef_, dtype=float)
        bounds = getattr(self, "contact_bounds_", None)  # None: saved before they were learnt
        return HandContact(
            int(self.contact_hand_), np.asarray(self.contact_offset_, float), coef[:3], coef[3],
            None if bounds is None else np.asarray(bounds, float),
        )  # fmt: skip

    def compared_names(self) -> list[str]:
        """Names of the points people are compared by (:meth:`body_positions`)."""
        if self.uses_markers:
            return list(self.marker_names_b_)
        return list(BODY_POINTS) if self.points == "body" else list(self.skeleton_b_.names)

    def _motion_features(
        self, pairs: Sequence[tuple[Motion, Motion]], groups: Sequence[str] | None = None
    ) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """A's and B's features of skeleton takes (module docstring, "Features"); sets the
        pipelines, skeletons and B's frames as exponential maps."""
        a_list, b_rel = [], []
        for a, b in pairs:
            if not isinstance(a, Motion) or not isinstance(b, Motion):
                raise TypeError("a dual HMM learns from pairs of all Motions or all Markers")
            a_list.append(self._rate(a))
            b_rel.append(self._rate(b))
        points = BODY_POINTS if self.points == "body" else None
        grounds = [ground_frame(a) for a in a_list]

        def b_in(frame: str) -> list[np.ndarray]:
            where = []
            for b, (origin, yaw) in zip(b_rel, grounds, strict=True):
                rel = into_frame(b, origin, yaw if frame == "heading" else np.zeros_like(yaw))
                where.append(self.body_positions(rel))
            return where

        self.frame_ = self.frame if self.frame != "auto" else choose_frame(b_in, groups)
        turn = self.frame_ == "heading"
        b_rel = [
            into_frame(b, *self._training_place((origin, yaw if turn else np.zeros_like(yaw))))
            for b, (origin, yaw) in zip(b_rel, grounds, strict=True)
        ]
        self.skeleton_a_ = a_list[0].skeleton
        self.skeleton_b_ = b_rel[0].skeleton
        first = (
            BodyMotion(points=points, turn=turn)
            if self.observation == "motion"
            else JointPositions(points=points, turn=turn)
        )
        self.pipeline_a_ = FeaturePipeline([first, PCA(self.energy), *self._centring()])
        self.pipeline_b_ = FeaturePipeline(
            [JointPositions(body_centred=False, points=points), PCA(self.energy)]
        )
        self.expmaps_b_ = ExpMaps(root_position="full")
        xa, lengths = check_sequences(
            np.vstack(self.pipeline_a_.fit_transform(a_list)), [len(m) for m in a_list]
        )
        xb = np.vstack(self.pipeline_b_.fit_transform(b_rel))
        self.frames_b_ = np.vstack(self.expmaps_b_.fit_transform(b_rel)).astype(np.float32)
        return xa, xb, lengths

    def _marker_features(
        self,
        pairs: Sequence[tuple[Motion | Markers, Motion | Markers]],
        groups: Sequence[str] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """A's and B's features of marker takes (module docstring, "Markers"): A's markers
        about A's own ground frame, B's in A's; sets the pipelines and ``markers_b_``."""
        seen = seen_in_every(
            [self._rate(self.as_markers(m)) for pair in pairs for m in pair]
        )  # A and B of every take keep the same markers (both roles, the person's body)
        a_list = [fill_gaps(m) for m in seen[0::2]]
        b_list = [fill_gaps(m) for m in seen[1::2]]
        first = MarkerFeatures(motion=self.observation == "motion").fit(a_list)
        grounds = [first.place(first.select(a).positions) for a in a_list]

        def b_in(frame: str) -> list[np.ndarray]:
            return [
                into_marker_frame(b, o, y if frame == "heading" else 0 * y).positions
                for b, (o, y) in zip(b_list, grounds, strict=True)
            ]

        self.frame_ = self.frame if self.frame != "auto" else choose_frame(b_in, groups)
        first.turn = self.frame_ == "heading"
        b_rel = []
        for a, b in zip(a_list, b_list, strict=True):
            b_rel.append(
                into_marker_frame(b, *self._training_place(first.place(first.select(a).positions)))
            )
        if self.place_scale == "size":
            b_rel = self._fit_place_size(first, a_list, b_list, b_rel)
        if self.normalise == "person":  # averaged marker by marker: by name, not position
            b_rel = [b.select(b_rel[0].names) for b in b_rel]
            moved = on_average_body([b.positions for b in b_rel])
            b_rel = [Markers(b.names, p, b.fps, b.name) for b, p in zip(b_rel, moved, strict=True)]
        self.pipeline_a_ = FeaturePipeline([first, PCA(self.energy), *self._centring()])
        self.pipeline_b_ = FeaturePipeline([MarkerFeatures(body_centred=False), PCA(self.energy)])
        xa, lengths = check_sequences(
            np.vstack(self.pipeline_a_.fit_transform(a_list)), [len(m) for m in a_list]
        )
        xb = np.vstack(self.pipeline_b_.fit_transform(b_rel))
        names = self.pipeline_b_.steps[0].names_
        self.marker_names_b_ = list(names)
        self.markers_b_ = np.concatenate([b.select(names).positions for b in b_rel])
        self.markers_b_ = self.markers_b_.astype(np.float32)
        return xa, xb, lengths

    def _fit_place_size(
        self, first: MarkerFeatures, a_list: list, b_list: list, b_rel: list
    ) -> list[Markers]:
        """``place_scale="size"``: learn ``place_size_`` and take each training take's B
        place to the average pair's (the parameter's docstring)."""
        radii = []
        for a, b in zip(a_list, b_list, strict=True):
            try:
                radii.append(
                    [float(np.mean(body_radius(first.select(x).positions))) for x in (a, b)]
                )
            except SkeletonMismatchError as err:
                raise SkeletonMismatchError(
                    f"place_scale 'size' measures A and B by the same markers: {err}"
                ) from None
        radii = np.asarray(radii)
        self.place_size_ = float(radii.mean())
        out = []
        for b, (ra, rb) in zip(b_rel, radii, strict=True):
            centre = b.positions.mean(axis=1, keepdims=True)
            moved = self.scaled_root(centre, 2.0 * self.place_size_ / (ra + rb)) - centre
            out.append(Markers(b.names, b.positions + moved, b.fps, b.name))
        return out

    def place_scales(self, motion_a: Markers, missing: np.ndarray, lag: int) -> np.ndarray | None:
        """(F,) ``place_scale="size"``: the scale of B's place for each of B's frames, from A's
        markers (``motion_a``, the model's, at its rate) seen up to the frame ``lag`` frames
        later (the windowed partner's: what it has seen when it shows the frame); None for
        ``place_scale="none"``."""
        if getattr(self, "place_scale", "none") != "size":
            return None
        radius = body_radius(self.input_markers(motion_a).positions)
        scale = size_scale(radius, ~missing & np.isfinite(radius), self.place_size_)
        return scale[np.minimum(np.arange(len(scale)) + lag, len(scale) - 1)]

    @staticmethod
    def scaled_root(root: np.ndarray, scale: np.ndarray | float | None) -> np.ndarray:
        """B's root(s) (..., 3) in A's ground frame with the horizontal offset from A scaled."""
        if scale is None:
            return root
        root = np.array(root, dtype=float)
        root[..., GROUND] *= np.asarray(scale, dtype=float)[..., None]
        return root

    def _training_place(
        self, place: tuple[np.ndarray, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """A's ground frame in a training take as B's place is learnt in it: per frame (the
        paper's), or with ``place_memory`` averaged as the live partner averages it."""
        return self.smoothed(*place) if self.place_memory else place

    def _centring(self) -> list[RunningCentre]:
        """The last step of A's pipeline with ``normalise="person"``: A's running mean out."""
        return [RunningCentre()] if self.normalise == "person" else []

    def _fit_chains(self, xa: np.ndarray, xb: np.ndarray, lengths: list[int]) -> None:
        """lambda_A and lambda_B (eqs. 1-2) from A's and B's training features (``mode``)."""
        self.train_a_, self.train_b_ = xa, xb
        self.train_lengths_ = np.asarray(lengths, dtype=np.int64)
        kind = check_covariance_type(self.covariance_type)
        hmm = GaussianHMM(
            n_components=self.n_states,
            covariance_type=kind,
            n_iter=self.n_iter,
            tol=self.tol,
            var_floor=self.var_floor,
            random_state=self.random_state,
            n_jobs=self.n_jobs,
        )
        da = xa.shape[1]
        if self.mode == "paper":
            self.lambda_a_ = hmm.fit(xa, lengths)
            hmm.transmat_ = leavable(hmm.transmat_)
            gamma = hmm.predict_proba(xa, lengths)
            floor = covariance_floor(xb, hmm.min_covar, self.var_floor)
            means_b, covars_b, _ = gaussian_m_step(xb, gamma, kind)
            covars_b = floor_covariances(covars_b, floor, kind)
            self.lambda_b_ = _sharing_chain(hmm, means_b, covars_b, floor)
            self.train_states_ = hmm.decode(xa, lengths)[1]
        else:
            xab = np.hstack([xa, xb])
            joint = hmm.fit(xab, lengths)
            joint.transmat_ = leavable(joint.transmat_)
            self.train_states_ = joint.decode(xab, lengths)[1]
            m, c, floor = joint.means_, joint.covars_, joint.covar_floor_
            for name, part in (("lambda_a_", slice(None, da)), ("lambda_b_", slice(da, None))):
                compact = compact_of_full(c[:, part, part], kind)
                setattr(self, name, _sharing_chain(joint, m[:, part], compact, floor[part]))
        self.history_ = hmm.history_

    @property
    def uses_markers(self) -> bool:
        """Whether the fitted model sees people as markers (and answers with Markers)."""
        return hasattr(self, "markers_b_")

    def as_markers(self, x: Motion | Markers) -> Markers:
        """``x`` as markers: Markers as they are, a Motion with ``markers`` virtual markers
        placed on it (:func:`~markovmotion.features.markers.virtual_markers`).

        Raises:
            SkeletonMismatchError: a Motion and no virtual markers (a model learnt from
                C3D markers), or a skeleton without the body points they need.
        """
        if isinstance(x, Markers):
            return x
        if not self.markers:
            return named_body_points(x, self.pipeline_a_.steps[0].names_)
        return virtual_markers(x, int(self.markers))

    def lifts(self, x: Motion | Markers) -> bool:
        """Whether A's points are lifted to the training people's height (:meth:`lift`): a
        skeleton given to a model learnt from C3D markers, whose vertical origin is the
        sensor's, not the floor; with ``heights="lifted"`` markers too."""
        if not self.uses_markers or self.markers:
            return False
        return isinstance(x, Motion) or getattr(self, "heights", "capture") == "lifted"

    def height_note(self, a: Markers) -> None:
        """A note when marker A (the model's markers, not lifted) stands further than
        :data:`HEIGHT_NOTE_MM` above or below the training people (``heights`` says why)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames with nothing seen
            off = float(np.nanmean(a.positions[..., 1])) - self.lift().height
        if abs(off) > HEIGHT_NOTE_MM:  # once a command (respond per method, per take)
            say(
                [
                    "note: A's markers stand more than "
                    f"{HEIGHT_NOTE_MM:.0f} mm above or below the training people's (another "
                    "vertical origin?): B is placed at the training capture's heights; train "
                    "with --heights lifted to place B by A's height"
                ],
                about=id(self),
            )

    def lift(self) -> Lift:
        """:class:`~markovmotion.features.markers.Lift` to the training people's mean
        centroid height (B's training markers, A's too with ``roles="both"``)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return Lift(float(np.nanmean(np.nanmean(self.markers_b_[..., 1], axis=1))))

    def a_in(self, x: Motion | Markers) -> tuple[Motion | Markers, np.ndarray | None]:
        """A as the model sees it, at the model's rate: a Motion, or on markers A's Markers
        (virtual or body points by name on a skeleton, :meth:`as_markers`), lifted when
        :meth:`lifts`; and the lift per frame (None when not lifted), by which B's answer
        goes down again."""
        lifting = self.lifts(x)
        if self.uses_markers:
            x = self.held()(self._rate(self.input_markers(x)))
        else:
            x = self._rate(x)
        if not lifting:
            return x, None
        return self.lift()(x)

    def held(self) -> HeldMarkers:
        """:class:`~markovmotion.features.markers.HeldMarkers` for A's markers: one unseen
        for at most :data:`~markovmotion.features.markers.HOLD_SECONDS` is held where the
        others say it is, so that its frame is not a missing observation."""
        return HeldMarkers(round(HOLD_SECONDS * float(self.fps)))

    def check_state(self) -> None:
        """The learnt parts a model file must hold, and that they fit each other: both
        chains of n_states states, T training frames in train_a_, train_b_, frames_b_ and
        train_states_ (states in range), feature widths those of the pipelines and chains,
        frames_b_ the width ExpMaps gives skeleton_b_; on markers, markers_b_ (T, M, 3) with
        M the marker_names_b_ the B pipeline's markers, A's marker features those given."""
        if not is_fitted(self):
            return
        if getattr(self, "frame_", "heading") not in ("heading", "world"):
            raise StateError(f"frame_: must be heading or world, got {self.frame_!r}")
        on_markers = hasattr(self, "markers_b_")
        if on_markers:
            require(self, *_LEARNT_MARKERS)
            types = {k: v for k, v in _LEARNT_TYPES.items() if k in _LEARNT_MARKERS}
            require_types(self, **types)
        else:
            require(self, *_LEARNT)
            require_types(self, **_LEARNT_TYPES)
        n = self.n_states
        t = len(check_shape("train_states_", self.train_states_, (None,)))
        check_index("train_states_", self.train_states_, n)
        for side in ("a", "b"):
            chain = getattr(self, f"lambda_{side}_")
            if chain.n_components != n:
                raise StateError(f"lambda_{side}_: {chain.n_components} states, n_states is {n}")
            width = chain.means_.shape[1]
            check_shape(f"train_{side}_", getattr(self, f"train_{side}_"), (t, width))
            out = getattr(self, f"pipeline_{side}_").output_width()
            if out is not None and out != width:
                raise StateError(f"pipeline_{side}_: gives {out} features, lambda_{side}_ {width}")
        if getattr(self, "output", "frames") == "regression":
            require(self, *_REGRESSION)
            da, db = self.lambda_a_.means_.shape[1], self.lambda_b_.means_.shape[1]
            check_shape("reg_means_a_", self.reg_means_a_, (n, da))
            check_shape("reg_means_b_", self.reg_means_b_, (n, db))
            check_shape("reg_gains_", self.reg_gains_, (n, db, da))
        if getattr(self, "contact_weight", 0):
            require(self, *_CONTACT)
            check_shape("contact_offset_", self.contact_offset_, (3,))
            check_shape("contact_coef_", self.contact_coef_, (4,))
            if getattr(self, "contact_bounds_", None) is not None:
                check_shape("contact_bounds_", self.contact_bounds_, (4, 2))
            hand = self.contact_hand_
            if not isinstance(hand, int | np.integer) or not -1 <= hand < len(
                self.compared_names()
            ):
                raise StateError(f"contact_hand_: not a point's index, got {hand!r}")
        if getattr(self, "place_scale", "none") == "size":
            require(self, "place_size_")
            size = self.place_size_
            if not (isinstance(size, int | float | np.number) and 0.0 < float(size) < 1e6):
                raise StateError(f"place_size_: must be a size in mm above 0, got {size!r}")
        if on_markers:
            self._check_marker_state(t)
            return
        check_shape("frames_b_", self.frames_b_, (t, self.expmaps_b_.output_width()))
        if self.expmaps_b_.skeleton_.n_joints != self.skeleton_b_.n_joints:
            raise StateError("expmaps_b_: its skeleton is not skeleton_b_")

    def _check_marker_state(self, frames: int) -> None:
        """A marker model's own parts: B's markers and names, the pipelines' first steps."""
        names = self.marker_names_b_
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise StateError("marker_names_b_: expected a list of marker names")
        check_shape("markers_b_", self.markers_b_, (frames, len(names), 3))
        for side in ("a", "b"):
            first = getattr(self, f"pipeline_{side}_").steps[0]
            if not isinstance(first, MarkerFeatures) or not is_fitted(first):
                raise StateError(f"pipeline_{side}_: does not start with fitted MarkerFeatures")
        if self.pipeline_b_.steps[0].names_ != names:
            raise StateError("marker_names_b_: not the markers of pipeline_b_")

    def _rate(self, motion: Motion | Markers) -> Motion | Markers:
        return motion if np.isclose(motion.fps, self.fps) else motion.resample(self.fps)

    # ---------------------------------------------------------------- responding
    def check_input(
        self, motion: Motion | Markers, source: str | os.PathLike[str] | None = None
    ) -> None:
        """Raise :class:`SkeletonMismatchError` (naming ``source``) unless A's skeleton has
        the body points the model sees (by joint names; any skeleton that has them), or,
        for a model that sees every joint (files of older versions), is the model's. On
        markers: unless A's markers (or the virtual ones placed on A's skeleton) include
        those the model learnt, by name; Markers given to a skeleton model never fit."""
        if self.uses_markers or isinstance(motion, Markers):
            self._check_markers(motion, source)
            return
        points = getattr(self.pipeline_a_.steps[0], "points", None)
        try:
            if points is None:
                self.skeleton_a_.check_compatible(motion.skeleton, "input")
            else:
                body_point_index(motion.skeleton, points, "its skeleton")
        except SkeletonMismatchError as exc:
            where = source or motion.name or "input motion"
            raise SkeletonMismatchError(
                f"{where}: person A's skeleton does not fit the model ({exc})", exc.reason
            ) from None

    def check_partner(
        self, motion: Motion | Markers, source: str | os.PathLike[str] | None = None
    ) -> None:
        """Raise :class:`SkeletonMismatchError` (naming ``source``) unless person B of a test
        take can be compared with what the model generates (:meth:`body_positions`): on
        markers, B's markers (or the virtual ones placed on B's skeleton) include the
        model's B markers, by name; on skeletons, B's skeleton has the body points (a model
        that compares every joint: B's skeleton is the model's)."""
        try:
            if self.uses_markers:
                self.as_markers(motion).select(self.marker_names_b_)
            elif isinstance(motion, Markers):
                raise SkeletonMismatchError("markers, but the model generates a skeleton")
            elif self.points == "all":
                self.skeleton_b_.check_compatible(motion.skeleton, "partner")
            else:
                body_point_index(motion.skeleton, BODY_POINTS, "its skeleton")
        except (KeyError, ValueError, SkeletonMismatchError) as exc:
            reason = getattr(exc, "reason", None) or (exc.args[0] if exc.args else str(exc))
            where = source or motion.name or "partner"
            raise SkeletonMismatchError(
                f"{where}: person B does not fit the model ({reason})", reason
            ) from None

    def _check_markers(self, x: Motion | Markers, source: str | os.PathLike[str] | None) -> None:
        where = source or x.name or "input"
        if not self.uses_markers:
            raise SkeletonMismatchError(
                f"{where}: markers, but the model was trained on skeletons (give a BVH file)"
            )
        try:
            picked = self.pipeline_a_.steps[0].select(self.as_markers(x))
            if never := picked.never_seen():  # a frame with one unseen is missing: all are
                raise SkeletonMismatchError(never)
            seen = picked.visible()
            if len(seen) and not seen.all(axis=1).any():
                hold = HeldMarkers(round(HOLD_SECONDS * picked.fps))  # as a_in holds them
                if not hold(picked).visible().all(axis=1).any():
                    raise SkeletonMismatchError(
                        f"no frame shows all {seen.shape[1]} of the model's markers, even "
                        f"with those unseen for at most {HOLD_SECONDS:g} s held (a frame "
                        "with one unseen is a missing observation)"
                    )
        except (ValueError, SkeletonMismatchError) as exc:
            raise SkeletonMismatchError(
                f"{where}: person A's markers do not fit the model ({exc})",
                getattr(exc, "reason", str(exc)),
            ) from None

    def input_markers(self, x: Motion | Markers) -> Markers:
        """A's markers the model sees, in its order (virtual ones placed on a Motion)."""
        return self.pipeline_a_.steps[0].select(self.as_markers(x))

    def place(self, x: Motion | Markers) -> tuple[np.ndarray, np.ndarray]:
        """A's ground frame per frame, origin (F, 3) and heading (F,), as the model places
        B through it: from A's markers on a marker model, else A's skeleton."""
        if self.uses_markers:
            first = self.pipeline_a_.steps[0]
            return first.place(self.input_markers(x).positions)
        return self.ground(x)

    @staticmethod
    def filled(motion: Motion | Markers) -> Motion | Markers:
        """``motion`` with its frames that have a point unseen (NaN) filled as :meth:`respond`
        fills A's (the last seen frame held): what B is placed through there."""
        return _fill_missing(motion, ~finite_frames(motion))

    def placing(
        self,
        x: Motion | Markers,
        method: str = "windowed",
        lift: np.ndarray | None = None,
        seen: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A's ground frame as B is placed through it by :meth:`respond` (``method``): per
        frame :meth:`place` of ``x`` (A's missing frames filled, :meth:`filled`), brought
        down by ``lift`` (A lifted by :meth:`a_in`: B goes down as much), averaged by
        :meth:`smoothed` over the frames ``seen`` (F,) (None: all)."""
        origin, yaw = self.place(x)
        if lift is not None:
            origin[:, 1] -= lift
        return self.smoothed(origin, yaw, method, seen)

    def smoothed(
        self,
        origin: np.ndarray,
        yaw: np.ndarray,
        method: str = "windowed",
        seen: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A's ground frame (origin (F, 3), yaw (F,)) averaged over ``place_memory`` frames
        before (at least ``placement_window // 2``) and ``placement_window // 2`` after each
        frame (online, ``method="windowed"``, at most the decoder's lag after), those where
        A was ``seen`` alone: :func:`~markovmotion.models.hmm.trellis.smooth_place`."""
        half = self.placement_window // 2
        if method != "standard":
            half = min(half, self.window - 1)
        return smooth_place(origin, yaw, half, max(half, int(self.place_memory)), seen)

    def ground(
        self, motion: Motion, positions: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """A's ground frame (origin (F, 3), heading (F,)) as the model places B: A's own
        facing, or with ``frame_ == "world"`` the world's axes (heading 0) at A's place."""
        origin, yaw = ground_frame(motion, positions)
        if getattr(self, "frame_", "heading") == "world":
            yaw = np.zeros_like(yaw)
        return origin, yaw

    def training_b(self) -> Motion | Markers:
        """B's training frames in A's ground frame, as the model outputs them."""
        if self.uses_markers:
            return Markers(self.marker_names_b_, self.markers_b_.astype(float), self.fps, "B")
        return self.expmaps_b_.inverse_transform([self.frames_b_.astype(float)])[0]

    def body_positions(
        self,
        motion: Motion | Markers,
        body_centred: bool = False,
        positions: np.ndarray | None = None,
    ) -> np.ndarray:
        """(F, P, 3) the positions (mm) people are compared by: the body points (world or
        body-centred), or every joint with ``points="all"``. A marker model compares B's
        markers (a Motion gets its virtual markers), world or about their own ground frame.
        ``positions``: a Motion's world joint positions, if already computed (not used for
        body-centred positions nor on markers)."""
        if self.uses_markers:
            markers = self.as_markers(motion).select(self.marker_names_b_)
            step = MarkerFeatures(body_centred=body_centred).fit([markers])
            return step.pose(markers)
        if body_centred:
            positions = None
        if self.points == "all":
            if positions is not None:
                return positions
            return motion.body_centred_positions() if body_centred else motion.positions()
        return body_points(motion, BODY_POINTS, body_centred=body_centred, positions=positions)

    def features_a(self, motion: Motion | Markers) -> tuple[np.ndarray, np.ndarray]:
        """A's model features (F, Da) at the model's rate and which frames are missing (NaN;
        on markers, a frame with any of the model's markers unseen)."""
        if self.uses_markers:
            motion = self.input_markers(motion)
        missing = ~finite_frames(motion)
        data = [_fill_missing(motion, missing)]
        for step in self.pipeline_a_.steps:
            if isinstance(step, RunningCentre):  # a missing frame, filled, is not in A's mean
                data = [step.centre(data[0], ~missing)]
            else:
                data = step.transform(data)
        return data[0], missing

    def score(self, motion_a: Motion) -> float:
        """log P(A's features | lambda_A): how well the model knows person A's motion.

        The forward algorithm over A's frames at the model's rate; a frame with
        NaN values is a missing observation (emission probability 1), as in
        :meth:`respond`.
        """
        self.check_input(motion_a)
        xa, missing = self.features_a(self.a_in(motion_a)[0])
        log_b = self.lambda_a_.log_frameprob(xa)
        log_b[missing] = 0.0
        hmm = self.lambda_a_
        return float(forward_backward(safe_log(hmm.startprob_), hmm.transmat_, log_b)[0])

    def respond(self, motion_a: Motion | Markers, method: str = "standard") -> Motion | Markers:
        """B's responsive motion to the whole of ``motion_a`` (at the model's rate, in A's world).

        ``method="standard"``: Viterbi over all of A, lowest-error trellis path.
        ``method="windowed"``: exactly what :meth:`partner` streams, frame by frame.
        Frames of A with NaN values count as missing observations. A model trained on
        markers takes A's Markers (or a Motion: virtual markers placed first) and returns
        B's Markers.
        """
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.check_input(motion_a)
        motion_a, lift = self.a_in(motion_a)
        if lift is None and self.uses_markers and not self.markers:
            self.height_note(motion_a)
        xa, missing = self.features_a(motion_a)
        log_b = self.lambda_a_.log_frameprob(xa)
        log_b[missing] = 0.0
        trellis = self._trellis()
        seen = [None if m else x for x, m in zip(xa, missing, strict=True)]
        if method == "standard" and self.output == "regression":
            rel = self.regression_positions(self.decode(log_b), seen)
            root, rot = blend_positions(rel, np.arange(len(rel)), self.blend_window // 2)
            idx = np.zeros(len(rel), dtype=int)
        elif method == "standard":
            states = self.decode(log_b)
            idx = trellis.best_path(states, trellis.columns(states, seen))
            root = trellis.placement(idx, self.placement_window // 2)
            rot = trellis.blend(idx, self.blend_window // 2)
        else:
            partner = self.partner()
            frames = track(zip(log_b, seen, strict=True), "answering A's frames", len(log_b))
            chosen = [partner.step_log_frameprob(row, x) for row, x in frames]
            chosen = [c for c in chosen if c is not None] + partner.finish_frames()
            idx = np.array([c[0] for c in chosen], dtype=int)
            root = np.array([c[1] for c in chosen])
            rot = np.array([c[2] for c in chosen])
        filled = _fill_missing(motion_a, missing)
        lag = self.window - 1 if method == "windowed" else 0
        root = self.scaled_root(root, self.place_scales(motion_a, missing, lag))
        placed = self.placing(filled, method, lift, ~missing)
        out = self.frames_to_motion(idx, *placed, root, rot)
        contact = self.contact
        if contact is None:
            return out
        a = self.body_positions(filled)
        shifts = contact.shifts(a, placed[1], self.body_positions(out))
        shifts[missing] = np.nan  # no evidence where A was not seen (as online)
        return self.moved(out, contact_shifts(shifts, self.contact_weight, self.contact_memory))

    @property
    def contact_memory(self) -> int | None:
        """Frames over which the contact's shifts are averaged: ``place_memory`` (all: 0)."""
        return int(self.place_memory) or None

    @staticmethod
    def moved(b: Motion | Markers, shift: np.ndarray) -> Motion | Markers:
        """B moved by ``shift`` (F, 3) mm, in place: a Markers' positions, a Motion's root."""
        if isinstance(b, Markers):
            b.positions[...] = b.positions + shift[:, None]
        else:
            b.translations[:, 0] += shift
        return b

    def regression_positions(
        self, states: Sequence[int], xa: Sequence[np.ndarray | None]
    ) -> np.ndarray:
        """(F, M, 3) B's markers in A's ground frame by ``output="regression"``: per frame the
        conditional mean of B's features given A's under the frame's state (the state's mean
        where A's frame is missing), :func:`state_regressions`, back through B's PCA."""
        q = np.asarray(states, dtype=int)
        xb = self.reg_means_b_[q].copy()
        for t, x in enumerate(xa):
            if x is not None:
                xb[t] += self.reg_gains_[q[t]] @ (x - self.reg_means_a_[q[t]])
        return np.asarray(self.pipeline_b_.inverse_transform([xb])[0], dtype=float)

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
        rotations: np.ndarray | None = None,
    ) -> Motion | Markers:
        """B's training frames ``idx`` as a Motion placed by A's ground frame (origin, yaw);
        ``root`` (F, 3): B's root positions in A's ground frame instead of the frames' own;
        ``rotations`` (F, J, 4): B's joint rotations instead (blended, :meth:`Trellis.blend`).
        On markers, Markers: ``root`` B's marker centroid, ``rotations`` B's markers about
        it (F, M, 3) (:meth:`Trellis.blend`)."""
        frames = self._trellis().motion_b
        if isinstance(frames, Markers):
            rel = frames.positions[idx]
            if rotations is not None:
                rel = np.asarray(rotations, dtype=float) + rel.mean(axis=1, keepdims=True)
            if root is not None:
                rel = rel - rel.mean(axis=1, keepdims=True) + np.asarray(root)[:, None]
            world = out_of_marker_frame(rel, origin, yaw)
            return Markers(frames.names, world, self.fps, "B")
        # out_of_frame written out on the frames' arrays (one Motion made, not three: online
        # this runs once per frame)
        rot = frames.rotations[idx] if rotations is None else np.array(rotations, dtype=float)
        trans = frames.translations[idx]
        if root is not None:
            trans[:, 0] = root
        rot[:, 0], trans[:, 0] = _turn_root(rot[:, 0], trans[:, 0], yaw)
        trans[:, 0] += origin
        return Motion(self.skeleton_b_, rot, trans, self.fps)

    def partner(self, window: int | None = None) -> Partner:
        """An online virtual partner (windowed Viterbi; ``window`` defaults to the model's):
        an :class:`~markovmotion.models.online.OnlinePartner`."""
        return Partner(self, window or self.window)

    def _trellis(self) -> Trellis:
        """The §3.2 trellis over the training frames (:mod:`.trellis`), built once."""
        cache = getattr(self, "_trellis_cache", None)
        if cache is not None:
            cache.kind = self.trellis  # a hyper-parameter, set_params may change it
            return cache
        prec_a, _ = precision_cholesky(self.lambda_a_.covars_)
        prec_b, _ = precision_cholesky(self.lambda_b_.covars_)
        motion_b = self.training_b()
        self._trellis_cache = build_trellis(
            self.train_a_,
            self.train_b_,
            self.train_states_,
            self.lambda_a_.means_,
            prec_a,
            prec_b,
            self.candidates,
            motion_b,
            successors(getattr(self, "train_lengths_", [len(self.train_a_)])),
            self.trellis,
        )
        return self._trellis_cache


def choose_frame(
    b_in: Callable[[str], list[np.ndarray]], groups: Sequence[str] | None = None
) -> str:
    """``"heading"`` or ``"world"``: the frame of A in which B's place is better told by the
    other training takes, by cross-validation on the training takes alone.

    ``b_in(frame)``: B's training positions per take ((frames, points, 3), NaN for unseen
    markers). Each take (with ``groups``, e.g. the takes' pairs of people, each group when
    there are two or more) is predicted by the mean of the others' positions, as the
    mean-pose baseline would be on a new take; the frame with the lower mean error wins.
    A room's axes fit takes from one room and one pair of people (CMU 18/19's pulls); A's
    facing fits new people placed anywhere by the sensor (Bütepage's pairs). One take:
    the frame in which its positions lie closer to their mean."""
    error = {}
    for frame in ("heading", "world"):
        takes = b_in(frame)
        keys = list(groups) if groups is not None else [str(i) for i in range(len(takes))]
        if len(set(keys)) < 2:
            keys = [str(i) for i in range(len(takes))]
        if len(takes) < 2:
            where = takes[0]
            error[frame] = float(
                np.nanmean(np.linalg.norm(where - np.nanmean(where, axis=0), axis=-1))
            )
            continue
        total, count = 0.0, 0
        for key in dict.fromkeys(keys):
            inside = [t for t, k in zip(takes, keys, strict=True) if k == key]
            others = np.concatenate([t for t, k in zip(takes, keys, strict=True) if k != key])
            mean = np.nanmean(others, axis=0)
            for t in inside:
                d = np.linalg.norm(t - mean, axis=-1)
                total += float(np.nansum(d))
                count += int(np.isfinite(d).sum())
        error[frame] = total / max(count, 1)
    return min(error, key=error.get)


def _check_one_skeleton_b(
    pairs: Sequence[tuple[Motion, Motion]], labels: Sequence[str] | None
) -> None:
    """Raise :class:`SkeletonMismatchError` naming the groups (by label, else by take)
    unless person B has one skeleton in every take: B's output frames are B's own
    training frames, so they must share one skeleton (A may vary: body points)."""
    groups: dict[int, tuple[Skeleton, list[str]]] = {}
    for i, (_, b) in enumerate(pairs):
        name = labels[i] if labels is not None else (b.name or f"take {i}")
        for sk, names in groups.values():
            if sk.same_topology(b.skeleton):
                if name not in names:
                    names.append(name)
                break
        else:
            groups[len(groups)] = (b.skeleton, [name])
    if len(groups) > 1:
        detail = "; ".join(
            f"{sk.n_joints} joints ({sk.names[0]} ...): {', '.join(names)}"
            for sk, names in groups.values()
        )
        raise SkeletonMismatchError(
            f"person B comes on {len(groups)} skeletons ({detail}); B's output frames are "
            "B's training frames, so train on takes of one of them (--labels)"
        )


def _sharing_chain(
    hmm: GaussianHMM, means: np.ndarray, covars: np.ndarray, floor: np.ndarray
) -> GaussianHMM:
    """lambda = (T, B, pi) with ``hmm``'s pi and T and the Gaussians given (eqs. 1-2; the
    covariances in ``hmm.covariance_type``'s compact form)."""
    out = GaussianHMM(**hmm.get_params())
    out.startprob_, out.transmat_ = hmm.startprob_, hmm.transmat_
    out.means_, out.covars_, out.covar_floor_ = means, covars, floor
    out.n_features_in_ = means.shape[1]
    out.history_, out.n_iter_, out.converged_ = hmm.history_, hmm.n_iter_, hmm.converged_
    return out


def _fill_missing(motion: Motion | Markers, missing: np.ndarray) -> Motion | Markers:
    """Missing frames replaced by the last finite one (the first finite one before it; the
    rest pose if none is finite; markers at the origin): A's place for the B frames shown
    then, and no jump in A's motion features."""
    if not missing.any():
        return motion
    out = motion.copy()
    if isinstance(motion, Markers):
        keep = _last_finite(missing)
        out.positions = np.zeros_like(motion.positions) if keep is None else motion.positions[keep]
        return out
    if missing.all():
        out.rotations[:] = [0.0, 0.0, 0.0, 1.0]
        out.translations[:] = motion.skeleton.offsets
        return out
    keep = _last_finite(missing)
    out.rotations, out.translations = motion.rotations[keep], motion.translations[keep]
    return out


def _last_finite(missing: np.ndarray) -> np.ndarray | None:
    """Per frame, the last frame up to it that is not ``missing`` (the first such frame for
    those before it); None if every frame is missing."""
    if missing.all():
        return None
    keep = np.maximum.accumulate(np.where(missing, 0, np.arange(len(missing))))
    keep[: int(np.argmin(missing))] = int(np.argmin(missing))
    return keep

"""Behaviour models over prototypes: a VLMM of prototype sequences (VLMM paper §2, §3.2).

Motion becomes augmented configuration vectors F = [C, lambda dC] in [0, 1]
(eqs. 1-4), each replaced by its nearest prototype with repeats collapsed
(eq. 3); a :class:`~markovmotion.models.vlmm.prediction_suffix_tree.VLMM` learns the prototype
sequences. Generation traverses the automaton and joins the emitted
prototypes' configurations by cubic Hermite interpolation with the time
intervals of eq. 8, sampled at the frame rate; prediction first recognises
the state from the observed prototypes (§3.2.2).

Configuration C is the joint rotations (exponential maps of the moving
joints plus the pelvis height, with each frame's heading removed),
body-centred joint positions, or the paper's 13 markers (§2.1.2: head,
shoulders, elbows, wrists, hips, knees, ankles, found on any skeleton by
joint names, :mod:`markovmotion.features.body_points`), object-centred; each
component is scaled to [0, 1] (eq. 4). Generated rotations or positions go
back to a :class:`Motion` (rotations directly, positions through an
inverse-kinematics fit to the training skeleton); markers come out as
:class:`~markovmotion.core.markers.Markers` (written as C3D or a point-light
animation). ``configuration="contour"`` learns from arrays instead of motions:
the paper's data set 1 (§2.1.1), a silhouette's closed B-spline control points
relative to its head reference point, (F, 2n) in [0, 1] per frame
(:func:`markovmotion.video.contours.contour_configurations`); generation and
prediction then return such arrays.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from markovmotion.algorithms.hermite import constant_acceleration_intervals, hermite_sample
from markovmotion.algorithms.kinematics import fit_rotations, rotvec_positions
from markovmotion.algorithms.vector_quantisation import (
    collapse_repeats,
    competitive_learning,
    kmeans_prototypes,
    nearest_prototype,
)
from markovmotion.core.frames import check_frames, is_sparse
from markovmotion.core.markers import Markers, find_markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import choose_kind, largest_group, same_set
from markovmotion.errors import DataNotFoundError, SkeletonMismatchError
from markovmotion.features import AugmentedConfiguration, ExpMaps, FeaturePipeline, JointPositions
from markovmotion.features.body_points import MARKER_POINTS, body_point_index
from markovmotion.features.heading import RemoveHeading
from markovmotion.features.markers import MarkerFeatures, fill_gaps, seen_in_every
from markovmotion.features.select import DropStaticColumns
from markovmotion.limits import MAX_FRAMES, check_length
from markovmotion.models.base import Model
from markovmotion.models.vlmm.prediction_suffix_tree import VLMM
from markovmotion.state import (
    StateError,
    check_index,
    check_lengths,
    check_shape,
    is_fitted,
    require,
    require_types,
)

CONFIGURATIONS = ("rotations", "positions", "markers", "contour")
QUANTISERS = ("kmeans", "competitive")


# ------------------------------------------------------------------- data
def load_motions(
    index: MocapIndex, entries: Sequence[Entry], fps: float
) -> tuple[list[Motion | Markers], list[Entry]]:
    """The entries' motions (C3D files: their markers, gaps filled) at ``fps``, keeping the
    largest group sharing one skeleton (or one set of marker names,
    :func:`~markovmotion.data.kinds.largest_group`, which says what it left out).

    Returns the motions and the entries left out for having another skeleton.
    """
    motions = [_take(t).resample(fps) for t in _seen(index.load_take(e) for e in entries)]
    best, left = largest_group(motions, [e.file for e in entries])
    return [motions[i] for i in best], [entries[i] for i in left]


def _seen(takes: Iterable[Motion | Markers]) -> list[Motion | Markers]:
    """The takes, markers without those some take never sees (:func:`seen_in_every`, said
    once); skeletons as they are."""
    takes = list(takes)
    markers = [i for i, t in enumerate(takes) if isinstance(t, Markers)]
    for i, t in zip(markers, seen_in_every([takes[i] for i in markers]), strict=True):
        takes[i] = t
    return takes


def _take(take: Motion | Markers) -> Motion | Markers:
    """A take as the models learn it: markers with their unseen samples filled in."""
    return fill_gaps(take) if isinstance(take, Markers) else take


def evaluation_joints(motions: Sequence[Motion], tol: float = 1e-3) -> np.ndarray:
    """The joints at which prediction errors are measured.

    These are the joints whose local rotation moves by more than ``tol``
    radians in the data, plus, where none of such a joint's children moves,
    its child with the longest bone (the tip of a hand, foot or head): a
    joint's rotation shows only in where its children are. CMU's figure has
    fixed fingers and eyes that would otherwise dilute the mean.
    """
    from scipy.spatial.transform import Rotation

    sk = motions[0].skeleton
    moving = np.zeros(sk.n_joints, dtype=bool)
    for m in motions:
        q = m.rotations
        rel = (
            Rotation.from_quat(q.reshape(-1, 4))
            * Rotation.from_quat(np.repeat(q[:1], len(q), axis=0).reshape(-1, 4)).inv()
        )
        moving |= rel.magnitude().reshape(len(q), -1).max(axis=0) > tol
    keep = moving.copy()
    for j in np.flatnonzero(moving):
        kids = sk.children(j)
        if kids and not moving[kids].any():
            keep[max(kids, key=lambda c: np.linalg.norm(sk.offsets[c]))] = True
    return np.flatnonzero(keep)


def call_rng(
    rng: np.random.Generator | None, stochastic: bool, random_state: int | None
) -> np.random.Generator | None:
    """The generator a verb draws from: ``None`` (maximum likelihood) unless ``stochastic``;
    then ``rng``, or a new one seeded with the model's ``random_state``."""
    if not stochastic:
        return None
    return rng if rng is not None else np.random.default_rng(random_state)


def contour_arrays(sequences: Sequence[np.ndarray], width: int | None = None) -> list[np.ndarray]:
    """Contour configurations as float arrays (F, 2n), checked: finite, even width
    (``width`` if given), at least two frames each.

    Raises:
        ValueError: anything else (one line).
    """
    if isinstance(sequences, np.ndarray) or not len(sequences):
        raise ValueError("contour configurations: give a list of (frames, 2n) arrays")
    out = []
    for i, s in enumerate(sequences):
        if not (isinstance(s, np.ndarray) or is_sparse(s)):
            raise ValueError(
                f"contour sequence {i}: a contour model takes (frames, 2n) arrays, "
                f"not {type(s).__name__}"
            )
        a = check_frames(s, f"contour sequence {i}")
        if a.shape[1] % 2 or len(a) < 2:
            raise ValueError(
                f"contour sequence {i}: expected finite (frames >= 2, 2n) values, got {a.shape}"
            )
        if width is not None and a.shape[1] != width:
            raise ValueError(
                f"contour sequence {i}: {a.shape[1]} values a frame, model has {width}"
            )
        out.append(a)
    return out


def array_record(array: np.ndarray, i: int) -> dict[str, str]:
    """Name and content hash of a training array (what ``train_files_`` lists of it)."""
    digest = hashlib.sha256(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    return {"file": f"contour sequence {i}", "sha256": digest.hexdigest()}


# ------------------------------------------------------------------ model
class BehaviourModel(Model):
    """Prototypes in augmented configuration space and a VLMM over them (§2, §3.2).

    Args:
        n_prototypes: number of prototypes (alphabet size).
        max_memory: N of the VLMM.
        epsilon: KL threshold of the VLMM (eq. 5).
        lam: weight of the derivative in F = [C, lam dC] (eq. 2). The defaults here
            are the paper's (``rotations``, lambda 10, join 0); ``vlmm train``'s are
            those chosen for prediction by cross-validation on the training takes
            (``positions``, lambda 100, join 2 s: docs/vlmm.md).
        configuration: ``"rotations"`` (exponential maps + pelvis height),
            ``"positions"`` (body-centred joint positions in mm) or ``"markers"``
            (the 13 body points of §2.1.2, body-centred) or ``"contour"`` ((F, 2n) arrays
            of silhouette contour configurations, §2.1.1, instead of motions).
        fps: frame rate the motion is resampled to for modelling.
        quantiser: ``"kmeans"`` or ``"competitive"`` (robust competitive learning).
        time_scale: factor on the eq. 8 intervals (1: the paper's).
        max_interval: longest interval between two prototypes, in seconds.
        join: time constant in seconds of the smooth join of a prediction to the observed
            configuration (:meth:`continuation`); 0 (the paper's join) starts the curve at
            the observed configuration and nothing more.
        random_state: seed of the vector quantisation, and of :meth:`generate`
            and :meth:`predict` when they are stochastic and given no ``rng``.

    Learnt attributes: ``pipeline_`` (motion -> F), ``prototypes_`` (K, 2d),
    ``vlmm_``, ``train_tokens_`` / ``train_lengths_`` (the collapsed training
    token sequences, concatenated), ``eval_joints_``, ``skeleton_``,
    ``train_files_``; :func:`fit_index` adds ``category_``, ``labels_`` and
    ``held_out_files_``.
    """

    KIND = "vlmm"
    VERBS = ("generate", "predict", "score")

    @property
    def takes_arrays(self) -> bool:
        """Contour models predict from contour arrays (:meth:`Model.takes_arrays`)."""
        return self.is_contour

    def __init__(
        self,
        n_prototypes: int = 100,
        max_memory: int = 5,
        epsilon: float = 1e-4,
        lam: float = 10.0,
        configuration: str = "rotations",
        fps: float = 30.0,
        quantiser: str = "kmeans",
        time_scale: float = 1.0,
        max_interval: float = 1.0,
        join: float = 0.0,
        random_state: int | None = 0,
    ):
        self.n_prototypes = n_prototypes
        self.max_memory = max_memory
        self.epsilon = epsilon
        self.lam = lam
        self.configuration = configuration
        self.fps = fps
        self.quantiser = quantiser
        self.time_scale = time_scale
        self.max_interval = max_interval
        self.join = join
        self.random_state = random_state

    # ---------------------------------------------------------------- fitting
    @property
    def is_contour(self) -> bool:
        """Whether the model learns contour arrays (§2.1.1) rather than motions."""
        return self.configuration == "contour"

    def _make_pipeline(self, skeleton: Skeleton | None) -> FeaturePipeline:
        if self.configuration == "contour":
            return FeaturePipeline([AugmentedConfiguration(self.lam)])
        if skeleton is None:  # markers read from C3D files: as they are named
            first = [MarkerFeatures(body_centred=True)]
            return FeaturePipeline([*first, DropStaticColumns(), AugmentedConfiguration(self.lam)])
        if self.configuration == "rotations":
            first = [RemoveHeading(), ExpMaps(root_position="height")]
        elif self.configuration == "positions":
            first = [JointPositions(body_centred=True)]
        elif self.configuration == "markers":
            body_point_index(skeleton, MARKER_POINTS, "the training skeleton")  # one line if not
            # the 13 points found by name on each take's skeleton: any skeleton that has them
            # is observed, as the dual HMM's (models saved before kept the training joints)
            first = [JointPositions(body_centred=True, points=list(MARKER_POINTS))]
        else:
            raise ValueError(f"configuration must be one of {CONFIGURATIONS}")
        return FeaturePipeline([*first, DropStaticColumns(), AugmentedConfiguration(self.lam)])

    def fit(self, motions: Sequence[Motion] | Sequence[np.ndarray]) -> BehaviourModel:
        """Learn prototypes and the VLMM from motions (resampled to ``fps``), or for
        ``configuration="contour"`` from (F, 2n) contour configurations at ``fps``; returns self."""
        if self.quantiser not in QUANTISERS:
            raise ValueError(f"quantiser must be one of {QUANTISERS}")
        if not self.join >= 0:
            raise ValueError(f"join must be a time constant >= 0 s, got {self.join}")
        if self.is_contour:
            motions = contour_arrays(motions)
            self.n_features_in_ = motions[0].shape[1]
            self.train_files_ = [array_record(a, i) for i, a in enumerate(motions)]
            self.skeleton_ = None
        else:
            self.record_training(motions)
            motions = [_take(m).resample(self.fps) for m in _seen(motions)]
            self._check_takes(motions)
            self.skeleton_ = None if isinstance(motions[0], Markers) else motions[0].skeleton
        self.pipeline_ = self._make_pipeline(self.skeleton_)
        feats = self.pipeline_.fit_transform(motions)
        x = np.vstack(feats)
        if self.quantiser == "kmeans":
            self.prototypes_ = kmeans_prototypes(x, self.n_prototypes, seed=self.random_state)
        else:
            self.prototypes_ = competitive_learning(x, self.n_prototypes, seed=self.random_state)
        runs = [collapse_repeats(nearest_prototype(f, self.prototypes_)) for f in feats]
        self.train_tokens_ = np.concatenate([r[0] for r in runs])
        self.train_lengths_ = np.array([len(r[0]) for r in runs])
        if self.is_contour:
            self.eval_joints_ = np.arange(motions[0].shape[1] // 2)  # the control points
        elif self._from_markers():
            self.eval_joints_ = np.arange(len(self.marker_names))  # every marker
        elif self.configuration == "markers":
            self.eval_joints_ = body_point_index(self.skeleton_, MARKER_POINTS)
        else:
            self.eval_joints_ = evaluation_joints(motions)
        self.vlmm_ = VLMM(self.max_memory, self.epsilon).fit(
            self.token_sequences(), n_symbols=self.n_prototypes
        )
        return self

    def _check_takes(self, takes: Sequence[Motion | Markers]) -> None:
        """Markers only for ``configuration="markers"``, and one kind of take throughout
        (:class:`SkeletonMismatchError` naming the first that differs)."""
        if isinstance(takes[0], Markers) and self.configuration != "markers":
            raise SkeletonMismatchError(
                f"{takes[0].name or 'markers'}: markers are learnt with "
                f'configuration="markers", not {self.configuration!r}'
            )
        for t in takes[1:]:
            if not same_set(takes[0], t):
                what = "markers" if isinstance(takes[0], Markers) else "a skeleton"
                raise SkeletonMismatchError(
                    f"{t.name or 'a take'}: not {what} like {takes[0].name or 'the first take'}"
                )

    def fits(self, take: Motion | Markers) -> bool:
        """Whether the model can observe ``take``: its skeleton's topology, or (a model
        learnt from markers files) markers holding every one the model learnt."""
        if self._from_markers():
            return isinstance(take, Markers) and take.has(self.marker_names)
        if isinstance(take, Motion) and self._by_points():
            try:
                body_point_index(take.skeleton, MARKER_POINTS, take.name or "take")
            except SkeletonMismatchError:
                return False
            return True
        return isinstance(take, Motion) and take.skeleton.same_topology(self.skeleton_)

    def _by_points(self) -> bool:
        """Whether the model finds its 13 body points by name on any skeleton (a markers
        model learnt from a skeleton, fitted by this version)."""
        steps = getattr(getattr(self, "pipeline_", None), "steps", None)
        return bool(steps) and getattr(steps[0], "points", None) is not None

    def why_not(self, take: Motion | Markers, what: str = "the take") -> str:
        """Why :meth:`fits` refuses ``take`` (called ``what``), in a few words naming what
        differs."""
        if self._from_markers():
            if not isinstance(take, Markers):
                return "a skeleton, and the model learnt markers"
            missing = find_markers(take.names, self.marker_names)[1]
            return f"markers not found: {', '.join(missing[:8])}"
        if not isinstance(take, Motion):
            return "markers, and the model learnt a skeleton"
        if self._by_points():
            try:
                body_point_index(take.skeleton, MARKER_POINTS, "its skeleton")
            except SkeletonMismatchError as exc:
                return str(exc)
        return self.skeleton_.difference(take.skeleton, "the model's", what) or "fits"

    @property
    def marker_names(self) -> tuple[str, ...]:
        """The markers a ``configuration="markers"`` model learns and writes: the 13 body
        points placed on a skeleton, or the markers of the C3D files it was trained on."""
        if self._from_markers():
            return tuple(self.pipeline_.steps[0].names_)
        return tuple(MARKER_POINTS)

    def check_state(self) -> None:
        """The learnt parts a model file must hold, and that they fit: one prototype per
        symbol of vlmm_, of the pipeline's width; training tokens prototype ids, their
        lengths summing to their count; eval_joints_ joints of skeleton_."""
        if not is_fitted(self):
            return
        require(self, "train_files_", "prototypes_", "eval_joints_", "train_tokens_")
        require(self, "train_lengths_")
        require_types(self, pipeline_=FeaturePipeline, vlmm_=VLMM)
        if not self.is_contour and not self._from_markers():
            require_types(self, skeleton_=Skeleton)
        width = self.pipeline_.output_width()
        k = len(check_shape("prototypes_", self.prototypes_, (None, width)))
        if self.vlmm_.n_symbols_ != k:
            raise StateError(f"prototypes_: {k} prototypes, vlmm_ has {self.vlmm_.n_symbols_}")
        tokens = check_index(
            "train_tokens_", check_shape("train_tokens_", self.train_tokens_, (None,)), k
        )
        check_lengths("train_lengths_", self.train_lengths_, len(tokens))
        if self.is_contour:
            n_points = width // 4
        elif self._from_markers():
            n_points = len(self.marker_names)
        else:
            n_points = self.skeleton_.n_joints
        check_index("eval_joints_", self.eval_joints_, n_points)

    def _from_markers(self) -> bool:
        """Whether the model learnt from markers files (its pipeline starts on markers)."""
        return self.configuration == "markers" and isinstance(
            self.pipeline_.steps[0], MarkerFeatures
        )

    def token_sequences(self) -> list[np.ndarray]:
        """The collapsed prototype sequences of the training motions."""
        return np.split(self.train_tokens_, np.cumsum(self.train_lengths_)[:-1])

    def with_vlmm(self, max_memory: int, epsilon: float) -> BehaviourModel:
        """The same prototypes with another VLMM trained on the same tokens
        (``max_memory=1, epsilon=0`` is the first-order Markov model)."""
        other = copy.copy(self)
        other.max_memory, other.epsilon = max_memory, epsilon
        other.vlmm_ = VLMM(max_memory, epsilon).fit(
            self.token_sequences(), n_symbols=self.n_prototypes
        )
        return other

    # ------------------------------------------------------------- features
    @property
    def n_dims(self) -> int:
        """d, the dimension of the configuration C (prototypes are 2d long)."""
        return self.prototypes_.shape[1] // 2

    def observe(self, motions: Sequence[Motion] | Sequence[np.ndarray]) -> list[np.ndarray]:
        """Augmented configuration vectors (F, 2d) of motions, at the model's frame rate
        (of contour configurations (F, d) for ``configuration="contour"``: eq. 2)."""
        if self.is_contour:
            return self.pipeline_.transform(contour_arrays(motions, self.n_dims))
        takes = [_take(m).resample(self.fps) for m in motions]
        markers = self._from_markers()
        for t in takes:
            if isinstance(t, Markers) != markers:
                learnt = "markers" if markers else "a skeleton"
                raise SkeletonMismatchError(f"{t.name or 'input'}: the model learnt {learnt}")
        return self.pipeline_.transform(takes)

    def knots(self, tokens: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Configurations C and their per-frame derivatives dC of prototypes (eq. 2)."""
        p = self.prototypes_[np.asarray(tokens)]
        return p[..., : self.n_dims], p[..., self.n_dims :] / self.lam

    def intervals(self, c: np.ndarray, dc: np.ndarray) -> np.ndarray:
        """Frames between successive knots: eq. 8 times ``time_scale``, at least one frame."""
        tau = constant_acceleration_intervals(c, dc) * self.time_scale
        return np.clip(tau, 1.0, self.max_interval * self.fps)

    def synthesize(
        self, tokens: np.ndarray, start: tuple[np.ndarray, np.ndarray] | None = None
    ) -> np.ndarray:
        """Configurations (F, d) at the frame rate through the prototypes ``tokens``.

        Cubic Hermite interpolation with the prototypes' derivatives as tangents
        and eq. 8 intervals (§3.2.1); ``start`` = (C, dC) puts a first knot
        before the prototypes (the current observed configuration).
        """
        c, dc = self.knots(tokens)
        if start is not None:
            c, dc = np.vstack([start[0], c]), np.vstack([start[1], dc])
        if len(c) == 1:
            return c.copy()
        times = np.r_[0.0, np.cumsum(self.intervals(c, dc))]
        return hermite_sample(c, dc, times, np.arange(int(np.floor(times[-1])) + 1))

    def to_motion(self, configs: np.ndarray) -> Motion | Markers | np.ndarray:
        """Scaled configurations (F, d) back to a motion on the training skeleton, or for
        ``configuration="markers"`` to the 13 markers (mm, lowest marker on the floor), or
        for ``"contour"`` to contour configurations (F, d) (eq. 4 undone)."""
        out = self.pipeline_.inverse_transform([configs])[0]
        if isinstance(out, Motion) or self.is_contour:
            return out
        if self.configuration == "markers":
            out = out - np.array([0.0, 1.0, 0.0]) * np.nanmin(out[..., 1])
            return Markers(self.marker_names, out, self.fps, name="vlmm")
        # positions: fit rotations to the skeleton, feet on the floor
        pos = out - np.array([0.0, 1.0, 0.0]) * out[..., 1].min(axis=1)[:, None, None]
        return fit_rotations(self.skeleton_, pos, fps=self.fps)

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        """Positions (M, J_eval, 3) in mm of the evaluated joints for scaled configurations (M, d);
        for ``"contour"``, control points (M, n, 2) in contour configuration units."""
        raw = self.pipeline_.steps[-1].inverse_transform([configs])[0]
        if self.is_contour:
            return raw.reshape(len(raw), -1, 2)
        raw = self.pipeline_.steps[-2].inverse_transform([raw])[0]
        if self.configuration == "positions":
            return raw.reshape(len(raw), -1, 3)[:, self.eval_joints_]
        if self.configuration == "markers":
            return raw.reshape(len(raw), -1, 3)
        expmaps = self.pipeline_.steps[1]
        sk = expmaps.skeleton_
        n_rot = 3 * len(expmaps.joint_index_)
        rotvecs = np.zeros((len(raw), sk.n_joints, 3))
        rotvecs[:, expmaps.joint_index_] = raw[:, :n_rot].reshape(len(raw), -1, 3)
        root = np.tile(sk.offsets[sk.body_root], (len(raw), 1))
        root[:, 1] = raw[:, n_rot]
        return rotvec_positions(sk, rotvecs, root, self.eval_joints_, root_joint=sk.body_root)

    # ----------------------------------------------------------- generation
    def generate_tokens(
        self, seconds: float, rng: np.random.Generator | None = None, stochastic: bool = True
    ) -> np.ndarray:
        """Prototypes from a start state until they span ``seconds`` (§3.2.1).

        Drawn from the automaton when ``stochastic`` (from ``rng``, else a
        generator seeded with ``random_state``), else its most likely path.
        """
        seconds = check_length(seconds, self.fps, MAX_FRAMES, "seconds")
        rng = call_rng(rng, stochastic, self.random_state)
        n_frames = seconds * self.fps
        start = self.vlmm_.start_state(rng)
        state = np.array([start])
        # the start state's memory ends with the first prototype of the routine
        memory = self.vlmm_.memories_[start]
        tokens = [int(memory[-1])] if len(memory) and memory[-1] >= 0 else []
        prev = tokens[0] if tokens else None
        total = 0.0
        while total < n_frames:
            tok, state = self.vlmm_.step(state, rng)
            if prev is not None:
                c, dc = self.knots(np.array([prev, tok[0]]))
                total += float(self.intervals(c, dc)[0])
            tokens.append(int(tok[0]))
            prev = tok[0]
        return np.array(tokens)

    def generate(
        self, seconds: float, rng: np.random.Generator | None = None, stochastic: bool = True
    ) -> Motion | Markers | np.ndarray:
        """A new routine of ``seconds`` (plus its first frame) on the training skeleton
        (13 markers; contour configurations (F, d)).

        Drawn from the automaton when ``stochastic`` (from ``rng``, else a
        generator seeded with ``random_state``), else its most likely path.
        """
        configs = self.synthesize(self.generate_tokens(seconds, rng, stochastic))
        return self.to_motion(configs[: int(round(seconds * self.fps)) + 1])

    # ----------------------------------------------------------- prediction
    def prepare(self, features: np.ndarray) -> np.ndarray:
        """The automaton state at every frame, recognising the observed prototypes (§3.2.2)."""
        tokens, starts = collapse_repeats(nearest_prototype(features, self.prototypes_))
        states = self.vlmm_.recognise(tokens)
        return np.repeat(states, np.diff(np.r_[starts, len(features)]))

    def predict_configurations(
        self,
        features: np.ndarray,
        prepared: np.ndarray,
        frames: np.ndarray,
        horizon: int,
        n_samples: int,
        rng: np.random.Generator | None,
    ) -> np.ndarray:
        """(len(frames), n_samples, horizon, d) predicted configurations after each frame.

        From the state at frame t, ``n_samples`` traversals (drawn from
        ``rng``; the most likely path when ``rng`` is None) emit prototypes
        until ``horizon`` frames are covered; the curve starts at the observed
        C_t, dC_t. This is the predictor protocol of
        :func:`markovmotion.evaluate.vlmm.evaluate_horizon`.
        """
        frames = np.asarray(frames)
        c0, dc0 = self.start_knots(features, frames, n_samples)
        states = np.repeat(prepared[frames], n_samples)
        first = np.zeros(len(states))
        times = np.zeros(len(states))
        tokens, prev = [], None
        while times.min() < horizon:
            tok, states = self.vlmm_.step(states, rng)
            if prev is None:
                c, dc = self.knots(tok)
                first = self.intervals(np.stack([c0, c], 1), np.stack([dc0, dc], 1))[:, 0]
                times = first.copy()
            else:
                times = times + self.pair_intervals[prev, tok]
            tokens.append(tok)
            prev = tok
        out = self.continuation(np.stack(tokens, axis=1), c0, dc0, horizon)
        return out.reshape(len(frames), n_samples, horizon, self.n_dims)

    def start_knots(
        self, features: np.ndarray, frames: np.ndarray, n_samples: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """The observed C_t and dC_t at ``frames``, each repeated ``n_samples`` times."""
        d = self.n_dims
        c0 = np.repeat(features[frames, :d], n_samples, axis=0)
        return c0, np.repeat(features[frames, d:] / self.lam, n_samples, axis=0)

    @property
    def pair_intervals(self) -> np.ndarray:
        """(K, K) eq. 8 intervals in frames between every two prototypes."""
        if not hasattr(self, "_pair_intervals"):
            c, dc = self.knots(np.arange(len(self.prototypes_)))
            k = len(c)
            pairs_c = np.stack([np.repeat(c, k, 0), np.tile(c, (k, 1))], axis=1)
            pairs_dc = np.stack([np.repeat(dc, k, 0), np.tile(dc, (k, 1))], axis=1)
            self._pair_intervals = self.intervals(pairs_c, pairs_dc)[:, 0].reshape(k, k)
        return self._pair_intervals

    def continuation(
        self, tokens: np.ndarray, c0: np.ndarray, dc0: np.ndarray, horizon: int
    ) -> np.ndarray:
        """(P, horizon, d) curves from (C0, dC0) through the prototypes ``tokens`` (P, R).

        Frames 1..horizon after the start; the prototypes must span the horizon.
        The curve is the cubic Hermite interpolant of eq. 8 with its first knot
        replaced by the observed (C0, dC0), as the interaction paper's smooth join
        replaces the first extrapolated state by the current one (§4 there). With
        ``join`` > 0 the curve is further blended with the observed configuration,

            C(T) = w(T) C0 + (1 - w(T)) H(T),   w(T) = exp(-T / (join fps)),

        so the prediction leaves the observed pose gradually rather than snapping
        to the prototypes (whose quantisation error, on unseen takes, is larger
        than a short horizon's motion).
        """
        c, dc = self.knots(tokens)
        c = np.concatenate([c0[:, None], c], axis=1)
        dc = np.concatenate([dc0[:, None], dc], axis=1)
        times = np.concatenate(
            [np.zeros((len(c), 1)), np.cumsum(self.intervals(c, dc), axis=1)], axis=1
        )
        out = hermite_sample(c, dc, times, np.arange(1, horizon + 1))
        w = self.join_weights(horizon)[:, None]
        return w * c0[:, None] + (1.0 - w) * out

    def join_weights(self, horizon: int) -> np.ndarray:
        """(horizon,) weight of the observed configuration at frames 1..horizon ahead:
        exp(-T / (join fps)), zero when ``join`` is 0 (:meth:`continuation`)."""
        join = getattr(self, "join", 0.0)
        if join <= 0:
            return np.zeros(horizon)
        return np.exp(-np.arange(1, horizon + 1) / (join * self.fps))

    def predict(
        self,
        motion: Motion | np.ndarray,
        seconds: float,
        rng: np.random.Generator | None = None,
        stochastic: bool = False,
    ) -> Motion | Markers | np.ndarray:
        """The observed motion (at the model's frame rate) followed by ``seconds`` of
        predicted continuation: the most likely one, or drawn when ``stochastic``."""
        feats = self.observe([motion])[0]
        states = self.prepare(feats)
        horizon = int(round(seconds * self.fps))
        rng = call_rng(rng, stochastic, self.random_state)
        pred = self.predict_configurations(
            feats, states, np.array([len(feats) - 1]), horizon, 1, rng
        )[0, 0]
        return self.to_motion(np.vstack([feats[:, : self.n_dims], pred]))

    # ---------------------------------------------------------------- score
    def tokens(self, motion: Motion | np.ndarray) -> np.ndarray:
        """The collapsed prototype sequence of a motion (eq. 3)."""
        return collapse_repeats(nearest_prototype(self.observe([motion])[0], self.prototypes_))[0]

    def score(self, motions: Sequence[Motion] | Sequence[np.ndarray]) -> float:
        """Log-likelihood (nats) of the motions' collapsed prototype sequences under the VLMM,
        summed over the motions (:meth:`VLMM.log_likelihood`: each sequence read from the
        root, unseen events backed off to P(a))."""
        return float(sum(self.vlmm_.log_likelihood(self.tokens(m)) for m in motions))


# ------------------------------------------------------------------ training on an index
@dataclass
class IndexFit:
    """What :func:`fit_index` trained on: the takes used, held out, and left out."""

    model: Model
    motions: list[Motion]
    used: list[Entry]
    held_out: list[Entry] = field(default_factory=list)
    other_skeleton: list[Entry] = field(default_factory=list)


def fit_index(
    model: Model,
    index: MocapIndex,
    category: str = "exercise",
    labels: Sequence[str] | None = None,
    hold_out: bool = True,
    kind: str | None = None,
) -> IndexFit:
    """Fit ``model`` (a behaviour model, plain or structured) on the takes of ``category``
    (and ``labels``) of an index, the last take of each label held out when ``hold_out``
    (:func:`markovmotion.data.splits.held_out_last`): takes of one kind (``kind``, else
    the larger group; :func:`~markovmotion.data.kinds.choose_kind`: a model of skeleton
    positions or rotations learns skeletons only), then the largest group of them that
    share a skeleton or marker set.

    Records on the model ``category_``, ``labels_`` (those of the takes used) and
    ``held_out_files_`` (INDEX.csv file names), which ``vlmm evaluate`` reads.

    Raises:
        DataNotFoundError: no take of that category and labels.
    """
    from markovmotion.data.splits import held_out_last

    entries = index.query(category=category, label=labels or None)
    if not entries:
        which = f"{category} takes labelled {', '.join(labels)}" if labels else f"{category} takes"
        raise DataNotFoundError(f"no {which} in {index.root / 'INDEX.csv'}")
    base = (model if isinstance(model, BehaviourModel) else model.prototype_model) or (
        BehaviourModel()
    )
    can = ("skeleton", "markers") if base.configuration == "markers" else ("skeleton",)
    entries, other_kind = choose_kind(entries, kind, f"{category} takes", can=can)
    # the largest skeleton group first, then the last take of each label held out of it: a
    # take held out on another skeleton would leave the model no take to be evaluated on
    takes = [index.load_take(e) for e in entries]
    best, left = largest_group(takes, [e.file for e in entries])
    kept = [entries[i] for i in best]
    train, held_out = held_out_last(kept) if hold_out else (kept, [])
    motions = [
        _take(t).resample(base.fps) for t in _seen(takes[i] for i in best if entries[i] in train)
    ]
    model.fit(motions)
    model.category_ = category
    model.labels_ = sorted({e.label for e in train})
    model.held_out_files_ = [e.file for e in held_out]
    return IndexFit(model, motions, train, held_out, [entries[i] for i in left] + other_kind)

"""The interaction model of the interaction paper, end to end: two people in, a partner out.

:class:`VirtualPartner` chains the joint shape features (§2), the behaviour
chain (§3-4) and hypothesis propagation (§5): trained on two-person takes
(pairs of motion-capture takes, skeletons or named markers, or silhouettes tracked
in video), it answers
one real person's observed shapes with the partner's shapes, placed in the
image or the world from the real person's position and height.

Verbs (:mod:`markovmotion.models.base`): ``respond`` (the partner's whole
motion for a whole captured motion) and ``partner()`` (the same, online, one
frame at a time: :class:`ChainPartner`, :mod:`markovmotion.models.online`).
"""

from __future__ import annotations

import hashlib
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from markovmotion.algorithms.kinematics import fit_rotations
from markovmotion.core.markers import Markers, find_markers, not_found
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.defaults import DEFAULT_PLACE_WINDOW, DEFAULT_PROTOTYPES
from markovmotion.errors import MarkovMotionError, SkeletonMismatchError
from markovmotion.features.base import FeaturePipeline
from markovmotion.features.body_motion import mean_place, place_rows
from markovmotion.features.joint_shape import (
    JointShape,
    Person,
    TwoPeople,
    joint_shape_pipeline,
    joints_skeleton,
    marker_size,
    person_from_motion,
    person_from_take,
    rotate_yaw,
    shape_joints,
)
from markovmotion.features.markers import MarkerFeatures, named_body_points, seen_in_every
from markovmotion.features.person import ShapeCentre
from markovmotion.features.smoothing import TemporalSmoothing
from markovmotion.models.base import Model, flatten
from markovmotion.models.chain.behaviour_chain import BehaviourChain
from markovmotion.models.chain.condensation import (
    DEFAULT_RESPONSE,
    DEFAULT_RESYNC,
    DEFAULT_SIGMA,
    MultipleHypotheses,
    Propagator,
    SingleHypothesis,
)
from markovmotion.models.online import FINISHED, CheckedOnce, MissingFrames, check_frame
from markovmotion.state import (
    StateError,
    check_positive,
    check_shape,
    is_fitted,
    require,
    require_types,
)

#: The paper's frame rate: motion-capture pairs are resampled to it for training.
DEFAULT_FPS = 25.0


@dataclass
class PartnerResponse:
    """The virtual partner over T frames, with what chose it.

    Attributes:
        partner: the partner's shape points, reference, height and heading.
        shapes: (T, d) the chosen hypotheses' combined shape vectors (normalised).
        roles: (T,) which half of the model the real person matched (0 or 1).
        errors: (T,) the matching error E of eq. (18).
    """

    partner: Person
    shapes: np.ndarray
    roles: np.ndarray
    errors: np.ndarray


#: The kinds of take the behaviour chain learns from (:mod:`markovmotion.data.kinds`).
KINDS = ("skeleton", "markers")
#: ``VirtualPartner(normalise=...)``: the paper's shapes, or each person's centred on the
#: training people's mean shape (:class:`~markovmotion.features.person.ShapeCentre`).
NORMALISE = ("none", "person")


class VirtualPartner(Model):
    """Interaction model: joint shape vectors, behaviour chain, virtual partner (§2-5).

    Args:
        window: smoothing window w (paper: 5).
        lam: derivative weight lambda of F = [C, lambda dC] (paper: 10).
        n_state_prototypes, n_behaviour_prototypes, gamma, n_epochs,
        interval_noise, random_state: passed to :class:`BehaviourChain`
            (``random_state`` also seeds the propagation unless a verb is given ``rng``).
        fps: the rate motion-capture pairs are resampled to for training (paper: 25).
        normalise: ``"person"``: each person's shape on the training people's mean
            (:data:`NORMALISE`).
        shrink: how far the partner's shape is pulled toward the training people's mean
            shape ``mean_shape_`` (the baseline partner), 0 to 1; 0, the default, is the
            paper's. Our addition for people the model has never seen: the chosen
            hypothesis is one training prototype, the mean averages them; a convex blend of
            the two, in the model's normalised shape space before placing, keeps the
            interaction's phases and loses much of a prototype's person (docs/chain.md).
        place_window: frames over which where a 3-D partner stands on the floor and faces
            is averaged, causally (:class:`PlaceAverage`; 1: not at all, the paper's),
            whole and online alike; its pose is not changed. Our addition: the response hops from
            hypothesis to hypothesis, and the half of C it shows but eq. (18) does not
            compare (where the partner stands) hops with it, hundreds of mm a frame; and
            the partner is placed by A's heading, which swings with A's hips. Default
            :data:`~markovmotion.defaults.DEFAULT_PLACE_WINDOW`, chosen by leaving one
            salsa training take out (docs/chain.md). Silhouettes are placed as the paper's.

    Learnt: ``pipeline_`` (TwoPeople -> state vectors), ``chain_``,
    ``mean_shape_`` (d,) the mean normalised combined shape (the baseline
    partner), ``stance_`` (2, 2) each person's median size and reference height over the
    training takes (mm: a skeleton's standing height and 0, its pelvis on the floor;
    markers' :func:`marker_size` and centroid height; how an online partner stands A before
    it has seen A), ``centre_``, ``fps_``, ``skeletons_`` (each person's skeleton
    of shape joints, from skeleton pairs; None from markers or prepared takes),
    ``markers_`` (the marker names each person is seen by, from marker pairs;
    else None), ``train_files_``.
    """

    KIND = "behaviour-chain"
    VERBS = ("respond", "partner")
    FITS_PAIRS = True
    PREPARED_TAKES = (TwoPeople,)
    #: Parameters a file saved before they existed was answering with (restore_estimator):
    #: the partner's place was not averaged.
    PARAMS_OF_OLDER_FILES: ClassVar[dict[str, object]] = {"place_window": 1}

    def __init__(
        self,
        window: int = 5,
        lam: float = 10.0,
        n_state_prototypes: int = DEFAULT_PROTOTYPES,
        n_behaviour_prototypes: int = DEFAULT_PROTOTYPES,
        gamma: float = 0.995,
        n_epochs: int = 5,
        interval_noise: tuple[float, float] = (0.5, 0.25),
        random_state: int = 0,
        fps: float = DEFAULT_FPS,
        normalise: str = "none",
        shrink: float = 0.0,
        place_window: int = DEFAULT_PLACE_WINDOW,
    ):
        self.window = window
        self.lam = lam
        self.n_state_prototypes = n_state_prototypes
        self.n_behaviour_prototypes = n_behaviour_prototypes
        self.gamma = gamma
        self.n_epochs = n_epochs
        self.interval_noise = interval_noise
        self.random_state = random_state
        self.fps = fps
        self.normalise = normalise
        self.shrink = shrink
        self.place_window = place_window

    def check_params(self) -> None:
        """Raise ValueError (one line, naming the parameter) for a hyper-parameter out of its
        choices: :meth:`fit` checks first, and ``--choose`` every setting before anything
        is learnt."""
        if self.normalise not in NORMALISE:
            raise ValueError(f"normalise must be one of {NORMALISE}, got {self.normalise!r}")
        if not 0.0 <= self.shrink <= 1.0:
            raise ValueError(f"shrink must be from 0 to 1, got {self.shrink!r}")
        w = self.place_window
        if not (isinstance(w, int | np.integer) and not isinstance(w, bool) and 1 <= w <= 1000):
            raise ValueError(f"place_window must be 1 to 1000 frames, got {w!r}")

    def fit(
        self,
        takes: Sequence[tuple[Motion, Motion]]
        | Sequence[tuple[Markers, Markers]]
        | Sequence[TwoPeople],
    ) -> VirtualPartner:
        """Learn the feature ranges, both prototype sets and the chain from two-person takes.

        ``takes``: pairs (A, B) of motion-capture takes, all skeletons or all markers
        (resampled to ``fps``; both files recorded in ``train_files_``; markers are picked
        by the names of the first take's A, ``markers_``), or prepared :class:`TwoPeople`
        (silhouettes tracked in video: their names and a hash of their points are
        recorded).
        """
        takes = list(takes)  # checked by Model's fit wrapper (check_params, check_takes)
        self.skeletons_ = self.markers_ = None
        if all(isinstance(t, TwoPeople) for t in takes):
            people = takes
            self.train_files_ = [_take_record(t) for t in people]
        else:
            pairs = [tuple(t) for t in takes]
            for kind in (Motion, Markers):
                if all(len(t) == 2 and all(isinstance(m, kind) for m in t) for t in pairs):
                    break
            else:
                raise TypeError(
                    "fit takes (A, B) pairs, all Motions or all Markers, or TwoPeople takes"
                )
            a, b = pairs[0]
            if kind is Markers:
                seen = seen_in_every([m for pair in pairs for m in pair])
                pairs = list(zip(seen[0::2], seen[1::2], strict=True))
                a, b = pairs[0]
                self.markers_ = list(a.names)
            else:
                self.skeletons_ = [
                    joints_skeleton(m.skeleton, shape_joints(m.skeleton)) for m in (a, b)
                ]
            try:
                people = [TwoPeople.from_motions(a, b, self.fps, self.markers_) for a, b in pairs]
            except ValueError as exc:  # a take without the first one's markers
                raise SkeletonMismatchError(str(exc)) from None
            self.record_training(flatten(pairs))
        self.pipeline_ = joint_shape_pipeline(people, self.window, self.lam, self.normalise)
        states = self.pipeline_.fit_transform(people)
        self.chain_ = BehaviourChain(
            n_state_prototypes=self.n_state_prototypes,
            n_behaviour_prototypes=self.n_behaviour_prototypes,
            gamma=self.gamma,
            lam=self.lam,
            n_epochs=self.n_epochs,
            interval_noise=self.interval_noise,
            random_state=self.random_state,
        ).fit(states)
        self.mean_shape_ = np.vstack(states)[:, : self.chain_.dim].mean(axis=0)
        heights = np.vstack([t.height for t in people])  # (frames, 2)
        levels = np.vstack([t.reference[..., 1] for t in people])
        self.stance_ = np.column_stack([np.median(heights, axis=0), np.median(levels, axis=0)])
        self.centre_ = float(
            np.median(np.concatenate([t.reference[..., 0].ravel() for t in people]))
        )
        self.fps_ = float(people[0].fps)
        return self

    def check_state(self) -> None:
        """The learnt parts a model file must hold, and that they fit: chain_ state
        vectors of the pipeline's width, mean_shape_ their configuration half,
        skeletons_ none or one per person, a positive frame rate."""
        if not is_fitted(self):
            return
        require(self, "train_files_", "mean_shape_", "centre_", "fps_", "skeletons_")
        markers = getattr(self, "markers_", None)  # absent from files of older versions
        if markers is not None and not (
            isinstance(markers, list)
            and all(isinstance(n, str) for n in markers)
            and len(markers) == self.pipeline_.steps[0].n_points_
        ):
            raise StateError("markers_: expected none or one name per shape point")
        require_types(self, pipeline_=FeaturePipeline, chain_=BehaviourChain)
        width = self.pipeline_.output_width()
        check_shape("chain_.state_prototypes_", self.chain_.state_prototypes_, (None, width))
        check_shape("mean_shape_", self.mean_shape_, (self.chain_.dim,))
        stance = getattr(self, "stance_", None)  # absent from files of older versions
        if stance is not None:
            check_positive("stance_ (sizes)", check_shape("stance_", stance, (2, 2))[:, 0])
        skeletons = self.skeletons_
        if skeletons is not None and not (
            isinstance(skeletons, list)
            and len(skeletons) == 2
            and all(isinstance(s, Skeleton) for s in skeletons)
        ):
            raise StateError("skeletons_: expected none or a skeleton for each of two people")
        check_positive("fps_", self.fps_)

    @property
    def uses_markers(self) -> bool:
        """Whether the model sees people as named markers (and answers with Markers)."""
        return getattr(self, "markers_", None) is not None

    @property
    def source(self) -> str:
        """``mocap`` (a model of 3-D joint shapes) or ``silhouette`` (of tracked outlines)."""
        return "mocap" if self.shape_step.n_dims_ == 3 else "silhouette"

    @property
    def shape_step(self) -> JointShape:
        return self.pipeline_.steps[0]

    @staticmethod
    def people(person: int | None) -> tuple[int, ...]:
        """The halves of the model the real person may be: ``person``, or either if None
        (ValueError for anything but 0, 1 or None)."""
        if person not in (None, 0, 1) or isinstance(person, bool):
            raise ValueError(f"person must be 0 (A), 1 (B) or None (either), got {person!r}")
        return (0, 1) if person is None else (int(person),)

    def roles(self, person: int | None) -> list[slice]:
        """Columns of C the real person may match: its own half, or either (eq. 18) if None."""
        return [self.shape_step.person_slice(p) for p in self.people(person)]

    def observe(self, real: Person, person: int | None = None) -> np.ndarray:
        """(T, KD) the real person's shape vectors S^H, centred (``normalise="person"``, on
        the mean shape of ``person``'s half: :meth:`ShapeCentre.person`), smoothed and
        scaled like C."""
        s = self.shape_step.shape_vectors(real)
        if self.shape_centre is not None:
            s = self.shape_centre.person(s, person)
        smoothing = next(st for st in self.pipeline_.steps if isinstance(st, TemporalSmoothing))
        return self.scaled(smoothing.transform([s])[0])

    @property
    def shape_centre(self) -> ShapeCentre | None:
        """The pipeline's :class:`ShapeCentre` (``normalise="person"``), else None."""
        return next((st for st in self.pipeline_.steps if isinstance(st, ShapeCentre)), None)

    def scaled(self, s: np.ndarray) -> np.ndarray:
        """Smoothed shape vectors (..., KD) of one person mapped into C's [0, 1] range."""
        scaling = self.pipeline_.steps[-1]
        sl = self.shape_step.person_slice(0)
        return (s - scaling.min_[sl]) / scaling.scale_[sl]

    def propagator(
        self,
        person: int | None = None,
        n_hypotheses: int = 200,
        sigma: float = DEFAULT_SIGMA,
        response: str = DEFAULT_RESPONSE,
        map_radius: float | None = None,
        resync: float = DEFAULT_RESYNC,
        rng: np.random.Generator | int | None = None,
    ) -> Propagator:
        """Single-hypothesis propagation if ``n_hypotheses`` is 1 (re-synchronised with margin
        ``resync``), else CONDENSATION (§5).

        The propagator's roles index :meth:`people` of ``person``. ``rng`` (a
        Generator or a seed) drives extrapolation and resampling; default
        ``random_state``.
        """
        roles = self.roles(person)
        seed = self.random_state if rng is None else rng
        if n_hypotheses == 1:
            return SingleHypothesis(self.chain_, roles, resync, seed=seed)
        return MultipleHypotheses(
            self.chain_, roles, n_hypotheses, sigma, response, map_radius, seed=seed
        )

    def respond_shapes(self, real: Person, person: int | None = None, **options) -> PartnerResponse:
        """The virtual partner of ``real`` over a whole sequence (options: :meth:`propagator`).

        ``person`` is the real person's half of the model (0 or 1); None lets
        eq. (18) choose it at every frame (silhouettes: left or right).
        """
        shapes, matched, errors = self.propagator(person, **options).run(self.observe(real, person))
        roles = np.asarray(self.people(person))[matched]
        shapes = self.toward_mean(shapes)
        placed = self.place_average()(self.place(shapes, roles, real))
        return PartnerResponse(placed, shapes, roles, errors)

    def place_average(self) -> PlaceAverage:
        """A fresh :class:`PlaceAverage` over ``place_window`` frames (3-D; silhouettes: 1)."""
        window = int(self.place_window)
        return PlaceAverage(window if self.shape_step.n_dims_ == 3 else 1)

    def toward_mean(self, shapes: np.ndarray) -> np.ndarray:
        """Normalised combined shapes (T, d) pulled ``shrink`` of the way to ``mean_shape_``."""
        s = float(getattr(self, "shrink", 0.0))
        return shapes if s == 0.0 else (1.0 - s) * shapes + s * self.mean_shape_

    def check_input(self, motion: Motion | Markers) -> None:
        """Raise :class:`SkeletonMismatchError` unless this 3-D model can observe ``motion``:
        a skeleton with as many shape joints, or markers with every name of ``markers_``."""
        where = motion.name or ("markers" if isinstance(motion, Markers) else "motion")
        if self.uses_markers and isinstance(motion, Motion):
            try:
                self.as_markers(motion)
            except SkeletonMismatchError as exc:
                raise SkeletonMismatchError(f"{where}: {exc}") from None
            return
        if self.uses_markers or isinstance(motion, Markers):
            if not (self.uses_markers and isinstance(motion, Markers)):
                learnt = "markers" if self.uses_markers else "skeletons"
                raise SkeletonMismatchError(
                    f"{where}: the model was trained on {learnt}, not "
                    f"{'markers' if isinstance(motion, Markers) else 'a skeleton'}"
                )
            missing = find_markers(motion.names, self.markers_)[1]
            if missing:
                raise SkeletonMismatchError(f"{where}: {not_found(motion.names, missing)}")
            return
        try:
            joints = shape_joints(motion.skeleton, self.shape_names)
        except SkeletonMismatchError as exc:
            raise SkeletonMismatchError(f"{where}: {exc}") from None
        if len(joints) != self.shape_step.n_points_ or self.shape_step.n_dims_ != 3:
            raise SkeletonMismatchError(
                f"{where}: {len(joints)} shape joints, but the model was "
                f"trained on {self.shape_step.n_points_} in {self.shape_step.n_dims_}-D"
            )

    @property
    def shape_names(self) -> list[str] | None:
        """The names of the shape joints a skeleton model learnt, in its features' order (a
        skeleton's joints are matched by these names, not by their count); None for markers
        and for models fitted on prepared takes."""
        skeletons = getattr(self, "skeletons_", None)
        if self.uses_markers or not skeletons:
            return None
        learnt = skeletons[0]  # the shape joints alone: shape_joints gives their order
        return [learnt.names[j] for j in shape_joints(learnt)]

    def _seen_by(self, motion: Motion | Markers) -> list[str] | None:
        """What :func:`~markovmotion.features.joint_shape.person_from_take` picks of
        ``motion``: the model's markers, or a skeleton's shape joints by the model's names."""
        if self.uses_markers:
            return self.markers_
        return self.shape_names if isinstance(motion, Motion) else None

    def partner_skeleton(self, motion: Motion | None = None, person: int = 0) -> Skeleton:
        """The skeleton the partner of ``person`` is written on: the partner's own shape joints
        from training, or (models fitted on prepared takes) those of the real ``motion``."""
        if getattr(self, "skeletons_", None):
            return self.skeletons_[1 - person]
        if motion is None:
            raise MarkovMotionError(
                "this model has no partner skeleton (fitted on prepared takes): "
                "refit it on motion-capture pairs"
            )
        return joints_skeleton(motion.skeleton, shape_joints(motion.skeleton))

    def as_markers(self, motion: Motion | Markers) -> Markers:
        """A model of markers' view of ``motion``: Markers as they are; a skeleton's joints of
        the body points the markers name (``TORSO``, ``R_HAND``...,
        :func:`~markovmotion.features.markers.named_body_points`). No lift is needed (unlike
        the dual HMM's, :class:`~markovmotion.features.markers.Lift`): the partner is placed
        about A's marker centroid, height included (:func:`person_from_markers`)."""
        if isinstance(motion, Markers):
            return motion
        return named_body_points(motion, self.markers_)

    def person(self, take: Motion | Markers) -> Person:
        """One captured person as the model sees it (its shape joints or markers), at the
        take's own rate (:func:`~markovmotion.features.joint_shape.person_from_take`)."""
        return person_from_take(take, self._seen_by(take))

    def two_people(self, a: Motion | Markers, b: Motion | Markers) -> TwoPeople:
        """Both people of a take as the model sees them, at its rate ``fps_``."""
        return TwoPeople.from_motions(a, b, self.fps_, self._seen_by(a))

    def respond(
        self,
        motion: Motion | Markers,
        person: int = 0,
        rng: np.random.Generator | int | None = None,
        **options,
    ) -> Motion | Markers:
        """The 3-D partner of a captured person over the whole of ``motion``, at ``fps_``.

        ``motion`` is resampled to the model's rate. The partner's joint
        positions are turned into rotations by inverse kinematics on the
        partner's skeleton (:meth:`partner_skeleton`); a marker model answers with
        the partner's markers (``markers_``, mm). ``options``: those of
        :meth:`propagator` (``n_hypotheses``, ``sigma``, ``response``, ``resync``).
        ``person``: which of the pair the captured person is, 0 (A) or 1 (B); the partner is
        written on the other's skeleton, so "either" (None, as for silhouettes) is refused.
        """
        if person is None:  # checked before any work
            raise ValueError(
                "person must be 0 (A) or 1 (B) for a 3-D partner (None, either, is for "
                "silhouettes: respond_shapes)"
            )
        self.people(person)
        self.check_input(motion)
        motion = (self.as_markers(motion) if self.uses_markers else motion).resample(self.fps_)
        resp = self.respond_shapes(self.person(motion), person, rng=rng, **options)
        name = f"partner of {motion.name}" if motion.name else "virtual partner"
        if isinstance(motion, Markers):
            return Markers(tuple(self.markers_), resp.partner.points, self.fps_, name)
        skeleton = self.partner_skeleton(motion, person)
        out = fit_rotations(skeleton, resp.partner.points, fps=self.fps_)
        out.name = name
        return out

    def partner(
        self,
        person: int = 0,
        rng: np.random.Generator | int | None = None,
        size: float | None = None,
        **options,
    ) -> ChainPartner:
        """An online partner (:class:`ChainPartner`) answering ``person`` frame by frame
        (``size``: a marker model's size of the person, :class:`ChainPartner`)."""
        return ChainPartner(self, person, rng, size=size, **options)

    def place(self, shapes: np.ndarray, roles: np.ndarray, real: Person) -> Person:
        """Partners of ``real`` from normalised combined shapes (T, d), real person's roles (T,)."""
        scaling = self.pipeline_.steps[-1]
        d = shapes.shape[1]
        c = shapes * scaling.scale_[:d] + scaling.min_[:d]
        roles = np.asarray(roles)
        if np.all(roles == roles[0]):
            return self.shape_step.place(c, int(roles[0]), real)
        left, right = (self.shape_step.place(c, r, real) for r in (0, 1))

        def pick(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return np.where((roles == 0).reshape((-1,) + (1,) * (a.ndim - 1)), a, b)

        return Person(
            pick(left.points, right.points),
            pick(left.reference, right.reference),
            pick(left.height, right.height),
            pick(left.heading, right.heading),
        )

    def centre_roles(self, real: Person) -> np.ndarray:
        """(T,) the real person's half guessed from where it stands: the left-hand individual
        (0) left of the middle of the training takes' floor (``centre_``), else 1."""
        return (real.reference[:, 0] > self.centre_).astype(int)

    def mean_partner(self, real: Person, roles: np.ndarray) -> Person:
        """Baseline: the partner's mean shape, separation and scale placed beside ``real``."""
        shapes = np.broadcast_to(self.mean_shape_, (real.n_frames, len(self.mean_shape_)))
        return self.place(shapes, np.asarray(roles), real)


class PlaceAverage:
    """Where a 3-D partner stands and faces, averaged over its last ``window`` frames
    (causal: the online partner has no later response to average), its body moved and
    turned with it (our addition, ``VirtualPartner(place_window=...)``).

    Call it on the partner's frames in order (one or many at a time: the same frames give
    the same result to the bit, so the online partner streams :meth:`VirtualPartner.respond`'s
    frames). The reference point's place on the floor (x, z) is averaged by its mean, the
    heading by the direction of the mean unit vector (as the dual HMM's
    :func:`~markovmotion.models.hmm.trellis.smooth_place` averages A's ground frame); its
    height and the body about it are left as they are, so the partner's pose, measured
    body-centred (heights kept), does not change. ``window`` 1 returns the frames as they are.
    """

    def __init__(self, window: int = 1):
        self.window = int(window)
        self._rows: deque = deque(maxlen=max(self.window, 1))  # place_rows: x, z, cos, sin

    def __call__(self, partner: Person) -> Person:
        """``partner``'s frames, which follow those given before, about the averaged place."""
        if self.window <= 1:
            return partner
        points = np.empty_like(partner.points)
        reference = partner.reference.copy()
        heading = np.empty_like(partner.heading)
        rows = place_rows(partner.reference[:, [0, 2]], partner.heading)  # on the floor
        for t in range(partner.n_frames):  # frame by frame, as online
            ref, yaw = partner.reference[t], partner.heading[t]
            self._rows.append(rows[t])
            reference[t, [0, 2]], heading[t] = mean_place(np.mean(np.asarray(self._rows), axis=0))
            body = rotate_yaw(partner.points[t] - ref, -yaw)  # in the partner's own frame
            points[t] = reference[t] + rotate_yaw(body, heading[t])
        return Person(points, reference, partner.height, heading)


def _take_record(take: TwoPeople) -> dict[str, str]:
    """What :meth:`VirtualPartner.fit` records of a prepared take: its name and a points hash."""
    digest = hashlib.sha256(np.ascontiguousarray(take.points, dtype=np.float64).tobytes())
    return {"file": take.name or "(in memory)", "sha256": digest.hexdigest()}


class ChainPartner:
    """The behaviour chain's virtual partner online (:class:`markovmotion.models.online.OnlinePartner`).

    Each frame of A gives its shape vector S^H (§2); the propagator
    (:mod:`markovmotion.models.chain.condensation`) steps once on it (§5) and
    the chosen hypothesis's other half is placed beside A and written on the
    partner's skeleton by inverse kinematics. The model smooths shapes over a
    centred window of ``window`` frames, so B's frame for A's frame t comes
    when frame t + ``lag`` has arrived (``lag = window - 1 - window // 2``, 2
    frames = 0.08 s at 25 fps with the paper's w = 5); over a whole motion the
    frames equal :meth:`VirtualPartner.respond`'s. A missing or dropped frame
    repeats A's last one. A frame before A is first seen (a camera that sees no one yet)
    is answered, in its turn, with the training people's mean shape beside a stand-in A
    (:meth:`unseen`): the same frame every time, nothing propagated, so that the
    propagation starts afresh at A's first frame (the frames from there are those
    :meth:`VirtualPartner.respond` gives for A's frames alone) and, as with the dual HMM's
    partner, every frame of the stream (N calls of :meth:`step`, :meth:`skip`, then
    :meth:`finish`) gets its B frame, in order.

    A model of markers takes A's one-frame Markers and answers with B's markers
    (``markers_``). The person's size (:func:`marker_size`, which a whole take gives
    at once) is ``size`` if known, else the median of the frames' sizes so far: causal,
    and once the take is in, the size :meth:`VirtualPartner.respond` uses (with
    ``size`` given, the frames equal respond's). A frame with a marker unseen counts
    as missing (respond fills such gaps over time; online the future is not there).
    """

    def __init__(
        self,
        model: VirtualPartner,
        person: int = 0,
        rng: np.random.Generator | int | None = None,
        size: float | None = None,
        **options,
    ):
        if model.shape_step.n_dims_ != 3:
            raise MarkovMotionError(
                "an online partner needs a model of 3-D people (skeletons or markers), "
                "not of silhouettes"
            )
        if size is not None and not (np.isfinite(size) and size > 0):
            raise ValueError(f"size must be a positive number of mm, got {size}")
        self.model = model
        self.person = person
        self.fps = model.fps_
        w = self._window = int(model.window)
        self._behind = w // 2  # frames of the centred window before its frame
        self.lag = w - 1 - self._behind
        self._markers = list(model.markers_) if model.uses_markers else None
        self._size, self._sizes = size, []  # markers: the size given, or each frame's
        if self._markers is not None:
            self._skeleton = None
            self._place_step = MarkerFeatures().fit(
                [Markers(tuple(self._markers), np.zeros((1, len(self._markers), 3)), self.fps)]
            )
        else:
            self._skeleton = model.partner_skeleton(None, person)
        centre = model.shape_centre
        self._centre = None if centre is None else centre.online(person)
        self._propagator = model.propagator(person, rng=rng, **options)
        self._propagator.reset()
        self._place = model.place_average()  # B's place averaged over its last frames
        self._shapes: deque = deque(maxlen=w)  # A's last raw shape vectors
        self._people: deque = deque(maxlen=self.lag + 1)  # A's last frames (Person)
        self._first: np.ndarray | None = None
        self._last: Motion | None = None
        self._checked = CheckedOnce(model.check_input)  # A against the model, once a kind
        self._height: tuple[Skeleton, np.ndarray] | None = None
        self._frames_in = 0  # A's frames seen (and repeated) since A was first seen
        self._before = 0  # the stream's frames before A was first seen
        self._stand_in: Motion | Markers | None = None  # B's answer to them (unseen)
        # whether a stand-in A can be made (a file saved before stance_ without a size: no)
        self._stands_in = getattr(model, "stance_", None) is not None or size is not None
        self._missing = MissingFrames()  # frames of A missing (the first logged)
        self._finished = False

    @property
    def skeleton(self) -> Skeleton | None:
        """B's skeleton (the partner's shape joints; None for a model of markers)."""
        return self._skeleton

    def step(self, frame: Motion | Markers | None) -> Motion | Markers | None:
        """One frame of A in (None: missing); B's frame for ``lag`` frames ago out. A frame at
        another rate than the partner's, not one frame, or after :meth:`finish`: a ValueError
        (:func:`check_frame`). A missing frame (None, NaN, a marker unseen) is skipped
        (:meth:`skip`), with a logged warning (once per stream: :class:`MissingFrames`)."""
        if self._finished:
            raise ValueError(FINISHED)
        if frame is None:
            return self._skip_missing()
        check_frame(frame, self.fps)
        self._checked(frame)
        if self._markers is not None and isinstance(frame, Motion):
            frame = self.model.as_markers(frame)  # a skeleton's body points by name
        if isinstance(frame, Markers):
            pos = frame.select(self._markers).positions
            if not np.isfinite(pos).all():
                return self._skip_missing()
            real = self._marker_person(pos)
        elif np.isfinite(frame.rotations).all() and np.isfinite(frame.translations).all():
            real = self._person(frame)
        else:
            return self._skip_missing()
        self._last = frame
        s = self.model.shape_step.shape_vectors(real)[0]
        if self._centre is not None:  # normalise="person": as observe centres a whole take
            s = self._centre(s)
        if self._first is None:
            self._first = s
        self._shapes.append(s)
        self._people.append(real)
        self._frames_in += 1
        return self._due()

    def _due(self) -> Motion | Markers | None:
        """B's frame for the stream's frame ``lag`` frames before its newest (None while the
        window fills): the stand-in's answer for a frame before A was first seen, else the
        propagated partner of A's frame (A's frames counted from A's first)."""
        t = self._before + self._frames_in - 1 - self.lag
        if t < 0:
            return None
        return self._owed(t)

    def _owed(self, t: int) -> Motion | Markers:
        """B's frame for the stream's frame ``t`` (in order, each once)."""
        if t < self._before:
            return self._unseen_answer()
        return self._answer(t - self._before, self._frames_in - 1)

    def unseen(self) -> Person | None:
        """The stand-in for A before A's first frame (a stream that starts with frames
        missing: the camera sees no one yet): standing at the origin facing +Z, of the
        training people's median size and reference height (``stance_``; the ``size``
        given, if any), as the dual HMM's partner answers from its dynamics alone, placed at
        the origin. B beside it is the training people's mean shape
        (:meth:`VirtualPartner.mean_partner`), the same frame for every such frame; nothing
        is propagated. None for a model saved before it learnt ``stance_`` (then nothing is
        answered before A is seen) unless ``size`` is given."""
        if not self._stands_in:
            return None
        model, p = self.model, self.person or 0
        stance = getattr(model, "stance_", None)
        size, level = stance[p] if stance is not None else (self._size, 0.0)
        size = self._size if self._size is not None else size
        shape = model.shape_step
        where = np.zeros((1, shape.n_dims_))
        where[0, 1] = level
        nobody = np.zeros((1, shape.n_points_, shape.n_dims_))
        return Person(nobody, where, np.array([float(size)]), np.zeros(1))

    def _unseen_answer(self) -> Motion | Markers:
        """B's frame for a frame before A was first seen: the mean shape beside
        :meth:`unseen`'s stand-in (made once; each answer its own copy)."""
        if self._stand_in is None:
            role = np.asarray(self.model.people(self.person))
            placed = self.model.mean_partner(self.unseen(), role)
            if self._markers is not None:
                self._stand_in = Markers(
                    tuple(self._markers), placed.points, self.fps, "virtual partner"
                )
            else:
                self._stand_in = fit_rotations(self._skeleton, placed.points, fps=self.fps)
        return self._stand_in.copy()

    def _person(self, frame: Motion) -> Person:
        """:func:`person_from_motion` of one frame, the rest-pose height computed once."""
        if self._height is None or frame.skeleton is not self._height[0]:
            self._height = (frame.skeleton, person_from_motion(frame).height)
        pos = frame.positions()
        ref = pos[:, frame.skeleton.body_root].copy()
        ref[:, 1] = 0.0
        joints = shape_joints(frame.skeleton, self.model.shape_names)
        return Person(pos[:, joints], ref, self._height[1], frame.heading(pos))

    def _marker_person(self, pos: np.ndarray) -> Person:
        """:func:`person_from_markers` of one frame (1, M, 3): the size given, or the median
        of every frame's so far (:func:`marker_size` of the frames seen)."""
        self._sizes.append(marker_size(pos))
        size = self._size if self._size is not None else float(np.median(self._sizes))
        _, yaw = self._place_step.place(pos)
        return Person(pos, pos.mean(axis=1), np.full(1, size), yaw)

    def _skip_missing(self) -> Motion | Markers | None:
        """A frame of A given missing: the warning (the stream's first), then :meth:`skip`."""
        self._missing(self._before + self._frames_in)
        return self.skip()

    def skip(self) -> Motion | Markers | None:
        """A frame that did not come in time: A's last frame again (before A's first, a frame
        of the stream answered by the mean shape beside a stand-in A: :meth:`unseen`)."""
        if self._last is not None:
            return self.step(self._last)
        if self._finished:
            raise ValueError(FINISHED)
        if not self._stands_in:  # a model file without stance_: nothing before A
            return None
        self._before += 1
        return self._due()

    def drop(self) -> None:
        """A frame a caller dropped and will not show B's answer for: :meth:`skip`, its
        answer unused (the propagation must go on frame by frame)."""
        self.skip()

    def finish(self) -> list[Motion | Markers]:
        """B's frames still owed at the end of the stream (the window's edge repeats A's
        last); the stream ends (a later :meth:`step`, :meth:`skip` or :meth:`drop` is a
        ValueError)."""
        if self._finished:
            raise ValueError(FINISHED)
        self._finished = True
        n = self._before + self._frames_in
        return [self._owed(t) for t in range(max(n - self.lag, 0), n)]

    def _answer(self, t: int, newest: int) -> Motion | Markers:
        """B's frame for A's frame ``t``, given A's frames up to ``newest``."""
        shapes = list(self._shapes)  # A's frames newest - len + 1 .. newest
        oldest = newest - len(shapes) + 1
        rows = []
        for i in range(t - self._behind, t - self._behind + self._window):
            i = min(max(i, 0), newest)
            rows.append(self._first if i < oldest else shapes[i - oldest])
        r = self._propagator.step(self.model.scaled(np.mean(rows, axis=0)))
        real = self._people[t - (newest - len(self._people) + 1)]
        role = np.asarray(self.model.people(self.person))[[r.role]]
        placed = self._place(self.model.place(self.model.toward_mean(r.shape[None]), role, real))
        if self._markers is not None:
            return Markers(tuple(self._markers), placed.points, self.fps, "virtual partner")
        return fit_rotations(self._skeleton, placed.points, fps=self.fps)

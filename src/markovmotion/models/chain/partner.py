"""The interaction model of the interaction paper, end to end: two people in, a partner out.

:class:`VirtualPartner` chains the joint shape features (§2), the behaviour
chain (§3-4) and hypothesis propagation (§5): trained on two-person takes
(silhouettes tracked in video or 3-D motion capture), it answers one real
person's observed shapes with the partner's shapes, placed in the image or the
world from the real person's position and height.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.base import BaseEstimator

from markovmotion.algorithms.kinematics import fit_rotations
from markovmotion.core.motion import Motion
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features.joint_shape import (
    JointShape,
    Person,
    TwoPeople,
    joint_shape_pipeline,
    joints_skeleton,
    person_from_motion,
    shape_joints,
)
from markovmotion.models.chain.behaviour_chain import BehaviourChain
from markovmotion.models.chain.condensation import (
    DEFAULT_RESPONSE,
    DEFAULT_RESYNC,
    DEFAULT_SIGMA,
    MultipleHypotheses,
    Propagator,
    SingleHypothesis,
)
from markovmotion.persist import load_npz, save_npz
from markovmotion.state import estimator_state, register, restore_estimator

KIND = "behaviour-chain"
#: State and behaviour prototypes unless told. The paper's 300 each (for its handshakes)
#: give partners that lose to the mean shape on the eight salsa training takes; 40 each
#: was the best of 20-300 by leave-one-take-out over them (see the README).
DEFAULT_PROTOTYPES = 40


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


@register
class VirtualPartner(BaseEstimator):
    """Interaction model: joint shape vectors, behaviour chain, virtual partner (§2-5).

    Args:
        window: smoothing window w (paper: 5).
        lam: derivative weight lambda of F = [C, lambda dC] (paper: 10).
        n_state_prototypes, n_behaviour_prototypes, gamma, n_epochs,
        interval_noise, random_state: passed to :class:`BehaviourChain`.

    Learnt: ``pipeline_`` (TwoPeople -> state vectors), ``chain_``,
    ``mean_shape_`` (d,) the mean normalised combined shape (the baseline
    partner), ``fps_``.
    """

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
    ):
        self.window = window
        self.lam = lam
        self.n_state_prototypes = n_state_prototypes
        self.n_behaviour_prototypes = n_behaviour_prototypes
        self.gamma = gamma
        self.n_epochs = n_epochs
        self.interval_noise = interval_noise
        self.random_state = random_state

    def fit(self, takes: Sequence[TwoPeople]) -> VirtualPartner:
        """Learn the feature ranges, both prototype sets and the chain from two-person takes."""
        self.pipeline_ = joint_shape_pipeline(takes, self.window, self.lam)
        states = self.pipeline_.fit_transform(takes)
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
        self.centre_ = float(
            np.median(np.concatenate([t.reference[..., 0].ravel() for t in takes]))
        )
        self.fps_ = float(takes[0].fps)
        return self

    @property
    def shape_step(self) -> JointShape:
        return self.pipeline_.steps[0]

    @staticmethod
    def people(person: int | None) -> tuple[int, ...]:
        """The halves of the model the real person may be: ``person``, or either if None."""
        return (0, 1) if person is None else (person,)

    def roles(self, person: int | None) -> list[slice]:
        """Columns of C the real person may match: its own half, or either (eq. 18) if None."""
        return [self.shape_step.person_slice(p) for p in self.people(person)]

    def observe(self, real: Person) -> np.ndarray:
        """(T, KD) the real person's shape vectors S^H, smoothed and normalised like C."""
        _, smoothing, scaling = self.pipeline_.steps
        s = smoothing.transform([self.shape_step.shape_vectors(real)])[0]
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
        seed: int = 0,
    ) -> Propagator:
        """Single-hypothesis propagation if ``n_hypotheses`` is 1 (re-synchronised with margin
        ``resync``), else CONDENSATION (§5).

        The propagator's roles index :meth:`people` of ``person``.
        """
        roles = self.roles(person)
        if n_hypotheses == 1:
            return SingleHypothesis(self.chain_, roles, resync, seed=seed)
        return MultipleHypotheses(
            self.chain_, roles, n_hypotheses, sigma, response, map_radius, seed=seed
        )

    def respond(self, real: Person, person: int | None = None, **options) -> PartnerResponse:
        """The virtual partner of ``real`` over a whole sequence (options: :meth:`propagator`).

        ``person`` is the real person's half of the model (0 or 1); None lets
        eq. (18) choose it at every frame (silhouettes: left or right).
        """
        shapes, matched, errors = self.propagator(person, **options).run(self.observe(real))
        roles = np.asarray(self.people(person))[matched]
        return PartnerResponse(self.place(shapes, roles, real), shapes, roles, errors)

    def respond_motion(self, motion: Motion, person: int = 0, **options) -> Motion:
        """The 3-D partner of a captured person, as a motion of that person's major joints.

        The partner's joint positions are turned into rotations by inverse
        kinematics on the skeleton of the shape joints (the real person's bone
        lengths; the partner's own relative scale is not kept).
        """
        joints = shape_joints(motion.skeleton)
        if len(joints) != self.shape_step.n_points_ or self.shape_step.n_dims_ != 3:
            raise SkeletonMismatchError(
                f"{motion.name or 'motion'}: {len(joints)} shape joints, but the model was "
                f"trained on {self.shape_step.n_points_} in {self.shape_step.n_dims_}-D"
            )
        resp = self.respond(person_from_motion(motion), person, **options)
        skeleton = joints_skeleton(motion.skeleton, joints)
        return fit_rotations(skeleton, resp.partner.points, fps=motion.fps)

    def place(self, shapes: np.ndarray, roles: np.ndarray, real: Person) -> Person:
        """Partners of ``real`` from normalised combined shapes (T, d), real person's roles (T,)."""
        _, _, scaling = self.pipeline_.steps
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

    # ------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str], source: str = "mocap") -> None:
        """Write the model as ``.npz`` arrays + JSON header."""
        arrays: dict[str, np.ndarray] = {}
        header = {"source": source, "model": estimator_state(self, "model", arrays)}
        save_npz(path, KIND, header, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> tuple[VirtualPartner, str]:
        """A model written by :meth:`save`, and its source (``mocap`` or ``silhouette``)."""
        header, arrays = load_npz(path, KIND)
        return restore_estimator(header["model"], arrays), header.get("source", "mocap")

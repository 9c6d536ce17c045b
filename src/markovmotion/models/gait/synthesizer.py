"""Stylistic gait synthesis with HSMMs: train, adapt, generate, score, save (gait paper §4-5).

:class:`GaitSynthesizer` turns walks into exponential maps of every rotating
joint (root translation dropped, each walk turned to travel along +Z, §4;
rotations taken relative to the mean pose, far from the exponential map's
singularity: :class:`~markovmotion.features.reference_pose.ReferencePose`),
appends delta and delta-delta features (eqs. 2-3), cuts the walks into steps
at heel strikes (:mod:`markovmotion.features.gait`), and trains
context-dependent five-state HSMMs of left and right steps
(:class:`~markovmotion.models.gait.hsmm.HSMM`). Synthesis concatenates the step
models of the walk asked for, takes state durations from the duration
densities, generates the joint angles by MLPG with global variance
(:mod:`markovmotion.algorithms.mlpg`) and computes the root travel from foot
contact (§5.1.4).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from markovmotion.algorithms.hsmm_recursions import chain_cells
from markovmotion.algorithms.mlpg import global_variance, mlpg, mlpg_gv
from markovmotion.core.motion import Motion
from markovmotion.core.words import first_names
from markovmotion.data.kinds import counted
from markovmotion.errors import DataNotFoundError, MotionFormatError, SkeletonMismatchError
from markovmotion.features import ExpMaps, FeaturePipeline, add_deltas
from markovmotion.features.gait import (
    CONTEXTS,
    SIDES,
    align_walk,
    context_id,
    context_questions,
    detect_steps,
    foot_joints,
    root_from_contact,
    step_positions,
)
from markovmotion.features.reference_pose import ReferencePose
from markovmotion.limits import MAX_STEPS, check_length, max_values
from markovmotion.models.base import Model
from markovmotion.models.gait.adaptation import adapt, walker_adaptive_training
from markovmotion.models.gait.hsmm import DUR_VAR_FLOOR, HSMM
from markovmotion.progress import note
from markovmotion.state import (
    StateError,
    check_positive,
    check_shape,
    is_fitted,
    require,
    require_types,
)

KIND = "gait-hsmm"
WAT_UNITS = ("none", "take", "unit")
ROLES = ("average", "adapted", "scratch")


@dataclass
class WalkSet:
    """Walks as HSMM training data: observations from the first to the last heel strike.

    Attributes:
        names: one per walk (file names).
        obs: (T_i, 3D) [static, delta, delta-delta] exponential maps.
        contexts: (n_i,) context id of each step (:data:`~markovmotion.features.gait.CONTEXTS`).
        boundaries: (n_i + 1,) first frame of each step in ``obs``, then T_i.
        floor: height in mm of the lowest foot point when standing (median over frames).
    """

    names: list[str]
    obs: list[np.ndarray]
    contexts: list[np.ndarray]
    boundaries: list[np.ndarray]
    floor: float = 0.0
    units: list[str] = field(default_factory=list)

    @property
    def n_steps(self) -> int:
        return int(sum(len(c) for c in self.contexts))

    def first_steps(self, n_steps: int | None) -> WalkSet:
        """The first ``n_steps`` steps, walk after walk (the last walk cut short; contexts kept).

        Raises:
            DataNotFoundError: the walks hold fewer than ``n_steps`` steps.
        """
        if n_steps is None:
            return self
        if n_steps > self.n_steps:
            raise DataNotFoundError(
                f"{', '.join(self.names[:3])}{', ...' if len(self.names) > 3 else ''}: "
                f"{n_steps} steps asked, only {self.n_steps} found in "
                f"{counted(len(self.names), 'walks')}"
            )
        out = WalkSet([], [], [], [], self.floor, [])
        left = n_steps
        for i, (name, x, c, b) in enumerate(
            zip(self.names, self.obs, self.contexts, self.boundaries, strict=True)
        ):
            if left <= 0:
                break
            k = min(left, len(c))
            out.names.append(name)
            out.obs.append(x[: b[k]])
            out.contexts.append(c[:k])
            out.boundaries.append(b[: k + 1])
            out.units.append(self.units[i] if self.units else name)
            left -= k
        return out

    def gv(self) -> np.ndarray:
        """(walks, D) global variance of the static features of each walk (eq. 14)."""
        return np.array([global_variance(x[:, : x.shape[1] // 3]) for x in self.obs])


def step_chunks(boundaries: np.ndarray, n_states: int) -> list[tuple[int, int]]:
    """Runs of consecutive steps ``[start, stop)`` of a walk with these step ``boundaries``
    (n + 1,), each small enough to score as one chain (frames x states within
    ``MARKOVMOTION_MAX_VALUES``, :func:`~markovmotion.algorithms.hsmm_recursions.check_chain`).
    A walk of ordinary length is one run, scored exactly; a long one (a 10,000-frame walk is
    2,900 chain states: its arrays grow with the square of its length) is cut at heel strikes,
    its steps' boundaries there taken as detected."""
    cap = max_values()
    n = len(boundaries) - 1
    out, start = [], 0
    while start < n:
        stop = start + 1
        while stop < n and (
            chain_cells(
                int(boundaries[stop + 1] - boundaries[start]), (stop + 1 - start) * n_states
            )
            <= cap
        ):
            stop += 1
        out.append((start, stop))
        start = stop
    return out


def walk_set(
    motions: Sequence[Motion], pipeline: FeaturePipeline, units: Sequence[str] | None = None
) -> WalkSet:
    """Align, segment and featurise walks with a fitted ``pipeline`` (Motion -> static features).

    Raises:
        MotionFormatError: a walk in which fewer than two heel strikes are found.
    """
    out = WalkSet([], [], [], [], 0.0, [])
    floors = []
    for i, m in enumerate(motions):
        aligned = align_walk(m)
        pos = aligned.positions()
        steps = detect_steps(aligned, pos)
        if steps.n_steps < 1:
            raise MotionFormatError(
                m.name or "walk", "no steps found (fewer than two heel strikes)"
            )
        b = steps.boundaries
        static = pipeline.transform([aligned])[0]
        out.names.append(m.name)
        out.obs.append(add_deltas(static)[b[0] : b[-1]])
        out.contexts.append(steps.contexts())
        out.boundaries.append(b - b[0])
        out.units.append(units[i] if units is not None else m.name)
        feet = [j for pair in foot_joints(aligned).values() for j in pair]
        floors.append(np.median(pos[:, feet, 1].min(axis=1)))
    out.floor = float(np.median(floors)) if floors else 0.0
    return out


def walks_with_steps(motions: Sequence[Motion], what: str = "walks") -> list[int]:
    """Indices of the walks in which steps are found (two heel strikes or more; :func:`walk_set`
    refuses the others); the others are named in one note, as walks of another skeleton are,
    so that one short take does not stop the rest.

    Raises:
        DataNotFoundError: no walk has a step (one line naming them).
    """
    kept, left = [], []
    for i, m in enumerate(motions):
        (kept if detect_steps(align_walk(m)).n_steps >= 1 else left).append(i)
    if not left:
        return kept
    shown = [f"{motions[i].name or f'walk {i}'} ({motions[i].n_frames} frames)" for i in left]
    named = first_names(shown)
    if not kept:
        raise DataNotFoundError(f"{named}: no steps found (fewer than two heel strikes)")
    note(f"{what} without steps (fewer than two heel strikes) left out: {named}")
    return kept


def walk_contexts(n_steps: int, first_side: str = "R") -> tuple[np.ndarray, tuple[str, ...]]:
    """Context ids and sides of a walk of ``n_steps`` steps, sides alternating from ``first_side``."""
    if first_side not in SIDES:
        raise ValueError(f"first_side must be one of {SIDES}")
    start = SIDES.index(first_side)
    sides = tuple(SIDES[(start + k) % 2] for k in range(n_steps))
    ids = [context_id(s, p) for s, p in zip(sides, step_positions(n_steps), strict=True)]
    return np.array(ids, dtype=int), sides


class GaitSynthesizer(Model):
    """An HSMM walk model with its feature pipeline and global-variance statistics.

    Args:
        n_states: HSMM states per step (5 in the paper).
        n_iter: EM iterations.
        mdl_factor: MDL weight of context clustering.
        var_floor: output variance floor as a fraction of the data variance.
        dur_var_floor: duration variance floor in frames squared, which
            adapted and from-scratch models keep.
        wat: walker-adaptive training (§5.1.2) with one transform per
            ``"take"``, per unit given to :meth:`fit` (``"unit"``: a walker, a
            dataset), or ``"none"``.
        random_state: seed of the durations :meth:`generate` draws when
            ``stochastic`` and no ``rng`` is given.

    Learnt: ``pipeline_`` (exponential maps), ``hsmm_``, ``gv_mean_``/``gv_var_``
    (D,) global variance Gaussian, ``floor_`` (mm), ``fps_``, and what it was
    trained on: ``role_``, ``style_``, ``n_steps_`` (steps of its own walks),
    ``train_files_`` (every walk it depends on, by content hash: an adapted or
    from-scratch model lists the average model's walks, whose reference pose
    it keeps, then its own), ``n_inherited_files_`` (how many of
    ``train_files_`` come from the average model; 0 for an average model).
    """

    KIND = KIND
    VERBS = ("generate", "score")
    TAKES = (Motion,)  # walks of a skeleton: its joints' rotations and heel strikes

    def __init__(
        self,
        n_states: int = 5,
        n_iter: int = 10,
        mdl_factor: float = 1.0,
        var_floor: float = 0.01,
        dur_var_floor: float = DUR_VAR_FLOOR,
        wat: str = "none",
        random_state: int | None = 0,
    ):
        self.n_states = n_states
        self.n_iter = n_iter
        self.mdl_factor = mdl_factor
        self.var_floor = var_floor
        self.dur_var_floor = dur_var_floor
        self.wat = wat
        self.random_state = random_state

    def fit(
        self,
        motions: Sequence[Motion],
        n_steps: int | None = None,
        style: str = "normal",
        role: str = "average",
        units: Sequence[str] | None = None,
    ) -> GaitSynthesizer:
        """Train on walks (all their steps, or the first ``n_steps``), of one skeleton.

        ``units`` names the adaptation unit of each walk for ``wat="unit"``.

        Raises:
            SkeletonMismatchError: walks on skeletons of other joints, named with what differs
                (it was NumPy's concatenation error).
        """
        if self.wat not in WAT_UNITS:
            raise ValueError(f"wat must be one of {WAT_UNITS}")
        if self.wat == "unit" and units is None:
            raise ValueError("walker-adaptive training by unit needs the unit of each walk")
        first = motions[0]
        for i, m in enumerate(motions[1:], 1):
            if (differs := first.skeleton.difference(m.skeleton)) is not None:
                raise SkeletonMismatchError(
                    f"GaitSynthesizer.fit: walk {i} ({m.name or 'unnamed'}) is not on the "
                    f"skeleton of walk 0 ({first.name or 'unnamed'}) {differs}: train on walks "
                    "of one skeleton",
                    reason=differs,
                )
        self.pipeline_ = FeaturePipeline([ReferencePose(), ExpMaps(root_position="none")])
        self.pipeline_.fit([align_walk(m) for m in motions])
        data = walk_set(motions, self.pipeline_, units).first_steps(n_steps)
        self.fit_walks(data, style=style, role=role)
        self.record_training(motions[: len(data.names)])
        self.n_inherited_files_ = 0
        return self

    def fit_walks(self, data: WalkSet, style: str, role: str) -> GaitSynthesizer:
        """Train the HSMM and GV statistics on prepared walks (``pipeline_`` already fitted)."""
        self.hsmm_ = HSMM(
            n_states=self.n_states,
            n_iter=self.n_iter,
            var_floor=self.var_floor,
            dur_var_floor=self.dur_var_floor,
            mdl_factor=self.mdl_factor,
        ).fit(data.obs, data.contexts, data.boundaries, len(CONTEXTS), context_questions())
        self.wat_units_ = []
        if self.wat != "none" and role == "average":
            units = data.names if self.wat == "take" else data.units
            walker_adaptive_training(self.hsmm_, data.obs, data.contexts, units)
            self.wat_units_ = sorted(set(units))
        self.set_gv(data.gv())
        self.floor_ = data.floor
        self.fps_ = float(self.pipeline_.steps[-1].fps_)
        self.role_, self.style_ = role, style
        self.n_steps_ = data.n_steps
        return self

    def _inherit_files(self, average: GaitSynthesizer, motions: Sequence[Motion]) -> None:
        """``train_files_``: the average model's, then those of ``motions`` (its own walks)."""
        self.record_training(motions)
        inherited = list(average.train_files_)
        self.train_files_ = inherited + self.train_files_
        self.n_inherited_files_ = len(inherited)

    def check_state(self) -> None:
        """The learnt parts a model file must hold, and that they fit: hsmm_ over every
        context, its observations the pipeline's D features with deltas (3D), the global
        variance Gaussian (D,) with positive variances."""
        if not is_fitted(self):
            return
        require(self, "train_files_", "gv_mean_", "gv_var_", "floor_", "fps_")
        require_types(self, pipeline_=FeaturePipeline, hsmm_=HSMM)
        d = len(check_shape("gv_mean_", self.gv_mean_, (self.pipeline_.output_width(),)))
        check_positive("gv_var_", check_shape("gv_var_", self.gv_var_, (d,)))
        check_shape("hsmm_.means_", self.hsmm_.means_, (None, 3 * d))
        check_shape("hsmm_.out_map_", self.hsmm_.out_map_, (len(CONTEXTS), None))
        if self.hsmm_.n_states != self.n_states:
            raise StateError(f"hsmm_: {self.hsmm_.n_states} states, n_states is {self.n_states}")
        check_positive("fps_", self.fps_)

    @property
    def own_files(self) -> list[str]:
        """File names of the walks whose steps this model was fitted or adapted on."""
        return [rec["file"] for rec in self.train_files_[self.n_inherited_files_ :]]

    def adapt(
        self,
        motions: Sequence[Motion],
        style: str,
        n_steps: int | None = None,
        **options: Any,
    ) -> GaitSynthesizer:
        """A style model: this (average) model adapted to the first ``n_steps`` steps of the walks (§5.1.3).

        Adaptation starts from the steps' boundaries, as training does.
        ``options`` go to :func:`markovmotion.models.gait.adaptation.adapt` (method,
        structure, prior weights). The GV mean comes from the style walks, its
        variance from this model.
        """
        data = self.walk_set(motions).first_steps(n_steps)
        longest = max(int(np.diff(b).max()) for b in data.boundaries)
        out = GaitSynthesizer(**self.get_params())
        out.pipeline_, out.floor_, out.fps_ = self.pipeline_, self.floor_, self.fps_
        out.hsmm_ = adapt(
            self.hsmm_,
            data.obs,
            data.contexts,
            max_duration=int(np.ceil(0.6 * longest)),
            boundaries=data.boundaries,
            **options,
        )
        out.set_gv(data.gv(), var=self.gv_var_)
        out.role_, out.style_ = "adapted", style
        out.n_steps_ = data.n_steps
        out._inherit_files(self, motions[: len(data.names)])
        return out

    def scratch(
        self, motions: Sequence[Motion], style: str, n_steps: int | None = None
    ) -> GaitSynthesizer:
        """A style model trained from scratch on the first ``n_steps`` steps, with this model's features.

        The comparison of §5.1.3: same data as :meth:`adapt`, same feature
        pipeline (so likelihoods compare), no average model.
        """
        out = GaitSynthesizer(**self.get_params())
        out.pipeline_ = self.pipeline_
        data = self.walk_set(motions).first_steps(n_steps)
        out.fit_walks(data, style, "scratch")
        out._inherit_files(self, motions[: len(data.names)])
        return out

    def set_gv(self, gv: np.ndarray, var: np.ndarray | None = None) -> None:
        """GV Gaussian from per-walk global variances (the variance may be given instead)."""
        self.gv_mean_ = gv.mean(axis=0)
        spread = gv.var(axis=0) if var is None else var
        self.gv_var_ = np.maximum(spread, np.maximum(0.01 * self.gv_mean_**2, 1e-12))

    def walk_set(self, motions: Sequence[Motion], units: Sequence[str] | None = None) -> WalkSet:
        """Walks prepared with this model's pipeline.

        Raises:
            SkeletonMismatchError: a walk on another skeleton than the model's, named with
                what differs (it failed deep in the features before).
        """
        skeleton = self.pipeline_.steps[-1].skeleton_
        for m in motions:
            skeleton.check_compatible(m.skeleton, f"walk {m.name or ''}".strip())
        return walk_set(motions, self.pipeline_, units)

    # ------------------------------------------------------------ synthesis
    def _rng(self, rng: np.random.Generator | None, stochastic: bool) -> np.random.Generator | None:
        """The generator durations are drawn with, or None for the most likely durations."""
        if not stochastic:
            return None
        return rng if rng is not None else np.random.default_rng(self.random_state)

    def generate_features(
        self,
        n_steps: int,
        speed: float = 1.0,
        gv: bool = True,
        first_side: str = "R",
        rng: np.random.Generator | None = None,
        stochastic: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """Static exponential maps (T, D), step boundaries and sides of a new walk (§5.1.4).

        State durations are the most likely ones at ``speed``, or, if
        ``stochastic``, drawn from the duration densities
        (:meth:`HSMM.durations`) with ``rng`` (default: a generator seeded
        with ``random_state``, 0 as in every family, so that the same call gives the same
        walk; give each walk its own ``rng`` for walks that differ).
        """
        n_steps = int(check_length(n_steps, 1, MAX_STEPS, "n_steps", integer=True))
        if speed <= 0:
            raise ValueError("speed must be positive")
        contexts, sides = walk_contexts(n_steps, first_side)
        durations = self.hsmm_.durations(contexts, speed, self._rng(rng, stochastic))
        means, variances = self.hsmm_.frame_parameters(contexts, durations)
        if gv:
            static = mlpg_gv(means, variances, self.gv_mean_, self.gv_var_)
        else:
            static = mlpg(means, variances)
        per_step = durations.reshape(n_steps, self.n_states).sum(axis=1)
        boundaries = np.concatenate([[0], np.cumsum(per_step)])
        return static, boundaries, sides

    def generate(
        self,
        n_steps: int = 12,
        speed: float = 1.0,
        gv: bool = True,
        first_side: str = "R",
        rng: np.random.Generator | None = None,
        stochastic: bool = False,
    ) -> Motion:
        """A new walk of ``n_steps`` steps, with its root travel from foot contact.

        ``stochastic``: state durations drawn with ``rng`` rather than the most
        likely ones (:meth:`generate_features`).
        """
        static, boundaries, sides = self.generate_features(
            n_steps, speed, gv, first_side, rng, stochastic
        )
        motion = self.pipeline_.inverse_transform([static])[0]
        motion = root_from_contact(motion, boundaries, sides, floor=self.floor_)
        motion.name = f"{self.style_} walk ({self.role_} model, {n_steps} steps)"
        return motion

    def score(self, motions: Sequence[Motion]) -> float:
        """HSMM log-likelihood per frame of the steps of real walks (first to last heel strike).

        The walks go through this model's own features, each step under the
        model of its context (side and position in the walk).
        """
        data = self.walk_set(motions)
        total = 0.0
        for x, contexts, bounds in zip(data.obs, data.contexts, data.boundaries, strict=True):
            for start, stop in step_chunks(bounds, self.hsmm_.n_states):
                frames = slice(bounds[start], bounds[stop])
                total += self.hsmm_.posteriors(x[frames], contexts[start:stop])[0]
        return float(total / sum(len(x) for x in data.obs))

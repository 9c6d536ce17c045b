"""Objective evaluation of synthesized stylistic walks, in place of the user study (gait paper §6).

A style classifier stands in for the evaluators of §6.3. It sees one step at
a time: the mean and standard deviation of each exponential map over the
step and the step's duration, standardised; a logistic regression on the
first ``n_components`` principal components of these statistics, trained on
the steps of real training takes only. The styles of Bandai dataset-2 are so
far apart that the regression on all the statistics recognises every real
held-out step, which leaves no room to tell models apart; with
``n_components="auto"`` the classifier keeps the fewest components whose
recognition of real steps, cross-validated over the training takes (folds by
take), reaches ``target`` (90 %); every component when no fold can train on two styles
(of two, one has a single take). Held-out takes play no part in that choice.
The full classifier's rates are reported beside.

Reported, per kind of model (adapted, average, from scratch) and per number
of adaptation steps:

- step recognition rates of real held-out walks and of synthesized walks of
  the same styles (the mean over styles of each style's rate), with 95 %
  bootstrap intervals (within each style, the models are resampled, then
  the walks of each), walk recognition rates (summed step log posteriors),
  the confusion matrix of steps (Table 2) and the recognition efficiency
  eta = rate / chance (eq. 16);
- the distance of synthesized steps to the nearest real held-out step of the
  same style and side, after dynamic time warping: exponential-map RMSE (rad)
  and mean joint-position error (mm, body-centred, joints from the pelvis down);
- foot sliding: ground-plane travel of the stance foot per step (mm);
- the global-variance ratio synthesized / real (sum over dimensions);
- the log-likelihood per frame of the real held-out walks under the model;
- how well a machine tells synthesized steps from real held-out steps of
  the style (the naturalness test of §6.2, :func:`real_vs_synthesized`): the
  balanced accuracy of a logistic regression on all the step statistics,
  cross-validated with folds by walk; 0.5 means indistinguishable. Unlike
  the recognition rate it does not saturate on these well-separated styles.

Every model walks ``n_walks`` walks of ``walk_steps`` steps, starting on
either foot in turn, with state durations drawn from its duration densities
and a pace drawn within ``speed_jitter`` of its mean (the spread of the mean
step duration between real takes of a style is 2-6 %). The random numbers of
a style's walks are the same for every model, so that the comparison of two
models is paired. As a function of the number K of adaptation steps
(:meth:`Evaluation.sweep`), each style gets ``replicates`` adapted models and
as many from-scratch ones, replicate r from the first K steps of the
training takes that follow those of replicate r - 1; the adapted and the
from-scratch model of a replicate see the same K steps. The same
discriminator that tells synthesized from real steps then says how well
the adapted models' walks can be told from the from-scratch models'.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.decomposition import PCA
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import balanced_accuracy_score
from sklearn.model_selection import GroupKFold, StratifiedGroupKFold, cross_val_predict
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler

from markovmotion.algorithms.dtw import dtw_distance, dtw_path
from markovmotion.algorithms.mlpg import global_variance
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import counted
from markovmotion.data.splits import TEST_EVERY, held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.errors import DataNotFoundError, ModelFormatError
from markovmotion.evaluate.perceptual import efficiency
from markovmotion.evaluate.takes import TestTakes, test_takes
from markovmotion.features import ExpMaps, FeaturePipeline, JointPositions
from markovmotion.features.gait import SIDES, align_walk, detect_steps, foot_slide
from markovmotion.features.reference_pose import ReferencePose
from markovmotion.models.base import Model, file_sha256, training_hashes
from markovmotion.models.gait.synthesizer import KIND, GaitSynthesizer, walks_with_steps
from markovmotion.persist import load_npz
from markovmotion.progress import note, track

ROLES = ("adapted", "average", "scratch")
#: Categories of INDEX.csv rows that are walks.
WALK_CATEGORIES = ("walk", "style_walk")


@dataclass
class WalkSteps:
    """A walk seen by the evaluator: its steps' features, boundaries and measures."""

    name: str
    static: np.ndarray  # (F, D) exponential maps
    joints: np.ndarray  # (F, 3J) body-centred joint positions, mm
    boundaries: np.ndarray
    sides: tuple[str, ...]
    step_stats: np.ndarray  # (n, 2D + 1)
    slide: np.ndarray  # (n,) mm
    gv: np.ndarray  # (D,)

    @property
    def n_steps(self) -> int:
        return len(self.sides)

    def step(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        sl = slice(self.boundaries[k], self.boundaries[k + 1] + 1)
        return self.static[sl], self.joints[sl]


def step_statistics(static: np.ndarray, boundaries: np.ndarray, fps: float) -> np.ndarray:
    """(n, 2D + 1) per step: mean and standard deviation of each feature, duration in seconds."""
    b = boundaries
    stats = [
        np.concatenate(
            [
                static[b[k] : b[k + 1]].mean(axis=0),
                static[b[k] : b[k + 1]].std(axis=0),
                [(b[k + 1] - b[k]) / fps],
            ]
        )
        for k in range(len(b) - 1)
    ]
    return np.array(stats).reshape(len(stats), 2 * static.shape[1] + 1)


class Observer:
    """Turns walks (real or synthesized) into :class:`WalkSteps` with one fixed feature pipeline."""

    def __init__(self, reference_walks: Sequence[Motion]):
        aligned = [align_walk(m) for m in reference_walks]
        self.pipeline = FeaturePipeline([ReferencePose(), ExpMaps(root_position="none")])
        self.pipeline.fit(aligned)
        sk = aligned[0].skeleton
        below = [n for j, n in enumerate(sk.names) if _descends(sk.parents, j, sk.body_root)]
        self.positions = JointPositions(joints=below).fit(aligned[:1])

    def __call__(self, motion: Motion) -> WalkSteps:
        aligned = align_walk(motion)
        steps = detect_steps(aligned)
        static = self.pipeline.transform([aligned])[0]
        joints = self.positions.transform([aligned])[0]
        b = steps.boundaries
        span = static[b[0] : b[-1]] if steps.n_steps else static
        return WalkSteps(
            motion.name,
            static,
            joints,
            b,
            steps.sides,
            step_statistics(static, b, motion.fps),
            foot_slide(aligned, b, steps.sides) if steps.n_steps else np.zeros(0),
            global_variance(span),
        )


def _descends(parents: np.ndarray, joint: int, ancestor: int) -> bool:
    """True if ``joint`` is ``ancestor`` or below it."""
    while joint >= 0:
        if joint == ancestor:
            return True
        joint = parents[joint]
    return False


# ------------------------------------------------------------------ the classifier
class StyleClassifier(BaseEstimator):
    """Logistic regression on (principal components of) per-step statistics, trained on real steps.

    Args:
        n_components: principal components kept; ``None`` keeps all the
            statistics; ``"auto"`` the fewest whose cross-validated step
            recognition on the training walks (folds by walk) reaches ``target``.
        target: recognition rate sought by ``"auto"``.
        C: inverse regularisation of the logistic regression.
        n_folds: folds of the cross-validation.

    Learnt: ``model_`` (scikit-learn pipeline), ``classes_``,
    ``n_components_`` (None: all), ``cv_rates_`` (components tried by
    ``"auto"`` -> cross-validated step rate).
    """

    def __init__(
        self,
        n_components: int | str | None = "auto",
        target: float = 0.9,
        C: float = 1.0,
        n_folds: int = 5,
    ):
        self.n_components = n_components
        self.target = target
        self.C = C
        self.n_folds = n_folds

    def _pipeline(self, n_components: int | None) -> Pipeline:
        reduce = [PCA(n_components)] if n_components else []
        return make_pipeline(StandardScaler(), *reduce, LogisticRegression(C=self.C, max_iter=5000))

    def fit(self, walks: Sequence[WalkSteps], labels: Sequence[str]) -> StyleClassifier:
        x = np.vstack([w.step_stats for w in walks])
        y = np.concatenate([[lab] * w.n_steps for w, lab in zip(walks, labels, strict=True)])
        groups = np.concatenate([[i] * w.n_steps for i, w in enumerate(walks)])
        self.cv_rates_: dict[int, float] = {}
        k = self.n_components
        folds = walk_folds(min(self.n_folds, len(walks)), y, groups) if k == "auto" else None
        if k == "auto":
            k = None  # all, also when no fold trains on two styles (one of two styles one walk)
            # at most as many components as the smallest fold trains on steps (a collection of
            # 18 steps had asked a fold of 14 for 15: a traceback from scikit-learn)
            top = min(x.shape[1], *(len(t) for t, _ in folds.split(x, y, groups))) if folds else 0
            for n in range(1, top + 1):
                guess = cross_val_predict(self._pipeline(n), x, y, groups=groups, cv=folds)
                self.cv_rates_[n] = float(np.mean(guess == y))
                if self.cv_rates_[n] >= self.target:
                    k = n
                    break
        self.n_components_ = k
        self.model_ = self._pipeline(k).fit(x, y)
        self.classes_ = list(self.model_.classes_)
        return self

    def predict_steps(self, walk: WalkSteps) -> list[str]:
        if not walk.n_steps:
            return []
        return list(self.model_.predict(walk.step_stats))

    def predict(self, walk: WalkSteps) -> str | None:
        """The walk's style by summed step log posteriors, or None when no step was found in it."""
        if not walk.n_steps:
            return None
        log_post = self.model_.predict_log_proba(walk.step_stats).sum(axis=0)
        return self.classes_[int(np.argmax(log_post))]


def real_vs_synthesized(
    synth: Sequence[WalkSteps], real: Sequence[WalkSteps], n_folds: int = 5, C: float = 1.0
) -> float:
    """Balanced accuracy of telling ``synth`` steps from ``real`` ones (a stand-in for §6.2).

    Logistic regression on the standardised step statistics, classes
    weighted equally, predictions cross-validated with folds by walk. 0.5:
    the two sets of steps cannot be told apart; 1: always. NaN when either
    set has fewer than two walks (no fold would hold both kinds).
    """
    if min(len(synth), len(real)) < 2:
        return float("nan")
    walks = [*synth, *real]
    x = np.vstack([w.step_stats for w in walks])
    y = np.concatenate([np.full(w.n_steps, i < len(synth)) for i, w in enumerate(walks)])
    groups = np.concatenate([np.full(w.n_steps, i) for i, w in enumerate(walks)])
    model = make_pipeline(
        StandardScaler(), LogisticRegression(C=C, max_iter=5000, class_weight="balanced")
    )
    folds = walk_folds(min(n_folds, len(synth), len(real)), y, groups)
    if folds is None:
        return float("nan")
    guess = cross_val_predict(model, x, y, groups=groups, cv=folds)
    return float(balanced_accuracy_score(y, guess))


def walk_folds(
    k: int, y: np.ndarray, groups: np.ndarray
) -> GroupKFold | StratifiedGroupKFold | None:
    """``k`` folds by walk (``groups``) in which every training part holds two classes or
    more: by walk, else stratified by class; None when none can (of two classes, one has a
    single walk): a classifier cannot be fitted on one class."""
    x = np.zeros((len(y), 1))
    for folds in (GroupKFold(k), StratifiedGroupKFold(k)):
        if all(len(set(y[train])) > 1 for train, _ in folds.split(x, y, groups)):
            return folds
    return None


# ------------------------------------------------------------------ rates and intervals
def bootstrap_means(
    per_style: Sequence[tuple[np.ndarray, np.ndarray]], n_boot: int, seed: int = 0
) -> np.ndarray:
    """(n_boot,) bootstrap replicates of the mean over styles of ``sum(num) / sum(den)``.

    ``per_style`` holds, for each style, (num, den) arrays (groups, walks):
    steps recognised and steps of each walk, for a rate, the walks grouped by
    the model that made them (one group for real walks). Two stages, within
    each style: groups are resampled with replacement, then walks within each.
    """
    rng = np.random.default_rng(seed)
    out = np.zeros(n_boot)
    for num, den in per_style:
        n_groups, n_walks = num.shape
        groups = rng.integers(0, n_groups, size=(n_boot, n_groups, 1))
        walks = rng.integers(0, n_walks, size=(n_boot, n_groups, n_walks))
        total = den[groups, walks].sum(axis=(1, 2))
        out += num[groups, walks].sum(axis=(1, 2)) / np.maximum(total, 1e-12)
    return out / len(per_style)


def interval(replicates: np.ndarray, level: float = 0.95) -> list[float]:
    """Percentile interval [low, high] of bootstrap replicates."""
    tail = 50 * (1 - level)
    return [float(v) for v in np.percentile(replicates, [tail, 100 - tail])]


@dataclass
class Recognition:
    """Per-step recognition of walks, style by style: counts per walk and the confusion of steps.

    ``correct[s]`` and ``steps[s]`` (groups, walks) count the recognised and
    found steps of each walk of style s, walks grouped by the model that made
    them; ``walk_correct[s]`` whether each walk as a whole is recognised;
    ``confusion[s]`` (classes,) the step counts of each answer.
    """

    classes: list[str]
    correct: dict[str, np.ndarray] = field(default_factory=dict)
    steps: dict[str, np.ndarray] = field(default_factory=dict)
    walk_correct: dict[str, np.ndarray] = field(default_factory=dict)
    confusion: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def of(
        cls, clf: StyleClassifier, walks: Mapping[str, Sequence[Sequence[WalkSteps]]]
    ) -> Recognition:
        """Recognition of ``walks``: style -> groups of as many walks each."""
        out = cls(list(clf.classes_))
        for style, groups in walks.items():
            guesses = [[clf.predict_steps(w) for w in ws] for ws in groups]
            out.correct[style] = np.array(
                [[sum(g == style for g in w) for w in gs] for gs in guesses]
            )
            out.steps[style] = np.array([[len(w) for w in gs] for gs in guesses])
            out.walk_correct[style] = np.array(
                [[clf.predict(w) == style for w in ws] for ws in groups]
            )
            out.confusion[style] = np.array(
                [sum(g == c for gs in guesses for w in gs for g in w) for c in out.classes]
            )
        return out

    def _styles(self, styles: Sequence[str] | None) -> list[str]:
        return [s for s in (styles or self.correct) if self.steps[s].sum()]

    def rate(self, styles: Sequence[str] | None = None) -> float:
        """Mean over styles of the fraction of their steps recognised."""
        chosen = self._styles(styles)
        if not chosen:
            return float("nan")
        return float(np.mean([self.correct[s].sum() / self.steps[s].sum() for s in chosen]))

    def walk_rate(self, styles: Sequence[str] | None = None) -> float:
        """Mean over styles of the fraction of their walks recognised."""
        return float(np.mean([self.walk_correct[s].mean() for s in styles or self.walk_correct]))

    def replicates(
        self, styles: Sequence[str] | None = None, n_boot: int = 2000, seed: int = 0
    ) -> np.ndarray:
        """Bootstrap replicates of :meth:`rate` (:func:`bootstrap_means`)."""
        chosen = self._styles(styles)
        return bootstrap_means([(self.correct[s], self.steps[s]) for s in chosen], n_boot, seed)

    def table(self, styles: Sequence[str] | None = None) -> dict[str, dict[str, float]]:
        """Confusion matrix in percent of each style's steps (Table 2; rows: actual style)."""
        out = {}
        for s in self._styles(styles):
            share = 100 * self.confusion[s] / self.steps[s].sum()
            out[s] = {c: round(float(v), 1) for c, v in zip(self.classes, share, strict=True)}
        return out


def dtw_to_nearest(
    synth: Sequence[WalkSteps], real: Sequence[WalkSteps]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per synthesized walk, (exp-map RMSE, joint error mm) of each step to the nearest real step (same side)."""
    real_steps: dict[str, list] = {side: [] for side in SIDES}
    for w in real:
        for k, side in enumerate(w.sides):
            real_steps[side].append(w.step(k))
    out = []
    for w in synth:
        rmse, mm = [], []
        for k, side in enumerate(w.sides):
            a, ja = w.step(k)
            if not real_steps[side]:
                continue
            costs = [dtw_distance(a, b) for b, _ in real_steps[side]]
            b, jb = real_steps[side][int(np.argmin(costs))]
            _, path = dtw_path(a, b)
            diff = a[path[:, 0]] - b[path[:, 1]]
            rmse.append(np.sqrt(np.mean(diff**2)))
            dj = (ja[path[:, 0]] - jb[path[:, 1]]).reshape(len(path), -1, 3)
            mm.append(np.linalg.norm(dj, axis=2).mean())
        out.append((np.array(rmse), np.array(mm)))
    return out


def _per_walk(values: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(sums, counts) over walks of per-step values."""
    return np.array([v.sum() for v in values]), np.array([len(v) for v in values], float)


def _mean_over_styles(per_style: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
    return _finite_mean([num.sum() / den.sum() for num, den in per_style if den.sum()])


def _finite_mean(values: Sequence[float]) -> float:
    """Mean of the finite values (NaN if there is none)."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _step_duration_sd(walks: Mapping[str, Sequence[WalkSteps]], styles: Sequence[str]) -> float:
    """Mean over styles and walks of the standard deviation of step durations within a walk (s)."""
    sd = [np.mean([w.step_stats[:, -1].std() for w in walks[s] if w.n_steps]) for s in styles]
    return float(np.mean(sd))


def adaptation_takes(
    motions: Sequence[Motion], steps_per_take: Sequence[int], n_steps: int, replicate: int = 0
) -> list[Motion]:
    """The fewest consecutive takes that together hold at least ``n_steps`` steps.

    Replicate 0 starts at the first take, replicate r after the takes of
    replicate r - 1, so the replicates never share a take.

    Raises:
        DataNotFoundError: the takes left hold fewer steps.
    """
    start = 0
    for r in range(replicate + 1):
        total = np.cumsum(steps_per_take[start:])
        if not len(total) or total[-1] < n_steps:
            have = int(total[-1]) if len(total) else 0
            raise DataNotFoundError(
                f"{n_steps} adaptation steps asked for replicate {r}, "
                f"only {have} in the {len(total)} takes left"
            )
        end = start + int(np.searchsorted(total, n_steps)) + 1
        if r < replicate:
            start = end
    return list(motions[start:end])


# ------------------------------------------------------------------ the evaluation
@dataclass
class Evaluation:
    """Real walks prepared once: the observer, the classifiers and the walks by style.

    ``classifier`` is the one the rates come from (capacity chosen on the
    training takes), ``full`` the regression on all the step statistics.
    ``replicates`` is the number of adapted (and from-scratch) models per style
    and number of steps in :meth:`sweep`, each from other training takes.
    """

    observer: Observer
    classifier: StyleClassifier
    full: StyleClassifier
    test: dict[str, list[WalkSteps]]
    train: dict[str, list[WalkSteps]]
    test_motions: dict[str, list[Motion]]
    train_motions: dict[str, list[Motion]]
    n_walks: int = 8
    walk_steps: int = 12
    speed_jitter: float = 0.05
    replicates: int = 1
    seed: int = 0
    n_boot: int = 2000

    @property
    def styles(self) -> list[str]:
        return sorted(self.test)

    @classmethod
    def prepare(
        cls,
        train: Mapping[str, Sequence[Motion]],
        test: Mapping[str, Sequence[Motion]],
        classifier: StyleClassifier | None = None,
        **settings: Any,
    ) -> Evaluation:
        """Classifiers trained on ``train`` walks (style -> walks); ``test`` held out.

        ``settings`` set the synthesis and bootstrap fields (``n_walks``, ...).
        """
        observer = Observer([m for ws in train.values() for m in ws[:2]])
        tr = {s: [observer(m) for m in ws] for s, ws in train.items()}
        te = {s: [observer(m) for m in ws] for s, ws in test.items()}
        walks = [w for ws in tr.values() for w in ws]
        labels = [s for s, ws in tr.items() for _ in ws]
        clf = (classifier or StyleClassifier()).fit(walks, labels)
        full = StyleClassifier(n_components=None, C=clf.C).fit(walks, labels)
        motions = [{s: list(ws) for s, ws in part.items()} for part in (test, train)]
        return cls(observer, clf, full, te, tr, *motions, **settings)

    def _real(self, styles: Sequence[str]) -> dict[str, list[list[WalkSteps]]]:
        return {s: [self.test[s]] for s in styles}

    def real(self) -> dict[str, Any]:
        """Recognition of the real held-out walks, their foot sliding, and DTW test-to-training floor."""
        rec = Recognition.of(self.classifier, self._real(self.styles))
        n = len(self.classifier.classes_)
        rate = rec.rate()
        dtw = [dtw_to_nearest(self.test[s], self.train[s][:3]) for s in self.styles]
        slides = np.concatenate([w.slide for ws in self.test.values() for w in ws])
        return {
            "rate": rate,
            "rate_ci": interval(rec.replicates(n_boot=self.n_boot, seed=self.seed)),
            "walk_rate": rec.walk_rate(),
            "rate_full": Recognition.of(self.full, self._real(self.styles)).rate(),
            "chance": 1.0 / n,
            "eta": efficiency(100 * rate, n),
            "steps": int(sum(v.sum() for v in rec.steps.values())),
            "walks": int(sum(v.size for v in rec.steps.values())),
            "classifier": {
                "components": self.classifier.n_components_,
                "cv_step_rates": {str(k): v for k, v in self.classifier.cv_rates_.items()},
            },
            "foot_slide_mm": float(slides.mean()),
            "real_vs_synthesized": _finite_mean(
                [real_vs_synthesized(self.train[s], self.test[s]) for s in self.styles]
            ),
            "dtw_expmap_rmse": _mean_over_styles([_per_walk([d[0] for d in x]) for x in dtw]),
            "dtw_joint_mm": _mean_over_styles([_per_walk([d[1] for d in x]) for x in dtw]),
            "confusion": rec.table(),
        }

    def synthesized_walks(
        self, model: GaitSynthesizer, style: str, replicate: int = 0
    ) -> list[WalkSteps]:
        """``n_walks`` walks of ``model``, with the random numbers of (style, replicate).

        The same random numbers for every kind of model make comparisons paired.
        """
        rng = np.random.default_rng([self.seed, self.styles.index(style), replicate])
        out = []
        for i in range(self.n_walks):
            speed = rng.uniform(1 - self.speed_jitter, 1 + self.speed_jitter)
            walk = model.generate(
                self.walk_steps, speed=speed, first_side=SIDES[i % 2], rng=rng, stochastic=True
            )
            out.append(self.observer(walk))
        return out

    def models(
        self,
        models: Mapping[str, Sequence[GaitSynthesizer]],
        progress: Callable[[str], None] | None = None,
        label: str = "",
    ) -> tuple[dict[str, Any], np.ndarray, dict[str, list[WalkSteps]]]:
        """Metrics of one kind of model (``models``: style -> the models that should walk it).

        Returns the metrics, the bootstrap replicates of the synthesized
        step rate (models, then walks resampled) and the synthesized walks of
        each style. ``progress`` is told ``label`` + each style in turn.
        """
        styles = sorted(models)
        synth = {}
        for s in styles:
            if progress:
                progress(label + s)
            synth[s] = [self.synthesized_walks(m, s, r) for r, m in enumerate(models[s])]
        flat = {s: [w for ws in synth[s] for w in ws] for s in styles}
        real = Recognition.of(self.classifier, self._real(styles))
        rec = Recognition.of(self.classifier, synth)
        n = len(self.classifier.classes_)
        reps = rec.replicates(n_boot=self.n_boot, seed=self.seed + 1)
        dtw = {s: dtw_to_nearest(flat[s], self.test[s]) for s in styles}
        real_gv = {s: np.mean([w.gv.sum() for w in self.test[s]]) for s in styles}
        gv = [
            (np.array([w.gv.sum() / real_gv[s] for w in flat[s]]), np.ones(len(flat[s])))
            for s in styles
        ]
        out = {
            "real_rate": real.rate(),
            "real_rate_ci": interval(real.replicates(n_boot=self.n_boot, seed=self.seed)),
            "synthesized_rate": rec.rate(),
            "synthesized_rate_ci": interval(reps),
            "chance": 1.0 / n,
            "eta_real": efficiency(100 * real.rate(), n),
            "eta_synthesized": efficiency(100 * rec.rate(), n),
            "synthesized_walk_rate": rec.walk_rate(),
            "real_rate_full": Recognition.of(self.full, self._real(styles)).rate(),
            "synthesized_rate_full": Recognition.of(self.full, synth).rate(),
            "synthesized_steps": int(sum(v.sum() for v in rec.steps.values())),
            "step_duration_sd": _step_duration_sd(flat, styles),
            "real_step_duration_sd": _step_duration_sd(self.test, styles),
            "foot_slide_mm": _mean_over_styles(
                [_per_walk([w.slide for w in flat[s]]) for s in styles]
            ),
            "gv_ratio": _mean_over_styles(gv),
            "real_vs_synthesized": _finite_mean(
                [real_vs_synthesized(flat[s], self.test[s]) for s in styles]
            ),
            "dtw_expmap_rmse": _mean_over_styles(
                [_per_walk([d[0] for d in dtw[s]]) for s in styles]
            ),
            "dtw_joint_mm": _mean_over_styles([_per_walk([d[1] for d in dtw[s]]) for s in styles]),
            "test_log_likelihood": float(
                np.mean([m.score(self.test_motions[s]) for s in styles for m in models[s]])
            ),
            "adaptation_steps": {s: [m.n_steps_ for m in models[s]] for s in styles},
            "adaptation_files": {s: [m.own_files for m in models[s]] for s in styles},
            "confusion": rec.table(),
            "styles": styles,
        }
        return out, reps, flat

    def sweep(
        self,
        average: GaitSynthesizer,
        styles: Sequence[str],
        steps: Sequence[int] = (3, 6, 12, 24),
        progress: Callable[[str], None] | None = None,
        **options: Any,
    ) -> dict[str, dict[str, Any]]:
        """Adapted and from-scratch models of each style from K of its training steps, for each K.

        Both models of a style see exactly the same K steps; there are
        ``replicates`` pairs per style, each from other training takes
        (:func:`adaptation_takes`). ``options`` go to :meth:`GaitSynthesizer.adapt`.
        """
        out: dict[str, dict[str, Any]] = {}
        for k in steps:
            adapted: dict[str, list[GaitSynthesizer]] = {s: [] for s in styles}
            scratch: dict[str, list[GaitSynthesizer]] = {s: [] for s in styles}
            for style in styles:
                if progress:
                    progress(f"{k} steps: fitting {style}")
                counts = [w.n_steps for w in self.train[style]]
                for r in range(self.replicates):
                    takes = adaptation_takes(self.train_motions[style], counts, k, r)
                    adapted[style].append(average.adapt(takes, style, k, **options))
                    scratch[style].append(average.scratch(takes, style, k))
            a, a_reps, a_walks = self.models(adapted, progress, f"{k} steps: adapted ")
            s, s_reps, s_walks = self.models(scratch, progress, f"{k} steps: scratch ")
            out[str(k)] = {
                "adapted": a,
                "scratch": s,
                "adapted_minus_scratch": {
                    "synthesized_rate": a["synthesized_rate"] - s["synthesized_rate"],
                    "synthesized_rate_ci": interval(a_reps - s_reps),
                    "told_apart": _finite_mean(
                        [real_vs_synthesized(a_walks[st], s_walks[st]) for st in styles]
                    ),
                },
            }
        return out


# ------------------------------------------------------------------ ``gait evaluate``
class Models(dict[str, dict[str, GaitSynthesizer]]):
    """Gait models by role and style (a plain dict of that shape will do), and the file each
    was read from (``files``, by role and style, as the models are held), by which notes
    name them."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.files: dict[tuple[str, str], str] = {}


def model_name(models: Mapping[str, Mapping[str, GaitSynthesizer]], model: GaitSynthesizer) -> str:
    """The file ``model`` was read from (:func:`load_models`), else "the <role> <style> model"."""
    files = getattr(models, "files", {})
    return files.get((model.role_, model.style_), f"the {model.role_} {model.style_} model")


def load_models(path: str | os.PathLike[str]) -> Models:
    """Gait models by role and style: one model file, or those of a folder (other kinds skipped).

    Raises:
        DataNotFoundError: no such file or folder, or no gait model in the folder.
        ModelFormatError: a file given by name that is not a gait model.
    """
    path = Path(path)
    found = Models({r: {} for r in ROLES})
    if path.is_file():
        model = _load(path)
        found[model.role_][model.style_] = model
        found.files[model.role_, model.style_] = path.name
        return found
    if not path.is_dir():
        raise DataNotFoundError(f"{path}: no such gait model or folder of models")
    for file in sorted(path.glob("*.npz")):
        try:
            header, _ = load_npz(file)
        except ModelFormatError:
            continue
        if header.get("kind") == KIND:
            model = _load(file)
            found[model.role_][model.style_] = model
            found.files[model.role_, model.style_] = file.name
    if not any(found.values()):
        raise DataNotFoundError(f"{path}: no gait models (.npz) in this folder")
    return found


def _load(path: Path) -> GaitSynthesizer:
    model = GaitSynthesizer.load(path)
    if not hasattr(model, "train_files_"):
        raise ModelFormatError(
            path, "written before models recorded their training files; train it again"
        )
    return model


def _all(models: Models) -> list[GaitSynthesizer]:
    return [m for role in models.values() for m in role.values()]


def _trained_on_any(models: Models) -> Model:
    """A stand-in whose ``train_files_`` are those of every model (for :func:`test_takes`)."""
    union = Model()
    union.train_files_ = [rec for m in _all(models) for rec in m.train_files_]
    return union


def _skeleton(models: Models) -> Skeleton:
    """The skeleton the models learnt (their walks')."""
    return _all(models)[0].pipeline_.steps[-1].skeleton_


def trained_index(models: Models) -> str | None:
    """The folder of the index the models were trained on (``data_index``, recorded by
    ``gait train`` and ``gait adapt``), when every model that recorded one names the same
    and it is there; else None."""
    roots = set()
    for m in _all(models):
        record = getattr(m, "data_index_", None)
        if isinstance(record, dict) and isinstance(record.get("root"), str):
            roots.add(record["root"])
    if len(roots) == 1 and Path(root := roots.pop()).is_dir():
        return root
    return None


def _on_skeleton(
    walks: list[tuple[Entry, Motion]], skeleton: Skeleton, what: str
) -> list[tuple[Entry, Motion]]:
    """The (entry, walk) pairs whose walk is on the models' ``skeleton``; the others left out
    in a note naming them and how the first differs (they had reached the style classifier
    and the models' features: a traceback from NumPy). None kept: one error line instead.

    Raises:
        DataNotFoundError: no walk is on the models' skeleton.
    """
    kept, other = [], []
    for e, m in walks:
        (kept if skeleton.difference(m.skeleton) is None else other).append((e, m))
    if other:
        e, m = other[0]
        differs = skeleton.difference(m.skeleton, "the models'", Path(e.file).name)
        if not kept:
            raise DataNotFoundError(
                f"none of the {counted(len(other), what)} of {e.root / 'INDEX.csv'} is on the "
                f"models' skeleton {differs}: give the index they were trained on (--data)"
            )
        files = [x.file for x, _ in other]
        more = f" and {len(files) - 5} more" if len(files) > 5 else ""
        note(
            f"{counted(len(other), what)} on another skeleton than the models' left out: "
            f"{', '.join(files[:5])}{more} {differs}"
        )
    return kept


def walks_to_test(models: Models, index: MocapIndex) -> tuple[TestTakes, list[Motion]]:
    """The walks of ``index`` that fit the models, read, without those any model trained on.

    A walk fits if its category is a walk, its label the style of one of the
    models, and its skeleton the models' (same joints, same order). Takes are
    compared with the models' ``train_files_`` by content (:func:`test_takes`).

    Raises:
        DataNotFoundError: no walk fits, or every one that does is a training take.
    """
    styles = sorted({m.style_ for m in _all(models)})
    skeleton = _skeleton(models)
    rows = sorted(index.query(category=list(WALK_CATEGORIES), label=styles), key=lambda e: e.file)
    chosen = test_takes(_trained_on_any(models), index, rows, what=f"{'/'.join(styles)} walk")
    kept: list[Entry] = []
    motions: list[Motion] = []
    why = ""
    for e in track(chosen.takes, "reading test walks"):
        motion = index.load_motion(e)
        if (differs := skeleton.difference(motion.skeleton, "the models'", e.file)) is not None:
            why = why or f"; {e.file}: {differs}"
            continue
        kept.append(e)
        motions.append(motion)
    if not kept:
        raise DataNotFoundError(
            f"no walk of {', '.join(styles)} in {index.root / 'INDEX.csv'} has the models' "
            f"skeleton ({skeleton.n_joints} joints{why})"
        )
    return TestTakes(kept, chosen.left_out), motions


def _why_not_evaluated(
    model: GaitSynthesizer,
    style: str,
    styles: Sequence[str],
    average: GaitSynthesizer | None,
    test: str | os.PathLike[str] | None,
    index: MocapIndex,
    subset: str | None,
) -> str:
    """Why a style model is not among those evaluated: its style is the average model's
    (not a target), or no test (held-out) walk of its style is left."""
    if style in styles and average is not None and style == average.style_:
        return f"style {style} is the average model's own (a class, not a target)"
    if test is not None:
        return f"no test walk of style {style} in {Path(test)} (or none with steps)"
    takes = gait_entries(index, style, subset)
    if not takes:
        return f"no walk of style {style} in {index.root / 'INDEX.csv'}"
    _, held = held_out_every(takes)
    if held:
        return f"its held-out walks of style {style} have no steps"
    own = {Path(f).name for f in model.own_files}
    used = "used to adapt" if model.role_ == "adapted" else "trained on"
    how = used if all(Path(e.file).name in own for e in takes) else "in the training split"
    return (
        f"no held-out walk of style {style} ({counted(len(takes), 'takes')}, {how}; every "
        f"{TEST_EVERY}th take of a style is held out)"
    )


def _with_steps(walks: list[tuple[Entry, Motion]], what: str) -> list[tuple[Entry, Motion]]:
    """The (entry, walk) pairs whose walk has steps; the others named in a note
    (:func:`~markovmotion.models.gait.synthesizer.walks_with_steps`): one such take had
    stopped the evaluation of the rest."""
    return [walks[i] for i in walks_with_steps([m for _, m in walks], what)]


def evaluate_models(
    models: Models,
    test: str | os.PathLike[str] | None = None,
    *,
    data: str | os.PathLike[str] | None = None,
    sweep: Sequence[int] = (),
    classifier: StyleClassifier | None = None,
    n_walks: int = 8,
    walk_steps: int = 12,
    replicates: int = 3,
    seed: int = 0,
    n_boot: int = 2000,
    subset: str | None = None,
    progress: Callable[[str, int], None] | None = None,
) -> dict[str, Any]:
    """Everything ``gait evaluate`` reports, on held-out walks or on the walks of another index.

    The style classifier (and the sweep's adaptation) learns from the
    training takes (:func:`~markovmotion.data.splits.held_out_every`) of the
    walks of ``data`` (an INDEX.csv or its folder; default the one the models were
    trained on, :func:`trained_index`, else the shared collection) whose file starts with
    ``subset`` (None: :func:`~markovmotion.data.walks.default_subset`), those on the
    models' skeleton (the others are named in a note).
    Without ``test``, the models are evaluated on the held-out takes of that
    index, which they must not have trained on. With ``test`` (another
    INDEX.csv), on its walks that fit the models (:func:`walks_to_test`),
    less those the classifier learns from (compared by content too, listed
    as ``left_out_classifier_files``). ``progress`` is told each piece of
    work done and the total.

    Returns the results (``real``, one entry per role, ``sweep``), with
    ``test_files`` and ``left_out_training_files``.

    Raises:
        DataNotFoundError: no test walks, held-out walks the models trained
            on, a test style the classifier has no training walks of, or a
            sweep without an average model.
    """
    ks = list(sweep)
    if ks and not models["average"]:
        raise DataNotFoundError("the sweep needs an average model")
    index = MocapIndex.load(data if data is not None else trained_index(models))
    skeleton = _skeleton(models)
    train, held_out = held_out_every(gait_entries(index, None, subset))
    by_classifier: list[str] = []
    train_motions: dict[str, list[Motion]] = {}
    test_motions: dict[str, list[Motion]] = {}
    if test is None:
        trained = set().union(*(training_hashes(m) for m in _all(models)))
        leaked = sorted(e.name for e in held_out if file_sha256(e.path) in trained)
        if leaked:
            raise DataNotFoundError(
                f"the models were trained on held-out takes ({', '.join(leaked[:3])}); "
                "train them on the training split, or evaluate with a test index"
            )
        read = [(e, index.load_motion(e)) for e in track(held_out, "reading test walks")]
        read = _with_steps(_on_skeleton(read, skeleton, "held-out walks"), "held-out walks")
        takes = TestTakes([e for e, _ in read])
        for e, m in read:
            test_motions.setdefault(e.label, []).append(m)
    else:
        found, motions = walks_to_test(models, MocapIndex.load(test))
        learnt = {file_sha256(e.path) for e in train}
        kept = [
            (e, m)
            for e, m in zip(found.takes, motions, strict=True)
            if file_sha256(e.path) not in learnt
        ]
        by_classifier = [e.file for e in found.takes if file_sha256(e.path) in learnt]
        if not kept:
            raise DataNotFoundError(
                f"every walk of {found.takes[0].root / 'INDEX.csv'} that fits the models and "
                f"that they did not train on teaches the style classifier: "
                f"{', '.join(by_classifier)}"
            )
        kept = _with_steps(kept, "test walks")
        takes = TestTakes([e for e, _ in kept], found.left_out)
        for e, m in kept:
            test_motions.setdefault(e.label, []).append(m)
    read = [(e, index.load_motion(e)) for e in track(train, "reading training walks")]
    read = _on_skeleton(read, skeleton, "training walks")
    for e, m in _with_steps(read, "training walks"):
        train_motions.setdefault(e.label, []).append(m)
    missing = sorted(set(test_motions) - set(train_motions))
    if missing:
        raise DataNotFoundError(
            f"no training walks of {', '.join(missing)} in {index.root / 'INDEX.csv'} "
            "for the style classifier"
        )
    ev = Evaluation.prepare(
        train_motions,
        test_motions,
        classifier or StyleClassifier(),
        n_walks=n_walks,
        walk_steps=walk_steps,
        replicates=replicates,
        seed=seed,
        n_boot=n_boot,
    )
    average = next(iter(models["average"].values()), None)
    targets = [s for s in ev.styles if average is None or s != average.style_] or ev.styles
    chosen = {
        role: {s: [m] for s, m in models[role].items() if s in targets}
        for role in ("adapted", "scratch")
    }
    if average is not None:
        chosen["average"] = {s: [average] for s in targets}
    for role in ("adapted", "scratch"):  # a model left out is said, not dropped silently
        for style, model in models[role].items():
            if style not in targets:
                why = _why_not_evaluated(model, style, ev.styles, average, test, index, subset)
                note(f"{model_name(models, model)}: {why}: not evaluated")
    if not ks and not any(chosen.values()):
        which = "test" if test else "held-out"
        if not test_motions:  # it had said "the held-out walks are of  only"
            raise DataNotFoundError(
                f"no model left to evaluate: {index.root / 'INDEX.csv'} holds no held-out walk "
                f"(every {TEST_EVERY}th take of a style is held out): give walks to test "
                "on with --test"
            )
        raise DataNotFoundError(
            f"no model left to evaluate: the {which} walks are of {', '.join(ev.styles)} only"
        )
    work = sum(map(len, chosen.values())) + 3 * len(ks) * len(targets)

    def advance(what: str) -> None:
        if progress:
            progress(what, work)

    result: dict[str, Any] = {"styles": ev.styles, "targets": targets, "real": ev.real()}
    for role in ROLES:
        if chosen.get(role):
            result[role], _, _ = ev.models(chosen[role], advance, f"{role} ")
    if ks:
        result["sweep"] = ev.sweep(average, targets, ks, progress=advance)
    result.update(takes.report())
    result["left_out_classifier_files"] = by_classifier
    return result

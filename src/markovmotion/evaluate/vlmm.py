"""Prediction error against horizon, E_T (VLMM paper §3.2.3, eq. 9, Figs. 4 and 10).

On every frame t of every test sequence a predictor extrapolates the next
``horizon`` frames (``n_samples`` stochastic predictions: Monte Carlo); the
error of one trial at horizon T is the mean Euclidean distance, in mm, between
predicted and true joint positions at t + T. E_T is the mean over all trials
for which t + T lies in the sequence; its spread is the mean absolute
deviation (the paper's error bars).

A predictor has three methods: ``prepare(features)`` (whatever it needs per
sequence, e.g. the recognised state at each frame),
``predict_configurations(features, prepared, frames, horizon, n_samples, rng)``
-> (len(frames), n_samples, horizon, d), and ``configuration_positions(C)``
-> (M, J, 3) mm.

:func:`evaluate_model` is the experiment of ``vlmm evaluate``: a trained
behaviour model (plain or structured) on the takes of any INDEX.csv that fit
it, against a first-order Markov model over the same prototypes and the
zero-velocity baseline.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.core.words import first_names
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import counted
from markovmotion.errors import DataNotFoundError, SkeletonMismatchError
from markovmotion.evaluate.takes import TestTakes, test_takes
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.models.vlmm.structured import StructuredBehaviourModel
from markovmotion.progress import progress_bar
from markovmotion.viz.plots import new_figure, ordinal, save_figure

#: Horizons reported by ``vlmm evaluate`` (seconds).
REPORT_SECONDS = (0.5, 1.0, 2.0, 3.0)
#: Where E_T is measured: joint (or marker) positions in mm, or configurations (eq. 9).
SPACES = ("mm", "configuration")
#: The first-order Markov model: memory 1, every context kept.
FIRST_ORDER = (1, 0.0)


def trial_errors(predicted: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Mean joint distance (..., H) between predicted (..., H, J, 3) and true (H, J, 3) positions."""
    return np.linalg.norm(predicted - truth, axis=-1).mean(axis=-1)


@dataclass
class HorizonCurve:
    """E_T (mm) for T = 1..H frames, with the mean absolute deviation and trial counts."""

    name: str
    fps: float
    mean: np.ndarray
    mad: np.ndarray
    count: np.ndarray

    @classmethod
    def from_errors(cls, name: str, fps: float, errors: np.ndarray) -> HorizonCurve:
        """From per-trial errors (n_trials, H), NaN where t + T is past the sequence (eq. 9)."""
        valid = ~np.isnan(errors)
        count = valid.sum(axis=0)
        some = np.maximum(count, 1)  # a horizon without a trial is NaN, without NumPy's warning
        mean = np.where(count > 0, np.where(valid, errors, 0.0).sum(axis=0) / some, np.nan)
        spread = np.where(valid, np.abs(np.where(valid, errors, 0.0) - mean), 0.0)
        mad = np.where(count > 0, spread.sum(axis=0) / some, np.nan)
        return cls(name, fps, mean, mad, count)

    def at(self, seconds: float) -> float:
        """E_T at ``seconds`` ahead (the nearest frame)."""
        t = int(round(seconds * self.fps))
        if not 1 <= t <= len(self.mean):
            raise ValueError(f"horizon {seconds} s is outside 1..{len(self.mean)} frames")
        return float(self.mean[t - 1])


class Predictor(Protocol):
    """What :func:`evaluate_horizon` asks of a predictor (the VLMMs, the contour tracker's
    model, the baselines here): features prepared once per sequence, sampled futures of
    configurations from given frames, and the positions (mm) of configurations."""

    def prepare(self, features: np.ndarray) -> Any: ...

    def predict_configurations(
        self,
        features: np.ndarray,
        prepared: Any,
        frames: np.ndarray,
        horizon: int,
        n_samples: int,
        rng: np.random.Generator,
    ) -> np.ndarray: ...

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray: ...


class ZeroVelocity:
    """The baseline that holds the last observed pose, over another predictor's features."""

    def __init__(self, model):
        self.model = model

    def prepare(self, features: np.ndarray) -> None:
        return None

    def predict_configurations(self, features, prepared, frames, horizon, n_samples, rng):
        c = features[np.asarray(frames), : self.model.n_dims]
        return np.broadcast_to(c[:, None, None, :], (len(c), 1, horizon, c.shape[1]))

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        return self.model.configuration_positions(configs)


class ConfigurationSpace:
    """Another predictor measured in its configuration space: eq. 9 literally, the
    Euclidean distance between predicted and true configurations C in [0, 1]^d
    (the paper's Figs. 4 and 10), instead of joint positions in mm."""

    def __init__(self, predictor):
        self.predictor = predictor

    def prepare(self, features: np.ndarray):
        return self.predictor.prepare(features)

    def predict_configurations(self, features, prepared, frames, horizon, n_samples, rng):
        return self.predictor.predict_configurations(
            features, prepared, frames, horizon, n_samples, rng
        )

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        return np.asarray(configs)[:, None, :]


def evaluate_horizon(
    predictor: Predictor,
    sequences: Sequence[np.ndarray],
    horizon: int,
    fps: float,
    n_samples: int = 50,
    stride: int = 1,
    seed: int = 0,
    name: str = "",
    max_chunk_values: int = 4_000_000,
) -> HorizonCurve:
    """E_T for T = 1..``horizon`` frames on the frames ``0, stride, 2 stride, ...`` of each sequence.

    ``sequences`` are feature arrays (F, 2d) from the predictor's pipeline; the
    ground truth is the positions of their configurations.
    """
    rng = np.random.default_rng(seed)
    errors = []
    with progress_bar() as bar:
        total = sum(len(range(0, len(s) - 1, stride)) for s in sequences)
        task = bar.add_task(f"E_T {name}".strip(), total=total)
        for feats in sequences:
            d = feats.shape[1] // 2
            truth = predictor.configuration_positions(feats[:, :d])
            prepared = predictor.prepare(feats)
            frames = np.arange(0, len(feats) - 1, stride)
            chunk = max(1, max_chunk_values // (n_samples * horizon * d))
            for lo in range(0, len(frames), chunk):
                fr = frames[lo : lo + chunk]
                pred = predictor.predict_configurations(
                    feats, prepared, fr, horizon, n_samples, rng
                )
                s = pred.shape[1]
                pos = predictor.configuration_positions(pred.reshape(-1, d))
                pos = pos.reshape(len(fr), s, horizon, *pos.shape[1:])
                err = np.full((len(fr), s, horizon), np.nan, dtype=np.float32)
                for i, t in enumerate(fr):
                    h = min(horizon, len(feats) - 1 - t)
                    err[i, :, :h] = trial_errors(pos[i, :, :h], truth[t + 1 : t + 1 + h])
                errors.append(err.reshape(-1, horizon))
                bar.advance(task, len(fr))
    return HorizonCurve.from_errors(name, fps, np.concatenate(errors))


def plot_horizon_curves(
    curves: Sequence[HorizonCurve],
    path: str | os.PathLike[str],
    title: str = "",
    ylabel: str = "mean joint error E_T (mm)",
) -> None:
    """E_T against horizon in seconds, error bars mean +- MAD (paper Figs. 4 and 10), as a PNG;
    each curve labelled by :func:`curve_label` of its name."""
    fig, ax = new_figure(7.0, 4.5)
    for k, c in enumerate(curves):
        t = np.arange(1, len(c.mean) + 1) / c.fps
        every = max(1, len(t) // 15)
        ax.errorbar(
            t, c.mean, yerr=c.mad, errorevery=(k % every, every), capsize=2,
            label=curve_label(c.name), lw=1.4,
        )  # fmt: skip
    ax.set_xlabel("prediction horizon T (s)")
    ax.set_ylabel(ylabel.replace("E_T", "$E_T$"))  # the paper's subscript, not an underscore
    title = title.replace("E_T", "$E_T$")
    ax.set_title(
        f"{title}\n(mean, bars ± mean absolute deviation)"
        if title
        else "Prediction error against horizon (mean, bars ± mean absolute deviation)",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path)


#: Readable names of the predictors in a plot's legend (the JSON keeps the short ones).
CURVE_LABELS: dict[str, str] = {
    "first_order": "first-order Markov (same prototypes)",
    "zero_velocity": "zero velocity (hold the last pose)",
    "vlmm": "VLMM (the model)",
    "structured": "structured VLMM",
}


def curve_label(name: str) -> str:
    """A predictor's name as a legend shows it (``vlmm_N5``: "VLMM, memory 5"; several names
    of one curve joined by " = ")."""
    parts = []
    for n in name.split(" = "):
        if n.startswith("vlmm_N") and n[6:].isdigit():
            parts.append(f"VLMM, memory {n[6:]}")
        else:
            parts.append(CURVE_LABELS.get(n, n.replace("_", " ")))
    return " = ".join(parts)


# ------------------------------------------------------------------ the experiment
@dataclass
class VlmmEvaluation:
    """E_T curves of ``vlmm evaluate`` and the takes they were measured on.

    ``curves`` maps each predictor's name to its curve (a model asked for
    under two names shares one); ``takes`` are the evaluated index entries and
    the training takes left out, ``other_skeleton`` the takes left out for a
    skeleton the model cannot read.
    """

    curves: dict[str, HorizonCurve]
    takes: TestTakes
    motions: list[Motion]
    horizon: float
    samples: int
    stride: int
    other_skeleton: list[Entry] = field(default_factory=list)
    space: str = "mm"
    notes: list[str] = field(default_factory=list)

    @property
    def seconds(self) -> list[float]:
        """The reported horizons (:data:`REPORT_SECONDS` up to ``horizon``)."""
        return [s for s in REPORT_SECONDS if s <= self.horizon]

    @property
    def n_frames(self) -> int:
        """Frames of the test takes at the model's frame rate (the takes are kept at their
        own: 120 fps takes counted 5,441 frames where 1,361 were evaluated at 30)."""
        fps = next(iter(self.curves.values())).fps if self.curves else None
        if fps is None:
            return sum(m.n_frames for m in self.motions)
        return sum(frames_at(m, fps) for m in self.motions)

    def result(self) -> dict[str, Any]:
        """The JSON of ``vlmm evaluate --json``: ``E_T_mm.<model>.<seconds>`` in mm (or
        ``E_T_configuration.<model>.<seconds>``, eq. 9 in configuration space, to 4
        decimals), the test files, the training files left out and (if any) those of
        another skeleton."""
        digits = 2 if self.space == "mm" else 4
        out: dict[str, Any] = {
            f"E_T_{self.space}.{name}.{s:g}": round(c.at(s), digits)
            for name, c in self.curves.items()
            for s in self.seconds
        }
        out.update(self.takes.report())
        if self.other_skeleton:
            out["left_out_other_skeleton"] = [e.file for e in self.other_skeleton]
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    def plot(self, path: str | os.PathLike[str]) -> None:
        """E_T curves (paper Fig. 4) as a PNG."""
        names: dict[int, list[str]] = {}  # a model asked for under two names: one curve
        for name, c in self.curves.items():
            names.setdefault(id(c), []).append(name)
        unique = [
            replace(c, name=" = ".join(names[id(c)]))
            for c in {id(c): c for c in self.curves.values()}.values()
        ]
        fps = unique[0].fps if unique else 0.0
        every = f", every {ordinal(self.stride)} frame" if self.stride > 1 else ""
        plot_horizon_curves(
            unique,
            path,
            f"E_T on {counted(len(self.motions), 'test takes')} "
            f"({counted(self.n_frames, 'frames')} at {fps:g} fps"
            f"{every}; {counted(self.samples, 'samples')} each)",
            "mean joint error E_T (mm)" if self.space == "mm" else "E_T, configuration (eq. 9)",
        )


def frames_at(motion: Motion, fps: float) -> int:
    """Frames of ``motion`` at ``fps``, as :meth:`Motion.resample` gives them (a take at
    that rate is kept as it is)."""
    if np.isclose(motion.fps, fps):
        return motion.n_frames
    return int(np.floor((motion.n_frames - 1) * fps / motion.fps + 1e-9)) + 1


def _horizons(seconds: Sequence[float]) -> str:
    words = [f"{s:g}" for s in seconds]
    joined = words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
    return f"the {joined} s horizon{'s' if len(words) > 1 else ''}"


def horizon_notes(
    files: Sequence[str], motions: Sequence[Motion], fps: float, seconds: Sequence[float]
) -> list[str]:
    """Notes on the reported horizons (``seconds``) some test takes are too short for: a
    trial at T needs the frame T after the first (eq. 9), so a take of F frames at ``fps``
    measures horizons up to F - 1 frames.

    Raises:
        DataNotFoundError: every take is shorter than the shortest horizon (nothing to
            evaluate; it had printed tables of NaN and an empty plot).
    """
    reach = [frames_at(m, fps) - 1 for m in motions]

    def frames(i: int) -> str:
        return f"{motions[i].n_frames} frame{'s' if motions[i].n_frames != 1 else ''}"

    def short(s: float) -> list[int]:
        return [i for i, r in enumerate(reach) if r < int(round(s * fps))]

    first = min(seconds)
    if len(short(first)) == len(motions):
        if len(motions) == 1:
            what = f"{files[0]}: {frames(0)}, shorter than"
        else:
            takes = first_names([f"{files[i]} ({frames(i)})" for i in range(len(files))])
            what = f"{takes}: every test take is shorter than"
        raise DataNotFoundError(f"{what} {_horizons([first])}: nothing to evaluate")
    notes = []
    unmeasured = [s for s in seconds if len(short(s)) == len(motions)]
    if unmeasured:
        longest = int(np.argmax(reach))
        notes.append(
            f"no test take is as long as {_horizons(unmeasured)} (the longest, "
            f"{files[longest]}, has {frames(longest)}): E_T not measured there"
        )
    measured = [s for s in seconds if s not in unmeasured]
    partly = [
        f"{files[i]} ({frames(i)}: {', '.join(f'{s:g}' for s in measured if i in short(s))} s)"
        for i in range(len(motions))
        if any(i in short(s) for s in measured)
    ]
    if partly:
        notes.append(
            "shorter than some horizons, which are measured on the other takes only: "
            + first_names(partly)
        )
    return notes


def candidate_takes(
    model: BehaviourModel | StructuredBehaviourModel,
    index: MocapIndex,
    held_out: bool = False,
    category: str | None = None,
    labels: Sequence[str] | None = None,
) -> list[Entry]:
    """The takes of ``index`` a behaviour model is evaluated on, before leaving out its
    training takes.

    ``category``/``labels`` given: those takes. Else with ``held_out``: the
    takes the model held out in training (``held_out_files_``, by INDEX.csv
    file name). Else: the takes of the model's category and labels
    (``category_``, ``labels_``; any when the model did not record them).

    Raises:
        DataNotFoundError: ``held_out`` and none of the model's held-out takes is in ``index``.
    """
    if category or labels:
        return index.query(category=category, label=labels or None)
    if held_out:
        listed = set(getattr(model, "held_out_files_", []))
        entries = [e for e in index if e.file in listed]
        if not entries:
            raise DataNotFoundError(
                f"the model lists no held-out takes found in {index.root / 'INDEX.csv'}: "
                "give an index of test takes with --test, or --category/--label"
            )
        return entries
    return index.query(
        category=getattr(model, "category_", None), label=getattr(model, "labels_", None) or None
    )


def evaluate_model(
    model: BehaviourModel | StructuredBehaviourModel,
    index: MocapIndex,
    held_out: bool = False,
    category: str | None = None,
    labels: Sequence[str] | None = None,
    samples: int = 50,
    horizon: float = 3.0,
    stride: int = 1,
    memories: Sequence[int] = (),
    seed: int = 0,
    space: str = "mm",
) -> VlmmEvaluation:
    """E_T (eq. 9) of a behaviour model on the takes of ``index`` that fit it.

    The takes are :func:`candidate_takes` minus those the model trained on (by
    content, :func:`markovmotion.evaluate.takes.test_takes`) minus those of
    another skeleton. Predictors: ``vlmm`` (the model's prototype VLMM),
    ``first_order`` (a first-order Markov model over the same prototypes),
    ``zero_velocity``, ``vlmm_N<n>`` for each of ``memories`` and, for a
    structured model, ``structured``. ``samples`` Monte Carlo predictions from
    every ``stride``-th frame, up to ``horizon`` seconds. ``space``: ``"mm"`` (joint or
    marker positions) or ``"configuration"`` (eq. 9 on C in [0, 1]^d, :class:`ConfigurationSpace`).

    Raises:
        DataNotFoundError: no take fits, every one that does is a training take, or every
            one is shorter than the shortest reported horizon (:func:`horizon_notes`, whose
            notes on takes too short for some horizons the result keeps in ``notes``).
        SkeletonMismatchError: none of the remaining takes has the model's skeleton.
    """
    structured = isinstance(model, StructuredBehaviourModel)
    base = model.prototype_model_ if structured else model
    takes = test_takes(model, index, candidate_takes(model, index, held_out, category, labels))
    motions, kept, other = [], [], []
    for entry in takes.takes:
        motion = index.load_take(entry)
        if base.fits(motion):
            motions.append(motion)
            kept.append(entry)
        else:
            other.append(entry)
    if not motions:
        first = index.load_take(other[0])
        raise SkeletonMismatchError(
            f"no test take of {index.root / 'INDEX.csv'} has the model's skeleton: "
            + ", ".join(e.file for e in other[:5])
            + ("..." if len(other) > 5 else "")
            + f" ({other[0].file}: {base.why_not(first)})"
        )
    takes = TestTakes(kept, takes.left_out)
    seconds = [s for s in REPORT_SECONDS if s <= horizon] or [horizon]
    notes = horizon_notes([e.file for e in kept], motions, base.fps, seconds)
    features = base.observe(motions)
    predictors: dict[str, Any] = {
        "vlmm": base,
        "first_order": base.with_vlmm(*FIRST_ORDER),
        "zero_velocity": ZeroVelocity(base),
    }
    for n in memories:
        predictors[f"vlmm_N{n}"] = base if n == base.max_memory else base.with_vlmm(n, base.epsilon)
    if structured:
        predictors["structured"] = model
    n_frames = int(round(horizon * base.fps))
    curves: dict[str, HorizonCurve] = {}
    by_model: dict[int, HorizonCurve] = {}
    if space not in SPACES:
        raise ValueError(f"space must be one of {SPACES}")
    for name, p in predictors.items():  # a model asked for twice is evaluated once
        if id(p) not in by_model:
            measured = p if space == "mm" else ConfigurationSpace(p)
            by_model[id(p)] = evaluate_horizon(
                measured, features, n_frames, base.fps, samples, stride, seed=seed, name=name
            )
        curves[name] = by_model[id(p)]
    return VlmmEvaluation(curves, takes, motions, horizon, samples, stride, other, space, notes)

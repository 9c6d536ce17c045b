"""Evaluation of the virtual partner on held-out two-person takes (interaction paper, §5).

One partner of each held-out take is masked and generated from the other's
observed shape, by single- and multiple-hypothesis propagation; each person
of a take is masked in turn. Errors (lower is better):

- motion capture: mean joint position error of the partner's pose in mm, in
  its own actor-centred frame (pelvis on the floor, facing +Z), and, as
  ``placement_mm``, in the shared world frame (pose and where it stands);
- silhouettes: mean control-point distance in the image as a fraction of the
  true partner's height.

The baseline holds the partner's mean shape (with the mean separation and
relative scale) beside the real person. In silhouettes it must also pick the
side: ``mean_shape`` puts the partner towards the middle of the training
takes' floor, as a partner that knows only the real person could;
``mean_shape_true_side`` is told where the partner truly is.

The dual-HMM partner (dual-HMM paper) can be measured alongside, the same way
on the same frames: it answers person A (the first file of each pair) with B.

Which takes: :func:`evaluate_model` evaluates a model on the two-person takes
of any INDEX.csv that fit it (interaction pairs of its labels whose skeletons
it can observe), leaving out those it trained on by content hash
(:mod:`markovmotion.evaluate.takes`); without an index, on the held-out pairs
of the collection (:func:`markovmotion.data.splits.held_out_pairs`: of CMU's
salsa takes, trials 12, 13 and 15). Silhouette models are evaluated on the
held-out takes of a folder written by ``silhouette render``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from threadpoolctl import threadpool_limits

from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import choose_kind
from markovmotion.data.splits import held_out_pairs
from markovmotion.defaults import SOURCES
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.evaluate.takes import test_takes
from markovmotion.features.joint_shape import Person, TwoPeople, person_from_motion
from markovmotion.models.chain.condensation import (
    DEFAULT_RESPONSE,
    DEFAULT_RESYNC,
    DEFAULT_SIGMA,
    RESPONSES,
)
from markovmotion.models.chain.partner import KINDS, VirtualPartner
from markovmotion.progress import err_console, track

if TYPE_CHECKING:
    from markovmotion.models.hmm.dual import DualHMM


def mocap_takes(
    index: MocapIndex, pairs: Sequence[tuple[Entry, Entry]], fps: float = 25.0
) -> list[TwoPeople]:
    """Both people of each take as joint positions at ``fps`` (the paper's 25 fps)."""
    return [
        TwoPeople.from_motions(*index.load_pair(a, b), fps=fps)
        for a, b in track(pairs, "reading takes")
    ]


def model_labels(model: VirtualPartner, labels: Sequence[str] | None = None) -> list[str] | None:
    """The labels of two-person takes the model answers: ``labels``, else those it was trained
    on (``labels_``, saved by ``chain train``), else None (any)."""
    if labels:
        return list(labels)
    known = getattr(model, "labels_", None)
    return list(known) if known else None


@dataclass
class TestSet:
    """The takes a chain model is evaluated on, and what the JSON says of them.

    Attributes:
        takes: both people of each take (joint positions, or tracked silhouettes).
        pairs: the INDEX.csv entries of each take (motion capture), else None.
        index: the index they come from (motion capture), else None.
        report: ``test_files`` and ``left_out_training_files``.
    """

    __test__ = False  # not a pytest class

    takes: list[TwoPeople]
    pairs: list[tuple[Entry, Entry]] | None = None
    index: MocapIndex | None = None
    report: dict[str, list[str]] = field(default_factory=dict)


def test_set(
    model: VirtualPartner,
    test: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    takes: Sequence[TwoPeople] | None = None,
) -> TestSet:
    """The takes to evaluate ``model`` on (see the module docstring).

    Motion capture: the interaction pairs of ``test`` (an INDEX.csv or its
    folder) with the model's labels (:func:`model_labels`), minus the model's
    training takes (by content hash), minus pairs whose skeletons the model
    cannot observe (a warning each); without ``test``, the held-out pairs of the
    collection. Prepared ``takes`` (silhouettes tracked by
    :func:`markovmotion.video.dataset.silhouette_takes`) are taken as they are.

    Raises:
        DataNotFoundError: no take remains (one line saying why).
    """
    if takes is not None:
        if not takes:
            raise DataNotFoundError(f"{test or 'the test folder'}: no held-out takes")
        names = [t.name for t in takes]
        return TestSet(list(takes), report={"test_files": names, "left_out_training_files": []})
    if model.source != "mocap":
        raise ValueError("a silhouette model is evaluated on tracked takes: give takes")
    index = MocapIndex.load(test)
    candidates, _ = choose_kind(
        index.pairs(label=model_labels(model, labels)),
        None,
        "two-person takes",
        lambda p: p[0],
        KINDS,
    )
    if test is None:
        _, candidates = held_out_pairs(candidates)
    chosen = test_takes(model, index, candidates, "two-person take")
    pairs, takes = [], []
    for a, b in track(chosen.takes, "reading takes"):
        try:
            motions = index.load_pair(a, b)
            for m in motions:
                model.check_input(m)
        except MarkovMotionError as exc:
            err_console.print(f"[yellow]skipped[/] {a.file} + {b.file}: {exc}", highlight=False)
            continue
        pairs.append((a, b))
        takes.append(TwoPeople.from_motions(*motions, fps=model.fps_))
    if not takes:
        raise DataNotFoundError(
            f"no two-person take of {index.root / 'INDEX.csv'} can be observed by the model"
        )
    chosen.takes = pairs
    return TestSet(takes, pairs, index, chosen.report())


def evaluate_model(
    model: VirtualPartner,
    test: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    n_hypotheses: int = 200,
    response: str = DEFAULT_RESPONSE,
    seed: int = 0,
    sigma: float = DEFAULT_SIGMA,
    resync: float = DEFAULT_RESYNC,
    dual_hmm: DualHMM | None = None,
    takes: Sequence[TwoPeople] | None = None,
) -> dict:
    """:func:`evaluate_partner` on :func:`test_set`'s takes, with its ``test_files`` and
    ``left_out_training_files``; ``dual_hmm`` (motion capture) is measured alongside."""
    chosen = test_set(model, test, labels, takes)
    others = None
    if dual_hmm is not None:
        if chosen.index is None or chosen.pairs is None:
            raise ValueError("a dual HMM is compared on 3-D partners: give a mocap model")
        others = dual_hmm_partners(dual_hmm, chosen.index, chosen.pairs, chosen.takes)
    result = evaluate_partner(
        model, chosen.takes, model.source, n_hypotheses, response, seed, others, sigma, resync
    )
    return {**result, **chosen.report}


def pose_error_mm(model: VirtualPartner, pred: Person, truth: Person) -> float:
    """Mean joint distance (mm) between two people's poses, each in its own actor-centred frame."""
    js = model.shape_step
    k = js.n_points_

    def pose(p: Person) -> np.ndarray:
        return js.shape_vectors(p).reshape(p.n_frames, k, -1) * p.height[:, None, None]

    return float(np.linalg.norm(pose(pred) - pose(truth), axis=-1).mean())


def point_error(pred: Person, truth: Person, relative: bool) -> float:
    """Mean distance between corresponding points; divided by the true height if ``relative``."""
    dist = np.linalg.norm(pred.points - truth.points, axis=-1)
    if relative:
        dist = dist / truth.height[:, None]
    return float(dist.mean())


def dual_hmm_partners(
    dual: DualHMM,
    index: MocapIndex,
    pairs: Sequence[tuple[Entry, Entry]],
    takes: Sequence[TwoPeople],
) -> dict[str, list[tuple[Person | None, Person | None]]]:
    """The dual HMM's partner B of person A (person 0) of each take, for :func:`evaluate_partner`.

    B is generated by standard and by windowed Viterbi (dual-HMM paper §3),
    resampled to the takes' rate if the model's differs, and seen through the
    same shape joints as the takes, so that both models are measured alike.
    """
    from markovmotion.models.hmm.dual import METHODS

    out: dict[str, list[tuple[Person | None, Person | None]]] = {
        f"dual_hmm_{m}": [] for m in METHODS
    }
    for (ea, eb), take in zip(track(pairs, "dual HMM partners"), takes, strict=True):
        a, _ = index.load_pair(ea, eb)
        for m in METHODS:
            b = dual.respond(a, m).resample(take.fps)
            short = take.n_frames - b.n_frames
            if short > max(1.0, take.fps / dual.fps):
                raise DataNotFoundError(
                    f"{take.name}: the dual HMM gave {b.n_frames} frames, not {take.n_frames}"
                )
            if short > 0:  # resampling's rounding at the end: hold the last frame
                keep = np.r_[np.arange(b.n_frames), np.full(short, b.n_frames - 1)]
                b = replace(b, rotations=b.rotations[keep], translations=b.translations[keep])
            out[f"dual_hmm_{m}"].append((person_from_motion(b.trim(0, take.n_frames)), None))
    return out


def _errors(
    model: VirtualPartner, source: str, pred: Person, truth: Person
) -> tuple[float, float | None]:
    """(error, world placement error or None) of one partner over its frames."""
    if source == "mocap":
        return pose_error_mm(model, pred, truth), point_error(pred, truth, False)
    return point_error(pred, truth, True), None


def evaluate_partner(
    model: VirtualPartner,
    takes: Sequence[TwoPeople],
    source: str = "mocap",
    n_hypotheses: int = 200,
    response: str = DEFAULT_RESPONSE,
    seed: int = 0,
    others: Mapping[str, Sequence[tuple[Person | None, Person | None]]] | None = None,
    sigma: float = DEFAULT_SIGMA,
    resync: float = DEFAULT_RESYNC,
) -> dict:
    """Errors of the single- and multiple-hypothesis partners and of the mean-shape baseline.

    Each person of a take is masked in turn. The multiple-hypothesis partner is
    computed with every response (``multiple_hypotheses_ml``, ``_map``,
    ``_mean``), all with likelihood width ``sigma`` (eq. 20);
    ``multiple_hypotheses`` repeats the one named by ``response``. The single
    hypothesis re-synchronises with margin ``resync`` (inf: never).
    ``others`` adds partners from other models: per take, the partner of
    person 0 and of person 1 (None where the model gives none). Errors are
    means over frames, overall (methods that answer both people) and in
    ``by_real_person`` (which person was real).

    In silhouette takes person 0 and 1 are two identities (not left and right):
    the model matches the real person to either half (eq. 18); the baseline
    takes the side towards the floor's middle (:meth:`VirtualPartner.centre_roles`)
    and, as ``mean_shape_true_side``, the side where the partner truly is.
    """
    if source not in SOURCES:
        raise ValueError(f"source must be one of {SOURCES}, got {source!r}")
    if response not in RESPONSES:
        raise ValueError(f"response must be one of {RESPONSES}, got {response!r}")
    if not takes:
        raise ValueError("no takes to evaluate on")
    others = others or {}
    methods = {
        "single_hypothesis": {"n_hypotheses": 1, "resync": resync},
        **{
            f"multiple_hypotheses_{r}": {
                "n_hypotheses": n_hypotheses,
                "response": r,
                "sigma": sigma,
            }
            for r in RESPONSES
        },
    }
    # sums[name][real person] of frame-weighted errors, and the frames they cover
    baselines = ["mean_shape"] if source == "mocap" else ["mean_shape", "mean_shape_true_side"]
    names = [*baselines, *methods, *others]
    sums = {k: [0.0, 0.0] for k in names}
    placed = {k: [0.0, 0.0] for k in names}
    frames = {k: [0, 0] for k in names}
    seconds = {k: 0.0 for k in methods}
    jobs = [(i, take, person) for i, take in enumerate(takes) for person in (0, 1)]
    with threadpool_limits(1):  # per-frame times on one core, as for real-time use
        for i, take, person in track(jobs, "virtual partners"):
            real, truth = take.person(person), take.person(1 - person)
            if source == "mocap":
                role = person
                partners = {"mean_shape": model.mean_partner(real, np.full(take.n_frames, role))}
            else:
                role = None
                true_roles = (real.reference[:, 0] > truth.reference[:, 0]).astype(int)
                partners = {
                    "mean_shape": model.mean_partner(real, model.centre_roles(real)),
                    "mean_shape_true_side": model.mean_partner(real, true_roles),
                }
            for name, options in methods.items():
                start = time.perf_counter()
                partners[name] = model.respond_shapes(real, role, rng=seed, **options).partner
                seconds[name] += time.perf_counter() - start
            partners.update({k: v[i][person] for k, v in others.items()})
            for name, pred in partners.items():
                if pred is None:
                    continue
                err, place = _errors(model, source, pred, truth)
                sums[name][person] += err * take.n_frames
                placed[name][person] += (place or 0.0) * take.n_frames
                frames[name][person] += take.n_frames
    total = sum(t.n_frames for t in takes)
    both = [k for k in names if sum(frames[k]) == 2 * total]

    def table(errors: dict[str, list[float]], people: tuple[int, ...], keys: list[str]) -> dict:
        return {
            k: float(sum(errors[k][p] for p in people) / sum(frames[k][p] for p in people))
            for k in keys
        }

    def section(people: tuple[int, ...], keys: list[str]) -> dict:
        out = table(sums, people, keys)
        out["multiple_hypotheses"] = out[f"multiple_hypotheses_{response}"]
        if source == "mocap":
            place = table(placed, people, keys)
            place["multiple_hypotheses"] = place[f"multiple_hypotheses_{response}"]
            out["placement_mm"] = place
        return out

    per_frame_ms = {k: 1000.0 * s / (2 * total) for k, s in seconds.items()}
    per_frame_ms["multiple_hypotheses"] = per_frame_ms[f"multiple_hypotheses_{response}"]
    return {
        "unit": "mm" if source == "mocap" else "fraction of body height",
        **section((0, 1), both),
        "multiple_hypotheses_response": response,
        "per_frame_ms": per_frame_ms,
        "by_real_person": [section((p,), [k for k in names if frames[k][p]]) for p in (0, 1)],
        "source": source,
        "hypotheses": n_hypotheses,
        "sigma": sigma,
        "resync": resync if np.isfinite(resync) else None,
        "takes": [t.name for t in takes],
        "frames": 2 * total,
    }

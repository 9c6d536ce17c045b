"""Evaluation of the virtual partner on held-out two-person takes (interaction paper, §5).

One partner of each held-out take is masked and generated from the other's
observed shape, by single- and multiple-hypothesis propagation; each person
of a take is masked in turn. Errors (lower is better):

- motion capture: mean joint position error of the partner's pose in mm, in
  its own actor-centred frame (pelvis on the floor, facing +Z), and, as
  ``placement_mm``, in the shared world frame (pose and where it stands);
- silhouettes: mean control-point distance in the image as a fraction of the
  true partner's height.

How much a 3-D partner jumps, beside the real partner: ``jump_p90_mm``, the 90th
percentile of its median point's frame-to-frame steps, measured as the dual HMM's
(:func:`markovmotion.evaluate.takes.jump_sizes`).

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
from sklearn.base import clone
from threadpoolctl import threadpool_limits

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import choose_kind
from markovmotion.data.splits import held_out_pairs
from markovmotion.defaults import SOURCES
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.evaluate import choose
from markovmotion.evaluate.choose import ROLES
from markovmotion.evaluate.takes import (
    evaluation_index,
    jump_p90,
    jump_sizes,
    people_trained_on,
    take_names,
    test_takes,
)
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
    index = evaluation_index(model, test)
    candidates, _ = choose_kind(
        index.pairs(label=model_labels(model, labels)),
        "markers" if model.uses_markers else "skeleton",
        "two-person takes",
        lambda p: p[0],
        KINDS,
    )
    held = getattr(model, "held_out_files_", None)
    if test is None and held is not None:  # the takes it held out, in the index it learnt
        listed = set(held)
        candidates = [p for p in candidates if p[0].file in listed]
        if not candidates:
            raise DataNotFoundError(
                f"none of the {len(held)} files the model held out at training is a two-person "
                f"take of {index.root / 'INDEX.csv'} it can answer: give --test INDEX"
                if held
                else "the model held no take out at training (--test-trials none): give --test INDEX"
            )
    elif test is None:  # a model saved before it recorded them: the collection's split
        _, candidates = held_out_pairs(candidates)
    chosen = test_takes(model, index, candidates, "two-person take")
    pairs, takes = [], []
    for a, b in track(chosen.takes, "reading takes"):
        try:  # a marker the model sees never seen in one take: that take skipped, said
            motions = index.load_pair(a, b)
            for m in motions:
                model.check_input(m)
            take = model.two_people(*motions)
        except MarkovMotionError as exc:
            err_console.print(f"[yellow]skipped[/] {a.file} + {b.file}: {exc}", highlight=False)
            continue
        pairs.append((a, b))
        takes.append(take)
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
    ``left_out_training_files``, ``per_people`` (the same for each pair of people,
    INDEX.csv's ``subject``, when the takes come from two or more) and (motion capture)
    ``people_trained_on`` (those pairs the model learnt other takes of); ``dual_hmm``
    (motion capture) is measured alongside."""
    chosen = test_set(model, test, labels, takes)
    others = None
    if dual_hmm is not None:
        if chosen.index is None or chosen.pairs is None:
            raise ValueError("a dual HMM is compared on 3-D partners: give a mocap model")
        others = dual_hmm_partners(dual_hmm, chosen.index, chosen.pairs, chosen.takes, model)
    people = [a.subject for a, _ in chosen.pairs] if chosen.pairs else None
    result = evaluate_partner(
        model, chosen.takes, model.source, n_hypotheses, response, seed, others, sigma, resync,
        people=people,
    )  # fmt: skip
    if chosen.index is not None and chosen.pairs:
        result["people_trained_on"] = people_trained_on(model, chosen.index, chosen.pairs)
    return {**result, **chosen.report}


def pose_error_mm(model: VirtualPartner, pred: Person, truth: Person) -> float:
    """Mean joint distance (mm) between two people's poses, each in its own frame on the floor:
    about its reference point with the height kept (a skeleton's pelvis on the floor; markers'
    centroid on the floor, as the dual HMM's body-centred error), facing +Z."""
    js = model.shape_step
    k = js.n_points_

    def pose(p: Person) -> np.ndarray:
        floor = p.reference.copy()
        floor[:, 1] = 0.0
        p = Person(p.points, floor, p.height, p.heading)
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
    chain: VirtualPartner | None = None,
) -> dict[str, list[tuple[Person | None, Person | None]]]:
    """The dual HMM's partner B of person A (person 0) of each take, for :func:`evaluate_partner`.

    B is generated by standard and by windowed Viterbi (dual-HMM paper §3),
    resampled to the takes' rate if the model's differs, and seen through the
    same shape joints (or markers) as the takes by ``chain`` (default: the shape joints
    of :func:`person_from_motion`), so that both models are measured alike.
    """
    see = chain.person if chain is not None else person_from_motion
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
                if isinstance(b, Markers):
                    b = Markers(b.names, b.positions[keep], b.fps, b.name)
                else:
                    b = replace(b, rotations=b.rotations[keep], translations=b.translations[keep])
            out[f"dual_hmm_{m}"].append((see(b.trim(0, take.n_frames)), None))
    return out


def _errors(
    model: VirtualPartner, source: str, pred: Person, truth: Person
) -> tuple[float, float | None]:
    """(error, world placement error or None) of one partner over its frames."""
    if source == "mocap":
        return pose_error_mm(model, pred, truth), point_error(pred, truth, False)
    return point_error(pred, truth, True), None


#: The key of the real partner in ``jump_p90_mm`` (how much the real partner moves).
REAL = "real"


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
    steps: dict[str, list[list[np.ndarray]]] | None = None,
    people: Sequence[str] | None = None,
) -> dict:
    """Errors of the single- and multiple-hypothesis partners and of the mean-shape baseline.

    Each person of a take is masked in turn. The multiple-hypothesis partner is
    computed with every response (``multiple_hypotheses_ml``, ``_map``,
    ``_mean``), all with likelihood width ``sigma`` (eq. 20);
    ``multiple_hypotheses`` repeats the one named by ``response``. The single
    hypothesis re-synchronises with margin ``resync`` (inf: never; our addition), and
    ``single_hypothesis_paper`` is §5.1's, never re-synchronised (with ``resync`` inf the
    same partner).
    ``others`` adds partners from other models: per take, the partner of
    person 0 and of person 1 (None where the model gives none). Errors are
    means over frames, overall (methods that answer both people) and in
    ``by_real_person`` (which person was real).

    How much each partner jumps (motion capture): ``jump_p90_mm``, the 90th percentile
    over every frame step of how far the partner's median point moves
    (:func:`markovmotion.evaluate.takes.jump_sizes`, the dual HMM's ``*_jump_p90_mm``),
    with ``real`` the real partner's. ``steps``, if given (a dict), is filled with those
    steps: per partner (and ``real``), a list of arrays for each real person (0, 1).

    ``people``: who each take's pair of people are (INDEX.csv's ``subject``); when they are
    two or more pairs, ``per_people`` has the same report for each pair's takes, from the
    same answers (each take is answered once).

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
        # §5.1 as printed, never re-synchronised: the one hypothesis the paper compares with
        "single_hypothesis_paper": {"n_hypotheses": 1, "resync": np.inf},
        **{
            f"multiple_hypotheses_{r}": {
                "n_hypotheses": n_hypotheses,
                "response": r,
                "sigma": sigma,
            }
            for r in RESPONSES
        },
    }
    # sums[name][take, real person] of frame-weighted errors, and the frames they cover
    baselines = ["mean_shape"] if source == "mocap" else ["mean_shape", "mean_shape_true_side"]
    names = [*baselines, *methods, *others]
    sums = {k: np.zeros((len(takes), 2)) for k in names}
    placed = {k: np.zeros((len(takes), 2)) for k in names}
    frames = {k: np.zeros((len(takes), 2), dtype=int) for k in names}
    seconds = {k: 0.0 for k in methods}
    # frame steps (mm) per partner (and the real one), take and real person (None: no partner)
    moves: dict[str, list[list]] = {k: [[None, None] for _ in takes] for k in (*names, REAL)}
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
                sums[name][i, person] = err * take.n_frames
                placed[name][i, person] = (place or 0.0) * take.n_frames
                frames[name][i, person] = take.n_frames
                moves[name][i][person] = jump_sizes(pred.points)
            moves[REAL][i][person] = jump_sizes(truth.points)
    if steps is not None:
        steps.update(
            {k: [[m[p] for m in v if m[p] is not None] for p in (0, 1)] for k, v in moves.items()}
        )

    def report(which: list[int]) -> dict:
        """The report over the takes ``which``."""
        total = sum(takes[i].n_frames for i in which)

        def table(errors: dict[str, np.ndarray], people: tuple[int, ...], keys: list[str]) -> dict:
            return {
                k: float(errors[k][which][:, people].sum() / frames[k][which][:, people].sum())
                for k in keys
            }

        def section(people: tuple[int, ...], keys: list[str]) -> dict:
            out = table(sums, people, keys)
            out["multiple_hypotheses"] = out[f"multiple_hypotheses_{response}"]
            if source == "mocap":
                place = table(placed, people, keys)
                place["multiple_hypotheses"] = place[f"multiple_hypotheses_{response}"]
                out["placement_mm"] = place
                jumps = {
                    k: jump_p90(
                        [m for i in which for p in people if (m := moves[k][i][p]) is not None]
                    )
                    for k in (*keys, REAL)
                }
                jumps["multiple_hypotheses"] = jumps[f"multiple_hypotheses_{response}"]
                out["jump_p90_mm"] = jumps
            return out

        mine = {k: frames[k][which] for k in names}
        return {
            "unit": "mm" if source == "mocap" else "fraction of body height",
            **section((0, 1), [k for k in names if mine[k].sum() == 2 * total]),
            "multiple_hypotheses_response": response,
            "by_real_person": [
                section((p,), [k for k in names if mine[k][:, p].sum()]) for p in (0, 1)
            ],
            "source": source,
            "hypotheses": n_hypotheses,
            "sigma": sigma,
            "resync": resync if np.isfinite(resync) else None,
            "takes": [takes[i].name for i in which],
            "frames": 2 * total,
        }

    result = report(list(range(len(takes))))
    total = sum(t.n_frames for t in takes)
    per_frame_ms = {k: 1000.0 * s / (2 * total) for k, s in seconds.items()}
    per_frame_ms["multiple_hypotheses"] = per_frame_ms[f"multiple_hypotheses_{response}"]
    result["per_frame_ms"] = per_frame_ms
    groups = sorted(set(people or []) - {""})
    result["per_people"] = {
        who: report([i for i, p in enumerate(people or []) if p == who])
        for who in (groups if len(set(people or [])) > 1 else [])
    }
    return result


# ------------------------------------------------------------------ new people: crossval
#: The partners a cross-validation reports, in its tables' order: the multiple hypotheses
#: with the response asked for, the other responses, one hypothesis, and the baselines.
PARTNERS = (
    "multiple_hypotheses",
    *(f"multiple_hypotheses_{r}" for r in RESPONSES),
    "single_hypothesis",
    "single_hypothesis_paper",
    "mean_shape",
    "nearest_neighbour",
)

#: A two-person take of a cross-validation: name, label, people (INDEX.csv's subject), A, B.
Take = tuple[str, str, str, Motion | Markers, Motion | Markers]


def nearest_partners(
    model: VirtualPartner, train: Sequence[TwoPeople], take: TwoPeople
) -> tuple[Person, Person]:
    """Baseline: each real person of ``take`` answered frame by frame with the partner of the
    training frame whose real-person half is nearest (the smoothed, normalised shape S^H of
    eq. 18 against the same half of the training C's), placed as the chain places its own
    (:meth:`VirtualPartner.place`). Returns the partners of person 0 and of person 1."""
    from sklearn.neighbors import NearestNeighbors

    c = np.vstack(model.pipeline_.transform(list(train)))[:, : model.chain_.dim]
    out = []
    for person in (0, 1):
        real = take.person(person)
        half = c[:, model.shape_step.person_slice(person)]
        nn = NearestNeighbors(n_neighbors=1).fit(half)
        idx = nn.kneighbors(model.observe(real, person), return_distance=False)[:, 0]
        out.append(model.place(c[idx], np.full(len(idx), person), real))
    return out[0], out[1]


def _fit_on(model: VirtualPartner, takes: Sequence[Take], roles: str) -> VirtualPartner:
    """``model`` (unfitted) trained on ``takes`` in ``roles``
    (:func:`markovmotion.evaluate.choose.learnt`): every fit of a cross-validation."""
    learn, _ = choose.learnt([(t[0], t[1], t[3], t[4]) for t in takes], [t[2] for t in takes],
                             roles)  # fmt: skip
    return model.fit([(a, b) for _, _, a, b in learn])


def _scores(result: Mapping, frames: int, steps: Mapping[str, list[list[np.ndarray]]]) -> dict:
    """One take's errors from :func:`evaluate_partner` (and its frame ``steps``), as
    :func:`_pool` sums them."""
    response = f"multiple_hypotheses_{result['multiple_hypotheses_response']}"
    return {
        "frames": frames,
        "world_mm": {k: result["placement_mm"][k] for k in PARTNERS},
        "body_centred_mm": {k: result[k] for k in PARTNERS},
        "per_frame_ms": {k: result["per_frame_ms"][k] for k in result["per_frame_ms"]},
        "steps": {
            k: [s for per in steps[response if k == "multiple_hypotheses" else k] for s in per]
            for k in (*PARTNERS, REAL)
        },
    }


def _pool(rows: Sequence[Mapping]) -> dict:
    """Frame-weighted means of per-take :func:`_scores` (mm to 0.1, ms to 0.01), frames,
    takes, how much each partner jumps (``jump_p90_mm``: :func:`jump_p90` over the takes'
    frame steps, ``real`` the real partner's), and whether the aim is met: multiple
    hypotheses below one hypothesis and the mean shape, in the world and body-centred:
    ``aim_met`` against the re-synchronised single hypothesis (the stronger),
    ``aim_met_paper`` against §5.1's."""
    frames = sum(r["frames"] for r in rows)

    def mean(part: str, key: str) -> float:
        return sum(r[part][key] * r["frames"] for r in rows) / frames

    out: dict = {
        part: {k: round(mean(part, k), 1) for k in PARTNERS}
        for part in ("world_mm", "body_centred_mm")
    }
    out["per_frame_ms"] = {k: round(mean("per_frame_ms", k), 2) for k in rows[0]["per_frame_ms"]}
    out["jump_p90_mm"] = {
        k: jump_p90([s for r in rows for s in r["steps"][k]]) for k in (*PARTNERS, REAL)
    }
    for key, single in (
        ("aim_met", "single_hypothesis"),
        ("aim_met_paper", "single_hypothesis_paper"),
    ):
        out[key] = {
            part: bool(
                out[part]["multiple_hypotheses"] < min(out[part][single], out[part]["mean_shape"])
            )
            for part in ("world_mm", "body_centred_mm")
        }
    out.update(frames=int(frames), takes=len(rows))
    return out


def cross_validate_people(
    takes: Sequence[Take],
    model: VirtualPartner,
    n_hypotheses: int = 200,
    response: str = DEFAULT_RESPONSE,
    seed: int = 0,
    sigma: float = DEFAULT_SIGMA,
    resync: float = DEFAULT_RESYNC,
    roles: str = "one",
    per_label: bool = True,
    grid: Sequence[Mapping] | None = None,
) -> dict:
    """Leave one pair of people out at a time: each take is answered by a copy of ``model``
    (same settings) trained on the takes of the other pairs of people alone.

    ``takes``: ``(name, label, people, A, B)``, names unique, ``people`` INDEX.csv's ``subject`` (with
    one pair of people in all, one take is left out at a time). ``per_label``: one model
    per label (action), trained on that label's takes of the other people; else one model
    of every label. ``roles="both"``: each fold also learns its takes with A and B swapped.
    Each take is answered with each person masked in turn (:func:`evaluate_partner`: the
    multiple hypotheses with every response, ``response`` repeated as
    ``multiple_hypotheses``; one hypothesis; the mean shape), and by the nearest neighbour
    (:func:`nearest_partners`), in the world (``world_mm``) and body-centred
    (``body_centred_mm``: each person in its own frame, :func:`pose_error_mm`), with how
    much each partner jumps (``jump_p90_mm``, beside the real partner's, ``real``).

    ``grid``: settings to choose from in each fold (dicts of the model's parameters, and
    optionally ``roles``: :func:`parse_grid`), by leaving pairs of people out on the fold's
    training takes alone (:func:`choose_settings`: nested); each fold reports what it chose.

    Returns the JSON of ``chain crossval``: ``model`` (settings), ``overall``,
    ``per_label`` (each with its ``per_people``), ``per_people`` (over every label),
    ``per_pair`` (per take), ``folds`` (per fold: the
    files it trained on, as the fitted copy records them, the takes it answered, and
    with ``grid`` the settings chosen), ``left_out`` and ``roles``.
    """
    if roles not in ROLES:
        raise ValueError(f"roles must be one of {', '.join(ROLES)}, got {roles!r}")
    if not takes:
        raise DataNotFoundError("no two-person takes to cross-validate on")
    names = [t[0] for t in takes]
    if len(set(names)) < len(names):
        raise ValueError("the takes' names must be unique (they key the report)")
    groups = choose.fold_groups([t[2] for t in takes], names)
    scopes = sorted({t[1] for t in takes}) if per_label else [None]
    rows: dict[str, dict] = {}
    folds = []
    for scope in scopes:
        mine = [i for i, t in enumerate(takes) if scope is None or t[1] == scope]
        for group in track(
            list(dict.fromkeys(groups[i] for i in mine)), f"{scope or 'all'}: folds"
        ):
            rest = [takes[i] for i in mine if groups[i] != group]
            test = [i for i in mine if groups[i] == group]
            if not rest:
                raise DataNotFoundError(
                    f"{scope or 'the takes'}: only one pair of people ({group}), nothing to train on"
                )
            fold, fold_roles, chosen = clone(model), roles, {}
            if grid:
                chosen = choose_settings(
                    rest, fold, grid, roles, n_hypotheses, response, seed, sigma
                )
                fold_roles = chosen["settings"].get("roles", roles)
                fold.set_params(**choose.model_params(chosen["settings"]))
            fold = _fit_on(fold, rest, fold_roles)
            seen = [fold.two_people(t[3], t[4]) for t in rest]
            if fold_roles == "both":
                seen += [fold.two_people(t[4], t[3]) for t in rest]
            for i in test:
                name, label, people, a, b = takes[i]
                take = fold.two_people(a, b)
                nn = nearest_partners(fold, seen, take)
                steps: dict = {}
                result = evaluate_partner(
                    fold, [take], "mocap", n_hypotheses, response, seed,
                    {"nearest_neighbour": [nn]}, sigma, resync, steps,
                )  # fmt: skip
                rows[name] = {
                    **_scores(result, 2 * take.n_frames, steps),
                    "label": label,
                    "people": people,
                }
            folds.append(
                {
                    "label": scope,
                    "left_out": group,
                    "trained_on": [r["file"] for r in fold.train_files_],
                    "tested_on": [takes[i][0] for i in test],
                    **({"chosen": chosen} if chosen else {}),
                }
            )
    labels = sorted({t[1] for t in takes})
    people = sorted({t[2] for t in takes})
    per_pair = {n: _pool([rows[n]]) | {"label": rows[n]["label"], "people": rows[n]["people"]}
                for n in names}  # fmt: skip
    return {
        "model": {
            **{k: v for k, v in model.get_params().items() if k != "interval_noise"},
            "hypotheses": n_hypotheses,
            "response": response,
            "sigma": sigma,
            "resync": resync if np.isfinite(resync) else None,
            "models": "one per label" if per_label else "one for all labels",
        },
        "overall": _pool([rows[n] for n in names]),
        "per_label": {
            lab: _pool([r for r in rows.values() if r["label"] == lab])
            | {
                "per_people": {
                    p: _pool([r for r in rows.values() if r["label"] == lab and r["people"] == p])
                    for p in people
                    if any(r["label"] == lab and r["people"] == p for r in rows.values())
                }
            }
            for lab in labels
        },
        "per_people": {p: _pool([r for r in rows.values() if r["people"] == p]) for p in people},
        "per_pair": per_pair,
        "folds": folds,
        "left_out": "pairs of people" if len(set(t[2] for t in takes)) > 1 else "takes",
        "roles": roles,
    }


def parse_grid(text: str) -> list[dict]:
    """Settings of a behaviour chain to choose among, ``"param=v1,v2;param=v1,v2"``
    (:func:`markovmotion.evaluate.choose.parse_grid` over VirtualPartner's parameters and
    ``roles``; ``n_state_prototypes+n_behaviour_prototypes=20,40`` ties the two counts)."""
    grid = choose.parse_grid(text, choose.grid_defaults(VirtualPartner()))
    for setting in grid:  # a value out of its choices is refused before anything is learnt
        VirtualPartner(**choose.model_params(setting)).check_params()
    return grid


def choose_settings(
    takes: Sequence[Take],
    model: VirtualPartner,
    grid: Sequence[Mapping],
    roles: str = "one",
    n_hypotheses: int = 200,
    response: str = DEFAULT_RESPONSE,
    seed: int = 0,
    sigma: float = DEFAULT_SIGMA,
) -> dict:
    """The setting of ``grid`` (dicts of ``model``'s parameters, and optionally ``roles``,
    else ``roles``) whose multiple-hypothesis partner (``n_hypotheses``, ``response``,
    ``sigma``, eq. 20) has the lowest error, world plus body-centred (mm, frame-weighted, each
    person of a take masked in turn as in :func:`evaluate_partner`), by leaving one pair of
    people out at a time on ``takes`` alone (a fold's training takes; one take at a time when
    they come from one pair): :func:`markovmotion.evaluate.choose.choose_settings`.
    Returns ``settings`` (the pick) and ``inner_mm`` (every setting's error)."""
    groups = choose.fold_groups([t[2] for t in takes], [t[0] for t in takes], choosing=True)

    def fit(settings: Mapping, train: list[int]) -> VirtualPartner:
        copy = clone(model).set_params(**choose.model_params(settings))
        return _fit_on(copy, [takes[i] for i in train], settings.get("roles", roles))

    def score(fold: VirtualPartner, settings: Mapping, test: list[int]) -> tuple[float, int]:
        error, frames = 0.0, 0
        with threadpool_limits(1):
            for i in test:
                take = fold.two_people(takes[i][3], takes[i][4])
                for person in (0, 1):
                    real, truth = take.person(person), take.person(1 - person)
                    options = dict(n_hypotheses=n_hypotheses, response=response, sigma=sigma)
                    pred = fold.respond_shapes(real, person, rng=seed, **options).partner
                    body, world = _errors(fold, "mocap", pred, truth)
                    error += (body + (world or 0.0)) * take.n_frames
                    frames += take.n_frames
        return error, frames

    return choose.choose_settings(grid, groups, fit, score)


def fit_takes(
    model: VirtualPartner,
    takes: Sequence[Take],
    roles: str = "one",
    grid: Sequence[Mapping] | None = None,
    **scoring,
) -> tuple[VirtualPartner, dict]:
    """``chain train`` on two-person takes ``(name, label, people, A, B)``: ``model`` fitted on
    every take in ``roles``; with ``grid``, the setting (and roles) first chosen among it by
    leaving one pair of people out on these takes (:func:`choose_settings`, with ``scoring``:
    ``n_hypotheses``, ``response``, ``seed``, ``sigma``). Returns the model and the extras to
    save with it: ``roles`` and, with ``grid``, ``chosen`` (the pick and every setting's
    error)."""
    chosen: dict = {}
    if grid:
        chosen = choose_settings(takes, model, grid, roles, **scoring)
        roles = chosen["settings"].get("roles", roles)
        model.set_params(**choose.model_params(chosen["settings"]))
    return _fit_on(model, takes, roles), {"roles": roles} | ({"chosen": chosen} if chosen else {})


def crossval_index(
    model: VirtualPartner,
    data: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    kind: str | None = None,
    **options,
) -> dict:
    """``chain crossval``: :func:`cross_validate_people` over the two-person takes of
    ``labels`` in the index at ``data``, of one kind and set
    (:func:`markovmotion.evaluate.hmm.load_pairs`, which says what it leaves out); the JSON
    with ``test_files`` (every take's files: each is answered once)."""
    from markovmotion.data.splits import select_pairs
    from markovmotion.evaluate.hmm import load_pairs

    index = MocapIndex.load(data)
    pairs, loaded = load_pairs(index, select_pairs(index, labels, None, held_out=False), kind)
    names = take_names(pairs)
    takes = [(names[p], p[0].label, p[0].subject, *ab) for p, ab in zip(pairs, loaded, strict=True)]
    report = cross_validate_people(takes, model, **options)
    report["test_files"] = [e.file for pair in pairs for e in pair]
    return report

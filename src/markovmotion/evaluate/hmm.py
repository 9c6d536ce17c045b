"""Accuracy of a virtual partner against the real one (dual-HMM paper §4.1, Figs. 6-8).

For every two-person take of a test set, B is generated from A by standard
and by windowed Viterbi, through each trellis (``"path"``, ours, and
``"paper"``, §3.2 as printed), and each frame's error is the Euclidean
distance between generated and real positions, in mm, averaged over the
common body points (:mod:`markovmotion.features.body_points`, so the real B
may come on another skeleton than the model's) after forward kinematics --
world positions, B being placed through A's real ground frame, so the error
counts both B's pose and where B stands relative to A. How much B jumps:
per frame step, how far the median body point moves (:func:`jump_sizes`);
the JSON gives the 90th percentile of these steps (``*_jump_p90_mm``) and
the fraction over 100 mm (``*_jump_over_100mm``) for standard, windowed
and the real B. Baselines: B's mean pose (the mean of B's training joint
positions in A's ground frame), nearest-neighbour retrieval (the B frame
whose A frame is nearest in A's feature space) and, for a marker model,
Gaussian mixture regression of B's features on A's with the ``gmr`` package
(``gmr_mm``, as many components as states). The same are also given for
body-centred positions (pose alone). In the frames where the real people's
right hands touch (handshakes), ``hand_gap_in_contact_median_mm`` gives how far
A's hand is from each B's (:func:`hand_gaps`). ``windowed_as_shown_mm`` compares
the windowed output with the real B ``lag`` frames later, as a live viewer
sees it. Step latency is the time of one online partner step (emission
probabilities, windowed Viterbi, trellis) on A's features.

The command line's set-ups live here too (``dualhmm train``, ``evaluate``,
``crossval`` each call one function): :func:`fit_on_index` (the takes of an
index, minus ``--test-trials``; what to record in the model file),
:func:`evaluate_model` (``evaluate --test PATH/INDEX.csv`` on any index,
without leakage, through :func:`markovmotion.evaluate.takes.test_takes`; or
the model's own held-out takes) and :func:`crossval_index`.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.base import clone
from sklearn.neighbors import NearestNeighbors

from markovmotion.core.markers import Markers
from markovmotion.core.motion import UP, Motion
from markovmotion.data.index import INDEX_NAME, Entry, MocapIndex
from markovmotion.data.kinds import choose_kind, largest_group, never_seen, recorded
from markovmotion.data.splits import people_out, select_pairs
from markovmotion.errors import DataNotFoundError, SkeletonMismatchError
from markovmotion.evaluate import choose
from markovmotion.evaluate.choose import ROLES
from markovmotion.evaluate.takes import (
    TestTakes,
    evaluation_index,
    index_record,
    jump_p90,
    jump_sizes,
    people_trained_on,
    take_names,
    test_takes,
)
from markovmotion.features.markers import turn_about_up
from markovmotion.models.hmm.contact import CONTACT_MM, right_hand
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.models.hmm.trellis import TRELLISES, blend_positions
from markovmotion.progress import note, track
from markovmotion.viz.plots import new_figure, save_figure

METHODS = ("standard", "windowed", "mean_pose", "nearest_neighbour", "gmr", "known_motion")
#: Not a partner but a reference: B's real motion on the training people's mean pose
#: (:func:`known_motion`).
REFERENCES = ("known_motion",)
#: A step of the median body point larger than this between frames is a jump (mm).
JUMP_MM = 100.0


@dataclass
class PairResult:
    """Per-frame errors (mm) of one take, world (``errors``) and body-centred (``pose_errors``)."""

    name: str
    label: str
    fps: float
    errors: dict[str, np.ndarray] = field(default_factory=dict)
    people: str = ""  # INDEX.csv's subject: the pair of people of the take
    pose_errors: dict[str, np.ndarray] = field(default_factory=dict)
    latencies_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    jumps: dict[str, np.ndarray] = field(default_factory=dict)  # per frame step (mm)
    chosen: dict = field(default_factory=dict)  # settings picked on inner folds, if any
    hand_gaps: dict[str, np.ndarray] = field(default_factory=dict)  # mm, in contact frames
    windows: dict[str, np.ndarray] = field(default_factory=dict)  # A and B, for the observer
    places: dict[str, np.ndarray] = field(default_factory=dict)  # per frame (mm), see place_split


class Baselines:
    """What the baselines need from a model, computed once: B's mean pose, the nearest
    neighbour in A's features, and (a marker model) Gaussian mixture regression of B's
    features on A's by the ``gmr`` package, with as many components as the model has states
    (fitted on the model's own training features by scikit-learn's EM, seed 0)."""

    def __init__(self, model: DualHMM, regression: bool = True):
        self.model = model
        train_b = model.training_b()
        self.mean_rel = model.body_positions(train_b).mean(axis=0)
        self.mean_pose = model.body_positions(train_b, body_centred=True).mean(axis=0)
        self.nn = NearestNeighbors(n_neighbors=1).fit(model.train_a_)
        self.gmr = None
        if model.uses_markers and regression:
            from gmr import GMM
            from sklearn.mixture import GaussianMixture

            # EM by scikit-learn (its reg_covar keeps every component proper on few frames,
            # where gmr's own EM left NaN components on some folds); regression by gmr
            joint = np.hstack([model.train_a_, model.train_b_])
            fit = GaussianMixture(model.n_states, reg_covar=1e-3 * joint.var(0).mean(),
                                  random_state=0).fit(joint)  # fmt: skip
            self.gmr = GMM(model.n_states, fit.weights_, fit.means_, fit.covariances_)

    def regression(self, xa: np.ndarray, origin: np.ndarray, yaw: np.ndarray) -> Markers:
        """B by Gaussian mixture regression on A's features ``xa``, placed as the model does."""
        xb = self.gmr.predict(np.arange(xa.shape[1]), xa)
        rel = np.asarray(self.model.pipeline_b_.inverse_transform([xb])[0], dtype=float)
        root, rot = blend_positions(rel, np.arange(len(rel)), 0)
        return self.model.frames_to_motion(np.zeros(len(rel), dtype=int), origin, yaw, root, rot)

    def mean_world(self, origin: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        turn = Rotation.from_rotvec(np.outer(yaw, UP))
        return np.stack([turn.apply(p) for p in self.mean_rel], axis=1) + origin[:, None]

    def nearest(self, xa: np.ndarray, origin: np.ndarray, yaw: np.ndarray) -> Motion:
        idx = self.nn.kneighbors(xa, return_distance=False)[:, 0]
        return self.model.frames_to_motion(idx, origin, yaw)


def hand_gaps(
    model: DualHMM, a: np.ndarray, b: np.ndarray, generated: dict[str, np.ndarray]
) -> dict[str, np.ndarray] | None:
    """How far A's right hand is from B's (mm) in the frames where the real hands touch
    (closer than :data:`CONTACT_MM`): ``"real"`` and each generated B's. ``a``, ``b`` and
    ``generated`` are the positions the model compares people by (:meth:`DualHMM.body_positions`).
    None when the take has no such frame or the people have no right hand by name."""
    k = right_hand(model.compared_names())
    if k is None:
        return None
    real = np.linalg.norm(b[:, k] - a[:, k], axis=-1)
    contact = real < CONTACT_MM
    if not contact.any():
        return None
    out = {"real": real[contact]}
    for key in ("standard", "windowed", "nearest_neighbour", "gmr"):
        if key in generated:
            out[key] = np.linalg.norm(generated[key][:, k] - a[:, k], axis=-1)[contact]
    return out


#: The objective observer's windows: frames per window, frames between its samples, and
#: frames between windows (1 s windows seen at 10 fps, a new one every 1/3 s at 30 fps).
WINDOW, EVERY, HOP = 30, 3, 10


def observer_windows(
    a: np.ndarray, b: np.ndarray, origin: np.ndarray, yaw: np.ndarray
) -> np.ndarray:
    """(windows, dims) what the objective observer sees of a take: how A's and B's points
    ((F, P, 3) each, in A's ground frame) move over :data:`WINDOW` frames, every
    :data:`EVERY`th frame (:func:`_motion_in`), a window every :data:`HOP` frames (none if
    the take is shorter)."""
    both = np.concatenate([a, b], axis=1) - origin[:, None]
    both = turn_about_up(both, -yaw)
    starts = range(0, len(both) - WINDOW + 1, HOP)
    rows = [_motion_in(both[s : s + WINDOW : EVERY]).ravel() for s in starts]
    return np.array(rows).reshape(len(rows), len(range(0, WINDOW, EVERY)) * both[0].size)


def _motion_in(window: np.ndarray) -> np.ndarray:
    """A window's points about their own mean over the window: how each point moves, not
    where it is or whose body it is on (people differ by body and place more than the
    partner differs from a person)."""
    return window - window.mean(axis=0, keepdims=True)


def observer_accuracy(results: Sequence[PairResult], n_folds: int = 5) -> float:
    """Balanced accuracy of telling the windowed partner from the real B, given A: logistic
    regression on :func:`observer_windows`, cross-validated with folds by pair of people
    (by take when all come from one pair). 0.5: the two cannot be told apart (the aim of
    the observer study of §4); NaN with fewer than two groups."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import balanced_accuracy_score
    from sklearn.model_selection import GroupKFold, cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    keyed = [(r.people or r.name, r) for r in results if len(r.windows.get("real", ()))]
    groups_of = {g for g, _ in keyed}
    if len(groups_of) < 2:
        keyed = [(r.name, r) for _, r in keyed]
        groups_of = {g for g, _ in keyed}
    if len(groups_of) < 2:
        return float("nan")
    x, y, groups = [], [], []
    for g, r in keyed:
        for label, key in ((0, "real"), (1, "windowed")):
            x.append(r.windows[key])
            y.append(np.full(len(r.windows[key]), label))
            groups.append(np.full(len(r.windows[key]), g, dtype=object))
    x, y, groups = np.vstack(x), np.concatenate(y), np.concatenate(groups)
    model = make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=5000))
    folds = GroupKFold(min(n_folds, len(groups_of)))
    guess = cross_val_predict(model, x, y, groups=groups, cv=folds)
    return float(balanced_accuracy_score(y, guess))


def step_latencies(model: DualHMM, xa: np.ndarray) -> np.ndarray:
    """Microseconds of each online partner step over A's feature rows ``xa``."""
    partner = model.partner()
    place = (np.zeros(3), 0.0)
    out = np.empty(len(xa))
    for t, x in enumerate(xa):
        start = time.perf_counter_ns()
        partner.step_features(x, place)
        out[t] = (time.perf_counter_ns() - start) / 1e3
    return out


def known_motion(mean: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F, P, 3) B's real points ``truth`` moved so that their mean over the take is the
    training people's ``mean`` pose (P, 3) or mean placed pose (F, P, 3): what a partner
    that knew every move of the real B, but not B's own posture and place, would show.

    A reference beside the mean pose, not a partner: the people in a collection differ
    in posture (how they hold the arm that does not shake, the tracker's view of their
    shoulders and head), and no partner can learn a new person's posture from the other
    person. Its error is about how far below the mean pose a perfect partner of that kind
    could come (Bütepage markers, leave one pair out, the new-people options: 24 %
    body-centred in handshakes, 28 % in waves; docs/hmm.md, "New people")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a point never seen: NaN throughout
        return truth - np.nanmean(truth, axis=0) + np.mean(np.broadcast_to(mean, truth.shape), 0)


#: The partners whose world error is split into place and the rest (:func:`place_split`).
PLACED = ("windowed", "mean_pose")


def place_split(generated: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Where a generated B's world error comes from, per frame (mm): ``centroid``, the
    distance of its points' centroid from the real B's; ``at_true_place``, its world error
    once moved so that its centroid is the real B's (the error of its pose and heading
    alone). On new people most of the world error is the place: a pair stands where it
    chooses, which the other person's motion tells little of (docs/hmm.md, "New people")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame with no point seen: NaN
        mine = np.where(np.isfinite(truth), generated, np.nan)  # the same points as the truth's
        shift = np.nanmean(truth, axis=1, keepdims=True) - np.nanmean(mine, axis=1, keepdims=True)
    return {
        "centroid": np.linalg.norm(shift[:, 0], axis=-1),
        "at_true_place": seen_errors(generated + shift, truth),
    }


def evaluate_pair(
    model: DualHMM,
    a: Motion,
    b: Motion,
    name: str,
    label: str,
    baselines: Baselines | None = None,
) -> PairResult:
    """Errors of standard, windowed, mean-pose and nearest-neighbour B on one take; standard
    and windowed through the model's trellis, and (keys ``"<trellis>/standard"`` ...) through
    each of :data:`~markovmotion.models.hmm.trellis.TRELLISES` (B by regression: the model's
    own only, as it passes no trellis)."""
    baselines = baselines or Baselines(model)
    a, b = model._rate(a), model._rate(b)
    # the baselines see A as the partner does (a skeleton lifted to a sensor model's height,
    # DualHMM.a_in) and are placed as the windowed partner is, brought down by the same lift
    seen, lift = model.a_in(a)
    xa, missing = model.features_a(seen)
    # A unseen: as respond places B
    origin, yaw = model.placing(model.filled(seen), lift=lift, seen=~missing)
    generated = {"nearest_neighbour": baselines.nearest(xa, origin, yaw)}
    if baselines.gmr is not None:
        generated["gmr"] = baselines.regression(xa, origin, yaw)
    own = model.trellis
    try:
        # B by regression passes no trellis: one answer per method
        for kind in TRELLISES if model.output == "frames" else (own,):
            model.set_params(trellis=kind)
            for method in ("standard", "windowed"):
                generated[f"{kind}/{method}"] = model.respond(a, method)
    finally:
        model.set_params(trellis=own)
    for method in ("standard", "windowed"):
        generated[method] = generated[f"{own}/{method}"]
    truth, truth_pose = model.body_positions(b), model.body_positions(b, body_centred=True)
    # B's points unseen (NaN, occluded) are left out of every measure: a frame's errors are
    # over the points seen in it, a frame with none is left out; said once per take
    seen = np.isfinite(truth).any(axis=(1, 2)) & np.isfinite(truth_pose).any(axis=(1, 2))
    if not np.isfinite(truth).all():
        unseen = int((~np.isfinite(truth).all(axis=(1, 2))).sum())
        note(f"{name}: {unseen} of {len(seen)} frames of B have a point unseen: each frame's "
             f"errors are over the points seen ({int((~seen).sum())} frames with none: left "
             "out)")  # fmt: skip
    res = PairResult(name, label, model.fps)
    res.jumps["real"] = _finite(jump_sizes(truth))
    where = {k: model.body_positions(m) for k, m in generated.items()}  # once per output
    for k, m in generated.items():
        res.errors[k] = seen_errors(where[k], truth)[seen]
        res.pose_errors[k] = seen_errors(model.body_positions(m, True), truth_pose)[seen]
        res.jumps[k] = jump_sizes(where[k])
    placed = baselines.mean_world(origin, yaw)
    res.errors["mean_pose"] = seen_errors(placed, truth)[seen]
    for key, points in zip(PLACED, (where["windowed"], placed), strict=True):
        for part, err in place_split(points, truth).items():
            res.places[f"{key}_{part}"] = err[seen]
    mean_pose = np.broadcast_to(baselines.mean_pose, truth_pose.shape)
    if lift is not None:  # the training people's heights are the sensor's: down by the lift
        mean_pose = mean_pose - np.outer(lift, UP)[:, None]
    res.pose_errors["mean_pose"] = seen_errors(mean_pose, truth_pose)[seen]
    res.errors["known_motion"] = seen_errors(known_motion(placed, truth), truth)[seen]
    res.pose_errors["known_motion"] = seen_errors(known_motion(mean_pose, truth_pose), truth_pose)[
        seen
    ]
    where_a = model.body_positions(a)
    real, win = (observer_windows(where_a, p, origin, yaw) for p in (truth, where["windowed"]))
    whole = np.isfinite(real).all(axis=1) & np.isfinite(win).all(axis=1)  # A or B unseen
    res.windows = {"real": real[whole], "windowed": win[whole]}
    gaps = hand_gaps(model, where_a, truth, where)
    if gaps is not None:
        res.hand_gaps = gaps
    lag = model.window - 1
    shown = where["windowed"][: len(truth) - lag]
    res.errors["windowed_as_shown"] = _finite(seen_errors(shown, truth[lag:]))
    res.latencies_us = step_latencies(model, xa)
    return res


def seen_errors(predicted: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F,) mean distance (mm) over the points of ``truth`` (F, P, 3) seen in each frame
    (the mean over every point where all are seen; NaN where none is)."""
    dist = np.linalg.norm(predicted - truth, axis=-1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame with no point seen: NaN
        return np.nanmean(dist, axis=-1)


def _finite(values: np.ndarray) -> np.ndarray:
    """``values`` without NaN (frames, or steps between frames, where a point is unseen)."""
    return values[np.isfinite(values)]


def plot_pair(result: PairResult, path: str | os.PathLike[str]) -> Path:
    """Per-frame error of standard (solid) and windowed (dashed) Viterbi, as the paper's Figs. 6-8."""
    fig, ax = new_figure(8.0, 3.6)
    frames = np.arange(len(result.errors["standard"]))
    for key, style, label, extra in (
        ("standard", "-", "standard Viterbi", {"lw": 1.3}),
        ("windowed", "--", "windowed Viterbi", {"lw": 1.3}),
        ("mean_pose", ":", "mean pose", {"lw": 1.0, "color": "grey"}),
    ):  # the mean each command prints, in the legend
        err = result.errors[key]
        ax.plot(frames, err, style, label=f"{label} (mean {np.mean(err):.0f})", **extra)
    ax.set_xlabel(f"frame ({result.fps:g} fps)")
    ax.set_ylabel("Euclidean distance (mm)")
    # two lines: a take's name beside the words ran past the figure's left edge
    ax.set_title(f"Error of the generated behaviour\n{result.name} ({result.label})")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    # outside the axes, to the right: over the curves it hid frames 70-75 of a take
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    return save_figure(fig, path)


def _summary(results: Sequence[PairResult]) -> dict:
    def mean(key: str, attr: str = "errors") -> float:
        return round(float(np.concatenate([getattr(r, attr)[key] for r in results]).mean()), 1)

    lat = np.concatenate([r.latencies_us for r in results])
    methods = [k for k in METHODS if all(k in r.errors for r in results)]
    out = {f"{k}_mm": mean(k) for k in methods}
    out["windowed_as_shown_mm"] = mean("windowed_as_shown")
    out.update(_jumps(results, ("standard", "windowed", "real")))
    out["trellis"] = {
        kind: {f"{m}_mm": mean(f"{kind}/{m}") for m in ("standard", "windowed")}
        | _jumps(results, (f"{kind}/standard", f"{kind}/windowed"))
        for kind in TRELLISES
        if all(f"{kind}/standard" in r.errors for r in results)
    }
    out["body_centred"] = {f"{k}_mm": mean(k, "pose_errors") for k in methods}
    if all(r.places for r in results):
        out["place"] = {f"{k}_mm": mean(k, "places") for k in results[0].places}
    touching = [r for r in results if r.hand_gaps]
    if touching:
        keys = [k for k in touching[0].hand_gaps if all(k in r.hand_gaps for r in touching)]
        out["hand_gap_in_contact_median_mm"] = {
            k: round(float(np.median(np.concatenate([r.hand_gaps[k] for r in touching]))), 1)
            for k in keys
        } | {"frames": int(sum(len(r.hand_gaps["real"]) for r in touching))}
    out["latency_us"] = {
        "median": round(float(np.median(lat)), 1),
        "p99": round(float(np.percentile(lat, 99)), 1),
    }
    out["observer_accuracy"] = round(observer_accuracy(results), 3)
    out["frames"] = int(sum(len(r.errors["standard"]) for r in results))
    out["pairs"] = len(results)
    out["aims"] = aims(out)
    return out


#: What a partner for people it has never seen should reach (docs/hmm.md, "New people"),
#: judged on the windowed partner: world error this share below the mean pose's, body-centred
#: this share below, steps and the hands' gap in contact at most this many times the real
#: B's, an observer's accuracy at most this, a live step's p99 below this (µs).
AIMS = {
    "world_below_mean_pose": 0.30,
    "body_centred_below_mean_pose": 0.15,
    "jumps_times_real": 1.5,
    "hand_gap_times_real": 1.5,
    "observer_at_most": 0.70,
    "live_step_p99_us": 33_000.0,
}


def aims_line(found: dict) -> str:
    """:func:`aims` in one line, as the command line prints it."""

    def one(name: str, a: dict) -> str:
        v, aim, met = a["value"], a["aim"], "met" if a["met"] else "NOT met"
        if name.endswith("below_mean_pose"):
            what = name.removesuffix("_below_mean_pose").replace("_", "-")
            side = "below" if v >= 0 else "above"
            return f"{what} {100 * abs(v):.0f} % {side} the mean pose (aim {100 * aim:.0f} % below) {met}"
        if "_below_" in name:
            what, peers = name.split("_below_")
            peers = peers.replace("nearest_neighbour", "nearest neighbour").replace("gmr", "GMR")
            peers = peers.replace("_and_", " and ")
            return f"{what.replace('_', '-')} below {peers} ({v:.1f} against {aim:.1f} mm) {met}"
        if name.endswith("times_real"):
            what, whose = (
                ("jump p90", "B's") if name.startswith("jumps") else ("hand gap", "pairs'")
            )
            return f"{what} {v:.2f}x the real {whose} (aim {aim:g}x) {met}"
        if name == "observer_at_most":
            return f"observer {v:.2f} (aim at most {aim:.2f}) {met}"
        return f"live step p99 {v / 1000:.2f} ms (aim {aim / 1000:.0f} ms) {met}"

    return "; ".join(one(k, a) for k, a in found.items())


def aims(summary: dict) -> dict:
    """Each of :data:`AIMS` (and: below the nearest neighbour and GMR, world and body-centred)
    for one :func:`_summary`: ``{name: {"value", "aim", "met"}}``, the value as the aim is
    stated (a share below the mean pose, a ratio to the real B's, mm, µs); an aim the
    evaluation cannot judge (no GMR on skeletons, no contact in waves, one take for the
    observer) is left out."""
    body = summary["body_centred"]
    out: dict[str, dict] = {}

    def add(name: str, value: float, aim: float, met: bool) -> None:
        out[name] = {"value": round(float(value), 3), "aim": aim, "met": bool(met)}

    for name, part in (("world", summary), ("body_centred", body)):
        share = 1.0 - part["windowed_mm"] / part["mean_pose_mm"]
        bound = AIMS[f"{name}_below_mean_pose"]
        add(f"{name}_below_mean_pose", share, bound, share >= bound)
        peers = [k for k in ("nearest_neighbour_mm", "gmr_mm") if k in part]
        best = min(part[k] for k in peers)
        below = "_and_".join(k.removesuffix("_mm") for k in peers)
        add(f"{name}_below_{below}", part["windowed_mm"], best, part["windowed_mm"] < best)
    real = summary["real_jump_p90_mm"]
    if real:
        ratio = summary["windowed_jump_p90_mm"] / real
        add("jumps_times_real", ratio, AIMS["jumps_times_real"], ratio <= AIMS["jumps_times_real"])
    gap = summary.get("hand_gap_in_contact_median_mm")
    if gap and gap.get("real") and "windowed" in gap:
        ratio = gap["windowed"] / gap["real"]
        bound = AIMS["hand_gap_times_real"]
        add("hand_gap_times_real", ratio, bound, ratio <= bound)
    seen = summary["observer_accuracy"]
    if np.isfinite(seen):
        add("observer_at_most", seen, AIMS["observer_at_most"], seen <= AIMS["observer_at_most"])
    p99 = summary["latency_us"]["p99"]
    add("live_step_p99_us", p99, AIMS["live_step_p99_us"], p99 < AIMS["live_step_p99_us"])
    return out


def _jumps(results: Sequence[PairResult], keys: Sequence[str]) -> dict:
    """``<key>_jump_p90_mm`` (90th percentile of :func:`jump_sizes` over every frame step)
    and ``<key>_jump_over_100mm`` (the fraction of steps over :data:`JUMP_MM`) per key."""
    out = {}
    for k in keys:
        steps = np.concatenate([r.jumps[k] for r in results])
        name = k.split("/")[-1]
        out[f"{name}_jump_p90_mm"] = jump_p90([steps])  # None without a step (B unseen)
        over = round(float((steps > JUMP_MM).mean()), 4) if len(steps) else None
        out[f"{name}_jump_over_100mm"] = over
    return out


def describe(model: DualHMM) -> dict:
    """The settings of ``model`` reported with its results (and its PCA sizes once fitted)."""
    out = {
        "mode": model.mode,
        "n_states": model.n_states,
        "fps": model.fps,
        "window": model.window,
        "lag_frames": model.window - 1,
        "trellis": model.trellis,
        "blend_window": model.blend_window,
        "placement_window": model.placement_window,
        "place_memory": model.place_memory,
        "normalise": model.normalise,
        "output": model.output,
        "contact_weight": model.contact_weight,
        "place_scale": getattr(model, "place_scale", "none"),
        "heights": getattr(model, "heights", "capture"),
    }
    if hasattr(model, "train_a_"):
        out.update(dims_a=int(model.train_a_.shape[1]), dims_b=int(model.train_b_.shape[1]))
        out["frame"] = getattr(model, "frame_", "heading")
    return out


def summarise(results: Sequence[PairResult], model: DualHMM) -> dict:
    """The evaluation JSON: ``model``, ``overall``, ``per_label.<label>``, ``per_pair.<name>``."""
    labels = sorted({r.label for r in results})
    people = sorted({r.people for r in results if r.people})
    per_pair = {r.name: _summary([r]) | ({"chosen": r.chosen} if r.chosen else {}) for r in results}
    return {
        "model": describe(model),
        "overall": _summary(results),
        "per_label": {lab: _summary([r for r in results if r.label == lab]) for lab in labels},
        "per_people": {p: _summary([r for r in results if r.people == p]) for p in people},
        "per_pair": per_pair,
    }


def _fit_on(
    model: DualHMM,
    takes: Sequence[tuple[str, str, Motion, Motion]],
    people: Sequence[str] | None = None,
) -> DualHMM:
    """A copy of ``model`` (same hyper-parameters) trained on ``takes`` (of ``people``)."""
    return clone(model).fit([(a, b) for _, _, a, b in takes], groups=people)


#: DualHMM parameters that change generation, not training: a nested choice among them
#: reuses each inner fold's fit.
GENERATION_ONLY = frozenset({"placement_window", "blend_window"})


def parse_grid(text: str) -> list[dict]:
    """Settings of a DualHMM to choose among, ``"param=v1,v2;param=v1,v2"``
    (:func:`markovmotion.evaluate.choose.parse_grid` over DualHMM's parameters and ``roles``)."""
    grid = choose.parse_grid(text, choose.grid_defaults(DualHMM()))
    for setting in grid:  # a value out of its choices is refused before anything is learnt
        DualHMM(**choose.model_params(setting)).check_params()
    return grid


def choose_settings(
    takes: Sequence[tuple[str, str, Motion, Motion]],
    model: DualHMM,
    grid: Sequence[dict],
    people: Sequence[str] | None = None,
    roles: str = "one",
    method: str = "windowed",
) -> dict:
    """The settings of ``grid`` (dicts of DualHMM parameters, and ``roles``) under which
    ``model`` answers best, by leave-one-out over ``takes`` alone (one pair of people at a
    time when they come from two or more, else one take:
    :func:`markovmotion.evaluate.choose.choose_settings`): nested cross-validation when
    ``takes`` are an outer fold's training takes. The score is B's mean world error by
    ``method`` over the inner held-out frames; each inner fold learns ``roles`` (or the
    setting's own ``roles``) as the outer one would. With ``roles="both"`` (the
    interaction's roles are alike) the inner held-out takes are answered in both roles too:
    with a few pairs of people an inner fold has little to score a setting on, and the same
    people's other role doubles it. Returns
    ``{"settings": pick, "inner_mm": {"param=value,...": error}}``."""
    groups = choose.fold_groups(people, [t[0] for t in takes], choosing=True)

    def fit(settings: dict, train: list[int]) -> DualHMM:
        learn = choose.learnt([takes[i] for i in train], [groups[i] for i in train],
                              settings.get("roles", roles))  # fmt: skip
        return _fit_on(clone(model).set_params(**choose.model_params(settings)), *learn)

    def score(fold: DualHMM, settings: dict, test: list[int]) -> tuple[float, int]:
        fold.set_params(**choose.model_params(settings))
        error, frames = 0.0, 0
        held = [takes[i] for i in test]
        for _, _, a, b in choose.both_roles(held) if roles == "both" else held:
            truth = fold.body_positions(fold._rate(b))
            per_frame = _finite(seen_errors(fold.body_positions(fold.respond(a, method)), truth))
            error, frames = error + float(per_frame.sum()), frames + len(per_frame)
        return error, frames

    return choose.choose_settings(grid, groups, fit, score, GENERATION_ONLY)


def cross_validate(
    takes: Sequence[tuple[str, str, Motion, Motion]],
    model: DualHMM,
    plot_dir: str | os.PathLike[str] | None = None,
    grid: Sequence[dict] | None = None,
    people: Sequence[str] | None = None,
    roles: str = "one",
    method: str = "windowed",
) -> tuple[list[PairResult], list[Path]]:
    """Leave-one-out over the takes ``(name, label, A, B)`` (names unique): each is evaluated
    by a copy of ``model`` (same hyper-parameters) trained on the others.

    ``people`` (per take, INDEX.csv's ``subject``): when the takes come from two or more
    pairs of people, each pair of people is left out at once (its takes are evaluated by
    a copy trained on the other people's takes alone: a partner for people it has never
    seen); otherwise one take at a time (:func:`markovmotion.evaluate.choose.fold_groups`).
    ``roles="both"``: each fold also learns from its training takes with the roles swapped
    (:func:`~markovmotion.evaluate.choose.both_roles`). With ``grid`` (settings,
    :func:`parse_grid`), each copy's settings are first chosen among them on its training
    takes alone (:func:`choose_settings` by ``method``'s error: nested cross-validation),
    kept in each result's ``chosen``."""
    if roles not in ROLES:
        raise ValueError(f"roles must be one of {', '.join(ROLES)}, got {roles!r}")
    groups = choose.fold_groups(people, [t[0] for t in takes])
    results: list[PairResult | None] = [None] * len(takes)
    plots = []
    for group in track(list(dict.fromkeys(groups)), "leave-one-out"):
        rest = [t for t, g in zip(takes, groups, strict=True) if g != group]
        who = [g for g in groups if g != group]
        fold, chosen, learn = clone(model), {}, roles
        if grid:
            chosen = choose_settings(rest, fold, grid, who, roles, method)
            learn = chosen["settings"].get("roles", roles)
            fold.set_params(**choose.model_params(chosen["settings"]))
        fold = _fit_on(fold, *choose.learnt(rest, who, learn))
        for i in (i for i, g in enumerate(groups) if g == group):
            name, label, a, b = takes[i]
            res = evaluate_pair(fold, a, b, name, label)
            res.chosen, res.people = chosen, people[i] if people is not None else ""
            results[i] = res
            if plot_dir is not None:
                plots.append(plot_pair(res, Path(plot_dir) / f"{name}_error.png"))
    return [r for r in results if r is not None], plots


# ------------------------------------------------------------------ the command line's set-ups
Pair = tuple[Entry, Entry]


def load_pairs(
    index: MocapIndex, pairs: Sequence[Pair], kind: str | None = None
) -> tuple[list[Pair], list[tuple]]:
    """The two-person takes of ``pairs`` a dual HMM can learn together, loaded: those of
    one kind (``kind``, else the larger group) and, of these, the largest group whose
    person B shares one skeleton or marker set (:mod:`markovmotion.data.kinds`, which
    says what it left out). Returns the pairs kept and their (A, B) takes."""
    pairs, _ = choose_kind(pairs, kind, "two-person takes", entry=lambda p: p[0])
    takes = [index.load_pair(a, b) for a, b in track(pairs, "loading takes")]
    seen = recorded(pairs, takes)
    if pairs and not seen:
        raise DataNotFoundError(
            f"no two-person take of {index.root / INDEX_NAME} records both people"
        )
    pairs, takes = [pairs[i] for i in seen], [takes[i] for i in seen]
    keep, _ = largest_group(
        takes, [a.file for a, _ in pairs], "two-person takes (person B)", key=lambda t: t[1]
    )
    return [pairs[i] for i in keep], [takes[i] for i in keep]


def fit_on_index(
    model: DualHMM,
    data: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    test_trials: Sequence[str] | None = None,
    kind: str | None = None,
    roles: str = "one",
    grid: Sequence[dict] | None = None,
    test_people: Sequence[str] | None = None,
) -> tuple[DualHMM, dict, list[Pair]]:
    """Fit ``model`` on the two-person takes of ``labels`` in the index at ``data``, all but
    ``test_trials`` and those of the pairs of people ``test_people`` (INDEX.csv's
    ``subject``: a partner evaluated on people it has never seen), of one kind and set
    (:func:`load_pairs`), in both roles with ``roles="both"``
    (:func:`~markovmotion.evaluate.choose.both_roles`). With ``grid``, the
    settings are first chosen among it by leave-one-pair-of-people-out on these takes
    (:func:`choose_settings`).
    Returns the model, the extras to save with it (``data_index``: the index,
    ``held_out_files``: the held-out takes' files, which ``evaluate`` without ``--test``
    evaluates on; ``roles``; ``chosen``, with ``grid``) and the training pairs."""
    index = MocapIndex.load(data)
    pairs = select_pairs(index, labels, test_trials, held_out=False)
    away = people_out(index, pairs, test_people)
    pairs, motions = load_pairs(index, [p for p in pairs if p not in away], kind)
    names = take_names(pairs)
    takes = [(names[p], p[0].label, *ab) for p, ab in zip(pairs, motions, strict=True)]
    people = [a.subject for a, _ in pairs]
    chosen: dict = {}
    if grid:
        chosen = choose_settings(takes, model, grid, people, roles)
        roles = chosen["settings"].get("roles", roles)
        model.set_params(**choose.model_params(chosen["settings"]))
    takes, people = choose.learnt(takes, people, roles)
    model.fit(
        [(a, b) for _, _, a, b in takes], labels=[lab for _, lab, _, _ in takes], groups=people
    )
    held: list[str] = []
    if test_trials is not None:
        for a, b in select_pairs(index, labels, test_trials, held_out=True):
            if a.kind == pairs[0][0].kind:
                held += [a.file, b.file]
    held += [e.file for a, b in away if a.kind == pairs[0][0].kind for e in (a, b)]
    extras = {"data_index": index_record(index), "held_out_files": held, "roles": roles}
    return model, extras | ({"chosen": chosen} if chosen else {}), pairs


def evaluation_pairs(
    model: DualHMM,
    test: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    trials: Sequence[str] | None = None,
) -> tuple[MocapIndex, TestTakes]:
    """The two-person takes ``model`` is evaluated on, and those left out as training takes.

    With ``test`` (a folder or INDEX.csv): the takes of that index whose label is one of
    the model's training labels (``labels_``; any interaction if none were recorded),
    or of ``labels``, and (with ``trials``) of those trials. Without ``test``: the
    model's training index (or the default one), restricted to ``trials`` or else to
    the held-out takes recorded at training.
    Either way takes whose files the model trained on (by content) are left out
    (:func:`~markovmotion.evaluate.takes.test_takes`).

    Raises:
        DataNotFoundError: no take fits, or every one that does is a training take (one
            line listing them).
    """
    learnt = list(getattr(model, "labels_", None) or [])
    wanted = list(labels or learnt) or None
    index = evaluation_index(model, test)
    # the labels of its two-person takes, without pairing them (a row of another label
    # lacking its partner's row is that label's problem, said when it is asked for)
    there = sorted({e.label for e in index.query(category="interaction") if e.partner_file})

    def unlabelled(asked: str) -> DataNotFoundError:
        return DataNotFoundError(
            f"no two-person take of {index.root / INDEX_NAME} is labelled {asked}; its labels: "
            f"{', '.join(there) or 'none'}"
        )

    if labels:  # each label asked for is there, as train asks (a typo is not ignored)
        if absent := [lab for lab in labels if lab not in there]:
            raise unlabelled(", ".join(map(repr, absent)))
        if learnt and (other := [lab for lab in labels if lab not in learnt]):
            note(
                f"the model learnt {', '.join(learnt)}, not {', '.join(other)}: it answers "
                "those takes as best it can, and the numbers say how it does on an action "
                "it never saw"
            )
    if trials is not None:
        pairs = select_pairs(index, wanted, trials, held_out=True)
    else:
        pairs = index.pairs(label=wanted)
        if not pairs and wanted:
            raise unlabelled(f"{', '.join(wanted)} (the model's labels)")
        held = getattr(model, "held_out_files_", None)
        if test is None and held is not None and not held:  # recorded: none held out
            raise DataNotFoundError(
                "the model held no take out at training (dualhmm train learns every take "
                "unless given --test-people or --test-trials): give --test INDEX (or a "
                "folder) to answer other takes"
            )
        if test is None and held:
            kept = [p for p in pairs if p[0].file in held]
            if not kept:
                raise DataNotFoundError(
                    f"none of the {len(held)} files held out at training is a take labelled "
                    f"{', '.join(wanted or [])}: give --test INDEX (or a folder) to answer "
                    "other takes"
                )
            pairs = kept
    pairs, other_kind = own_kind(model, pairs)
    takes = test_takes(model, index, pairs, "two-person take")
    takes.other_kind = TestTakes._files(other_kind)
    return index, takes


def own_kind(model: DualHMM, pairs: Sequence[Pair]) -> tuple[list[Pair], list[Pair]]:
    """Of ``pairs``, those of the kind the model learnt (markers or skeletons) and the others,
    when both are there: a marker model answers a skeleton's A through virtual markers, but
    one mean over both kinds would mix two measures (a collection of C3D handshakes and a
    CMU skeleton take); with takes of one kind alone, those are kept whatever their kind."""
    own = "markers" if model.uses_markers else "skeleton"
    kept = [p for p in pairs if p[0].kind == own]
    if not kept or len(kept) == len(pairs):
        return list(pairs), []
    return kept, [p for p in pairs if p[0].kind != own]


def pairs_that_fit(
    model: DualHMM, index: MocapIndex, pairs: Iterable[Pair], other_skeleton: list[str]
) -> Iterator[tuple[Entry, Entry, Motion, Motion]]:
    """The takes of ``pairs`` loaded, those whose person A the model can answer and whose
    person B it can be compared with; the files of the others (A or B on a skeleton without
    the model's body points, or without its markers, or never seen) go to ``other_skeleton``,
    the one that does not fit with why (``file (markers not found: R_HAND)``)."""
    for ea, eb in pairs:
        a, b = index.load_pair(ea, eb)
        if empty := never_seen((ea, eb), (a, b)):  # nothing to answer or compare with
            other_skeleton += [f"{f} (never seen: every sample NaN)" for f in empty]
            continue
        try:
            model.check_input(a, ea.path)
        except SkeletonMismatchError as exc:
            other_skeleton += [f"{ea.file} ({exc.reason})", eb.file]
            continue
        try:
            model.check_partner(b, eb.path)
        except SkeletonMismatchError as exc:
            other_skeleton += [ea.file, f"{eb.file} ({exc.reason})"]
            continue
        yield ea, eb, a, b


def evaluate_model(
    model: DualHMM,
    test: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    trials: Sequence[str] | None = None,
    plot_dir: str | os.PathLike[str] | None = None,
) -> tuple[dict, list[Path]]:
    """``dualhmm evaluate``: the evaluation JSON (:func:`summarise`, with ``test_files``,
    ``left_out_training_files``, ``left_out_other_skeleton``, takes whose person A has
    another skeleton, and ``people_trained_on``, the test takes' pairs of people the model
    learnt other takes of: :func:`~markovmotion.evaluate.takes.people_trained_on`) on the
    takes of :func:`evaluation_pairs`, and the plots written."""
    index, takes = evaluation_pairs(model, test, labels, trials)
    baselines = Baselines(model)
    results, plots, kept, incompatible = [], [], [], []
    pairs = track(takes.takes, "evaluating pairs")
    for ea, eb, a, b in pairs_that_fit(model, index, pairs, incompatible):
        kept.append((ea, eb))
        res = evaluate_pair(model, a, b, take_names(takes.takes)[(ea, eb)], ea.label, baselines)
        res.people = ea.subject
        results.append(res)
        if plot_dir is not None:
            plots.append(plot_pair(res, Path(plot_dir) / f"{res.name}_error.png"))
    if not results:
        raise DataNotFoundError(
            f"no two-person take of {index.root / INDEX_NAME} can be answered by the model "
            f"and compared: {', '.join(incompatible)}"
        )
    report = summarise(results, model)
    report.update(TestTakes(kept, takes.left_out, takes.other_kind).report())
    report["left_out_other_skeleton"] = incompatible
    report["people_trained_on"] = people_trained_on(model, index, kept)
    return report, plots


def crossval_index(
    model: DualHMM,
    data: str | os.PathLike[str] | None = None,
    labels: Sequence[str] | None = None,
    plot_dir: str | os.PathLike[str] | None = None,
    grid: Sequence[dict] | None = None,
    kind: str | None = None,
    roles: str = "one",
) -> tuple[dict, list[Path]]:
    """``dualhmm crossval``: :func:`cross_validate` over the two-person takes of ``labels``
    in the index at ``data`` (one kind and set, :func:`load_pairs`), leaving out one pair of
    people at a time (INDEX.csv's ``subject``) when there are two or more, else one take;
    the JSON (:func:`summarise`, with ``test_files``, ``left_out`` and ``roles``) and plots."""
    index = MocapIndex.load(data)
    pairs, loaded = load_pairs(index, select_pairs(index, labels, None, held_out=False), kind)
    names = take_names(pairs)
    takes = [(names[(a, b)], a.label, *ab) for (a, b), ab in zip(pairs, loaded, strict=True)]
    people = [a.subject for a, _ in pairs]
    results, written = cross_validate(takes, model, plot_dir, grid, people, roles)
    report = summarise(results, model)
    report["left_out"] = "pairs of people" if len(set(people)) > 1 else "takes"
    if grid:  # ``model`` gives the settings before the choice; each fold's pick is here
        report["chosen_per_fold"] = {r.people or r.name: r.chosen["settings"] for r in results}
    report["roles"] = roles
    report.update(TestTakes(list(pairs)).report())
    return report, written

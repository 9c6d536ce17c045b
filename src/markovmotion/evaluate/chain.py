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
relative scale) beside the real person.

The split is fixed: of CMU's salsa takes, trials 12, 13 and 15 (the last three
pairs) are held out; the other eight train.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from markovmotion.data.index import Entry, MocapIndex
from markovmotion.features.joint_shape import Person, TwoPeople
from markovmotion.models.virtual_partner import VirtualPartner
from markovmotion.progress import track

#: Held-out salsa trials (CMU subjects 60/61): the last three pairs.
TEST_TRIALS = ("12", "13", "15")
SOURCES = ("mocap", "silhouette")


def salsa_split(
    index: MocapIndex, label: str = "salsa"
) -> tuple[list[tuple[Entry, Entry]], list[tuple[Entry, Entry]]]:
    """(training, held-out) two-person takes of ``label``; held out: :data:`TEST_TRIALS`."""
    pairs = index.pairs(label=label)
    test = [p for p in pairs if p[0].trial in TEST_TRIALS]
    return [p for p in pairs if p[0].trial not in TEST_TRIALS], test


def mocap_takes(
    index: MocapIndex, pairs: Sequence[tuple[Entry, Entry]], fps: float = 25.0
) -> list[TwoPeople]:
    """Both people of each take as joint positions at ``fps`` (the paper's 25 fps)."""
    return [
        TwoPeople.from_motions(*index.load_pair(a, b), fps=fps)
        for a, b in track(pairs, "reading takes")
    ]


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


def evaluate_partner(
    model: VirtualPartner,
    takes: Sequence[TwoPeople],
    source: str = "mocap",
    n_hypotheses: int = 200,
    seed: int = 0,
) -> dict:
    """Errors of the single- and multiple-hypothesis partners and of the mean-shape baseline.

    In silhouette takes person 0 and 1 are two identities (not left and right):
    the model matches the real person to either half (eq. 18) and the
    baseline is placed on the side where the partner truly is.
    """
    if source not in SOURCES:
        raise ValueError(f"source must be one of {SOURCES}, got {source!r}")
    methods = {
        "single_hypothesis": {"n_hypotheses": 1},
        "multiple_hypotheses": {"n_hypotheses": n_hypotheses},
        "multiple_hypotheses_map": {"n_hypotheses": n_hypotheses, "response": "map"},
    }
    errors: dict[str, list[float]] = {k: [] for k in (*methods, "mean_shape")}
    placement: dict[str, list[float]] = {k: [] for k in errors}
    seconds = {k: 0.0 for k in methods}
    frames = 0
    jobs = [(take, person) for take in takes for person in (0, 1)]
    with threadpool_limits(1):  # per-frame times on one core, as for real-time use
        for take, person in track(jobs, "virtual partners"):
            real, truth = take.person(person), take.person(1 - person)
            if source == "mocap":
                role, true_roles = person, np.full(take.n_frames, person)
            else:
                role = None
                true_roles = (real.reference[:, 0] > truth.reference[:, 0]).astype(int)
            partners = {"mean_shape": model.mean_partner(real, true_roles)}
            for name, options in methods.items():
                start = time.perf_counter()
                partners[name] = model.respond(real, role, seed=seed, **options).partner
                seconds[name] += time.perf_counter() - start
            for name, pred in partners.items():
                if source == "mocap":
                    errors[name].append(pose_error_mm(model, pred, truth) * take.n_frames)
                    placement[name].append(point_error(pred, truth, False) * take.n_frames)
                else:
                    errors[name].append(point_error(pred, truth, True) * take.n_frames)
            frames += take.n_frames
    out = {k: float(np.sum(v) / frames) for k, v in errors.items()}
    result = {
        "unit": "mm" if source == "mocap" else "fraction of body height",
        **out,
        "per_frame_ms": {k: 1000.0 * s / frames for k, s in seconds.items()},
        "source": source,
        "hypotheses": n_hypotheses,
        "takes": [t.name for t in takes],
        "frames": frames,
    }
    if source == "mocap":
        result["placement_mm"] = {k: float(np.sum(v) / frames) for k, v in placement.items()}
    return result

"""The tracked person's size: a global scale and leg and arm ratios of the body model.

The body model's skeleton is a template (:mod:`~markovmotion.video.body_model`); a real person
is taller or shorter, with longer or shorter legs and arms. :func:`scaled_body` scales the
template's bone offsets: the legs (every joint below a hip body point) by ``scale * legs``,
the arms (below a shoulder) by ``scale * arms``, the rest by ``scale``; the root's standing
height by ``scale * legs``. :func:`body_size_from_points` measures the three factors from a
person's body points (e.g. the monocular front end's, :mod:`~markovmotion.video.monocular`)
against the template's, as medians over frames of the same lengths on both: leg
(hip-knee-ankle) and arm (shoulder-elbow-wrist), each the mean of both sides. With ``l`` and
``a`` the leg and arm ratios, person to template, ``scale = sqrt(l a)`` (the trunk and head
follow it), ``legs = l / scale``, ``arms = a / scale``. The trunk is not measured: MediaPipe's
hip landmarks are not where a skeleton's hip joints are (its shoulder-to-hip distance is
about 30 % longer than the template's on the real video, while legs and arms agree within
10 %).

Segment by segment (``track --body-size views``): :func:`segment_sizes_from_points` measures
each of :data:`SEGMENTS` (upper arm, forearm, thigh, shin, the shoulders' width) from body
points triangulated from every camera, and :func:`segment_body` scales those bones alone: a
person's proportions are not the template's (the real video's man: forearms 1.35 times the
template's, shins 0.88). Written here, not taken from a library: the bones are the template
skeleton's, found between its body points.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from markovmotion.features.body_points import BODY_POINTS
from markovmotion.video.body_model import BodyModel

#: Factors outside this range are refused as a measurement gone wrong.
SIZE_RANGE = (0.6, 1.5)


def _lengths(points: np.ndarray) -> np.ndarray:
    """(F, 3) trunk, leg and arm lengths (mm) of (F, 19, 3) body points."""
    at = {n: points[:, i] for i, n in enumerate(BODY_POINTS)}

    def mid(a: str) -> np.ndarray:
        return (at[f"left_{a}"] + at[f"right_{a}"]) / 2

    def chain(*names: str) -> np.ndarray:
        return np.mean(
            [
                sum(
                    np.linalg.norm(at[f"{s}_{a}"] - at[f"{s}_{b}"], axis=-1)
                    for a, b in zip(names, names[1:], strict=False)
                )
                for s in ("left", "right")
            ],
            axis=0,
        )

    trunk = np.linalg.norm(mid("shoulder") - mid("hip"), axis=-1)
    return np.stack(
        [trunk, chain("hip", "knee", "ankle"), chain("shoulder", "elbow", "wrist")], axis=1
    )


def _standing(body: BodyModel) -> np.ndarray:
    """(1, 19, 3) the body model's template standing, its root at its standing height."""
    return body.joint_positions(body.standing(np.array([0.0, body.height, 0.0])))


def body_size_from_points(body: BodyModel, points: np.ndarray) -> tuple[float, float, float]:
    """(scale, legs, arms) of the person whose body points (F, 19, 3) are given, relative to
    the body model's template (see the module docstring); frames with NaN are left out.

    Raises:
        ValueError: no complete frame, or a factor outside :data:`SIZE_RANGE`.
    """
    person = _lengths(points)
    person = np.nanmedian(person[np.isfinite(person).all(axis=1)], axis=0)
    template = _lengths(_standing(body))[0]
    if not np.isfinite(person).all():
        raise ValueError("no frame with every body point to measure the person's size")
    leg, arm = person[1] / template[1], person[2] / template[2]
    scale = np.sqrt(leg * arm)
    legs, arms = leg / scale, arm / scale
    out = (float(scale), float(legs), float(arms))
    if not all(SIZE_RANGE[0] <= f <= SIZE_RANGE[1] for f in out):
        raise ValueError(f"body size {out} outside {SIZE_RANGE}: not a measurement to trust")
    return out


def scaled_body(body: BodyModel, scale: float, legs: float = 1.0, arms: float = 1.0) -> BodyModel:
    """The body model with its template's bones scaled (module docstring)."""
    sk = body.skeleton
    below = np.zeros((2, sk.n_joints), dtype=bool)  # legs, arms
    for k, part in enumerate(("hip", "shoulder")):
        for side in ("left", "right"):
            top = int(body.points[BODY_POINTS.index(f"{side}_{part}")])
            for j in range(sk.n_joints):
                p = int(sk.parents[j])
                while p >= 0 and p != top:
                    p = int(sk.parents[p])
                below[k, j] |= p == top
    factor = np.where(below[0], scale * legs, np.where(below[1], scale * arms, scale))
    skeleton = dataclasses.replace(sk, offsets=sk.offsets * factor[:, None])
    return dataclasses.replace(body, skeleton=skeleton, height=body.height * scale * legs)


#: The segments :func:`segment_sizes_from_points` measures, each from one body point to the
#: next on both sides (shoulders: from one to the other), and scales in :func:`segment_body`.
SEGMENTS: tuple[tuple[str, str], ...] = (
    ("shoulder", "elbow"),
    ("elbow", "wrist"),
    ("hip", "knee"),
    ("knee", "ankle"),
    ("shoulders", "width"),
)


def _span(points: np.ndarray, segment: tuple[str, str]) -> np.ndarray:
    """(F,) a segment's length (mm) per frame of (F, 19, 3) body points, the mean of both
    sides (or the shoulders' width)."""
    at = {n: points[:, i] for i, n in enumerate(BODY_POINTS)}
    if segment == ("shoulders", "width"):
        return np.linalg.norm(at["left_shoulder"] - at["right_shoulder"], axis=-1)
    a, b = segment
    return np.mean(
        [np.linalg.norm(at[f"{s}_{a}"] - at[f"{s}_{b}"], axis=-1) for s in ("left", "right")],
        axis=0,
    )


def segment_sizes_from_points(
    body: BodyModel, points: np.ndarray, notes: list[str] | None = None
) -> dict[str, float]:
    """Each of :data:`SEGMENTS`' length, person to template (median over the frames in which
    both its ends are seen), from a person's body points (F, 19, 3): e.g. MediaPipe's landmarks
    triangulated from every camera (``track --body-size views``). The trunk and the hips are
    not measured (MediaPipe's hip landmarks are not a skeleton's hip joints). A segment never
    seen, or whose factor is outside :data:`SIZE_RANGE`, is left out (the template's is kept,
    :func:`segment_body`) and said in ``notes``: one implausible segment (a shoulder
    landmark on the clothes) does not throw away the others.

    Raises:
        ValueError: no segment measured within :data:`SIZE_RANGE`.
    """
    template = _standing(body)
    out, left_out = {}, []
    for segment in SEGMENTS:
        key = "-".join(segment)
        person = _span(np.asarray(points, dtype=float), segment)
        person = person[np.isfinite(person)]
        if not len(person):
            left_out.append(f"{key} never seen")
            continue
        factor = float(np.median(person) / _span(template, segment)[0])
        if SIZE_RANGE[0] <= factor <= SIZE_RANGE[1]:
            out[key] = factor
        else:
            left_out.append(f"{key} {factor:.3f} outside {SIZE_RANGE}")
    if not out:
        raise ValueError(f"{'; '.join(left_out)}: not a measurement to trust")
    if left_out and notes is not None:
        notes.append(f"body size: the template's kept for {'; '.join(left_out)}")
    return out


def segment_body(body: BodyModel, sizes: dict[str, float]) -> BodyModel:
    """The body model with each of :data:`SEGMENTS` scaled by ``sizes`` (person to template,
    :func:`segment_sizes_from_points`): the bones from one body point to the next, on both
    sides; the shoulders' width by the bones from the shoulders' common ancestor to each.
    The legs' change moves the root's standing height with them."""
    sk = body.skeleton
    parents = [int(p) for p in sk.parents]
    joint = {n: int(body.points[i]) for i, n in enumerate(BODY_POINTS)}
    factor = np.ones(sk.n_joints)

    def above(j: int) -> list[int]:
        out = []
        while j >= 0:
            out.append(j)
            j = parents[j]
        return out

    for (a, b), key in zip(SEGMENTS, ("-".join(s) for s in SEGMENTS), strict=True):
        for side in ("left", "right"):
            if (a, b) == ("shoulders", "width"):
                other = set(above(joint[f"{'right' if side == 'left' else 'left'}_shoulder"]))
                bones = [j for j in above(joint[f"{side}_shoulder"]) if j not in other]
            else:
                top = joint[f"{side}_{a}"]
                chain = above(joint[f"{side}_{b}"])
                bones = chain[: chain.index(top)] if top in chain else []
            factor[bones] *= sizes.get(key, 1.0)
    skeleton = dataclasses.replace(sk, offsets=sk.offsets * factor[:, None])
    sized = dataclasses.replace(body, skeleton=skeleton)

    def leg(m: BodyModel) -> float:  # hip to ankle, standing
        return float(_span(_standing(m), ("hip", "ankle"))[0])

    return dataclasses.replace(sized, height=body.height * leg(sized) / leg(body))

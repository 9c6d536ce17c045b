"""Common body points of any skeleton, found by joint names.

Different captures name and build their skeletons differently: CMU's salsa
BVH (``hip``, ``lShldr``, ``lForeArm`` ...), cgspeed's conversion of CMU
(``Hips``, ``LeftArm``, ``LeftForeArm`` ...), CMU's ASF (``root``,
``lhumerus``, ``lradius`` ...), Bandai's (``Hips``, ``UpperArm_L`` ...),
Mixamo's (``mixamorig:LeftArm``), 3ds Max Biped's (``Bip01 L UpperArm``).
Models that learn from one person and answer another, or evaluation that compares a generated person with a real
one on another skeleton, need the same points on both: the pelvis, spine,
head, shoulders, elbows, wrists, hips, knees, ankles and toes
(:data:`BODY_POINTS`; the VLMM paper's 13 markers are :data:`MARKER_POINTS`).

Each point is a joint's position (a BVH joint sits where its segment
starts: ``LeftForeArm`` is the elbow). A point is found by the first of its
synonyms (:data:`SYNONYMS`) that names a joint, compared after
normalisation: lower case, a namespace prefix (``mixamorig:``, ``Bip01 ``) dropped,
separators dropped, and the side written either way (``left``/``l`` before
or after the part's name). The synonyms are ordered so that a more
specific name wins (``LeftArm``, the shoulder joint, before
``LeftShoulder``, which in cgspeed's skeleton is the collar bone).
Written here because no maintained library does this across these naming
schemes (retargeting tools map by hand-written per-rig tables, as this is).
"""

from __future__ import annotations

import re
import weakref
from collections.abc import Sequence

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.core.words import bare_name
from markovmotion.errors import SkeletonMismatchError

#: Parts of the body found on either side, with their names in the skeletons we know,
#: most specific first.
_SIDED: dict[str, tuple[str, ...]] = {
    "shoulder": ("arm", "upperarm", "uparm", "humerus", "shldr", "shoulder"),
    "elbow": ("forearm", "lowerarm", "lowarm", "radius", "elbow"),
    "wrist": ("wrist", "hand"),
    "hip": ("upleg", "upperleg", "thigh", "femur", "hip"),
    "knee": ("leg", "lowerleg", "lowleg", "shin", "tibia", "knee", "calf"),
    "ankle": ("foot", "ankle"),
    # a leg ending at the ankle: its end site (``LeftFoot_end``, ``LeftAnkle_end``)
    "toe": ("toebase", "toes", "toe", "toe0", "footend", "toeend", "ankleend"),
}

#: Points on the body's midline and their names.
_MIDDLE: dict[str, tuple[str, ...]] = {
    "pelvis": ("hips", "hip", "pelvis", "root"),
    "spine": ("spine", "abdomen", "lowerback", "spine1", "torso"),  # a Kinect's mid-trunk
    "chest": ("chest2", "chest", "thorax", "spine2", "spine1", "upperback"),
    "neck": ("neck", "lowerneck", "neck1"),
    "head": ("head",),
}


def _sided(side: str, parts: tuple[str, ...]) -> tuple[str, ...]:
    words = ("left", "l") if side == "left" else ("right", "r")
    return tuple(f for p in parts for w in words for f in (w + p, p + w))


#: Where a skeleton has no joint of a point's own, the joint that stands for it in the
#: models' points (:func:`body_point_index`): the classic BVH trunk of one joint (Hips,
#: Chest, Neck) or two (Chest, Chest2) has no spine below its chest, a trunk of one spine
#: joint under the head (PyMO's demo walker: Hips, Spine, Head) no chest and no neck (the
#: head joint sits where the neck ends).
_STANDS_FOR: dict[str, tuple[str, ...]] = {
    "spine": ("chest",),
    "chest": ("spine",),
    "neck": ("head",),
}
#: As :data:`_STANDS_FOR`, a joint that ends its chain (no child but end sites): video2bvh's
#: CMU-like skeleton (from 3-D keypoints) ends its neck at Neck1, the nose, where CMU's goes
#: on to the head (a head renamed there is still missing, not taken to be Neck1).
_TIP_STANDS_FOR: dict[str, tuple[str, ...]] = {"head": ("neck1",)}

#: Per body point, the normalised joint names it is found by, in order of preference.
SYNONYMS: dict[str, tuple[str, ...]] = {
    **_MIDDLE,
    **{
        f"{side}_{part}": _sided(side, names)
        for side in ("left", "right")
        for part, names in _SIDED.items()
    },
}

#: The points every model and evaluation works with (19: midline, arms, legs).
BODY_POINTS: tuple[str, ...] = (
    "pelvis",
    "spine",
    "chest",
    "neck",
    "head",
    *(f"{s}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "wrist")),
    *(f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "ankle", "toe")),
)

#: Each body point's parent on the body's tree (the pelvis is the root).
PARENT: dict[str, str] = {
    "spine": "pelvis",
    "chest": "spine",
    "neck": "chest",
    "head": "neck",
    **{
        f"{s}_{p}": q
        for s in ("left", "right")
        for p, q in (
            ("shoulder", "chest"),
            ("elbow", f"{s}_shoulder"),
            ("wrist", f"{s}_elbow"),
            ("hip", "pelvis"),
            ("knee", f"{s}_hip"),
            ("ankle", f"{s}_knee"),
            ("toe", f"{s}_ankle"),
        )
    },
}


def find_points(names: Sequence[str]) -> dict[str, int]:
    """The body points (:data:`SYNONYMS`) among ``names`` (joint or marker names), each
    point's index into ``names`` (the first name it is found by; a name serves one point)."""
    found: dict[str, int] = {}
    wanted = {normalise(n): i for i, n in reversed(list(enumerate(names)))}
    for point, synonyms in SYNONYMS.items():
        hit = next((wanted[w] for w in synonyms if w in wanted), None)
        if hit is not None and hit not in found.values():
            found[point] = hit
    return found


def point_bones(names: Sequence[str]) -> np.ndarray:
    """(B, 2) rows (child, parent) of indices into ``names`` joining the named points that
    are body points (:data:`SYNONYMS`: ``R_SHOULDER``, ``LELB``-style names are not all
    found) along the body's tree, skipping absent points (a head with no neck hangs from the
    chest); empty when fewer than two are found. For drawing marker sets as stick figures."""
    found = find_points(names)
    rows = []
    for point, index in found.items():
        parent = PARENT.get(point)
        while parent is not None and parent not in found:
            parent = PARENT.get(parent)
        if parent is not None:
            rows.append((index, found[parent]))
    return np.array(rows, dtype=int).reshape(-1, 2)


def figure_bones(names: Sequence[str]) -> np.ndarray:
    """(B, 2) index pairs into ``names`` of the lines a stick figure of a marker set is drawn
    with: :func:`point_bones` (a tree), and the lines across it that make a marker set look
    like a person: across the shoulders and across the hips; where the trunk has no point
    of its own (the VLMM paper's 13 markers), each shoulder down to its hip and the head to
    both shoulders (its chain found nothing to hang from). Drawing only: the tree is what
    models and the web page's parents use."""
    found = find_points(names)
    rows = [tuple(r) for r in point_bones(names).tolist()]
    joined = {frozenset(r) for r in rows}

    def join(a: str, b: str) -> None:
        if a in found and b in found and frozenset((found[a], found[b])) not in joined:
            rows.append((found[a], found[b]))
            joined.add(frozenset((found[a], found[b])))

    join("right_shoulder", "left_shoulder")
    join("right_hip", "left_hip")
    if not any(p in found for p in ("pelvis", "spine", "chest", "neck")):
        for side in ("left", "right"):
            join(f"{side}_hip", f"{side}_shoulder")
            join("head", f"{side}_shoulder")
    return np.array(rows, dtype=int).reshape(-1, 2)


#: Points of the legs: a marker set with none of them shows no feet to stand on.
LEG_POINTS: tuple[str, ...] = tuple(
    f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "ankle", "toe")
)


#: The VLMM paper's 13 markers (§2.1.2): head, shoulders, elbows, wrists, hips, knees, ankles.
MARKER_POINTS: tuple[str, ...] = (
    "head",
    *(f"{s}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "wrist")),
    *(f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "ankle")),
)

_CACHE: weakref.WeakKeyDictionary[Skeleton, dict[tuple[str, ...], np.ndarray]] = (
    weakref.WeakKeyDictionary()
)


def normalise(name: str) -> str:
    """A joint name as compared with :data:`SYNONYMS`: lower case, no namespace (Mixamo's
    ``mixamorig:``, 3ds Max Biped's ``Bip01 ``/``Bip001_``), no separators."""
    name = bare_name(name).lower()
    name = re.sub(r"^bip\d+(?=[^a-z0-9])", "", name)
    return re.sub(r"[^a-z0-9]", "", name)


def body_point_index(
    skeleton: Skeleton, points: Sequence[str] = BODY_POINTS, what: str = "skeleton"
) -> np.ndarray:
    """Indices (P,) of the joints of ``skeleton`` that are ``points``.

    Raises:
        SkeletonMismatchError: some points match no joint; the message (naming
            ``what``) lists them and the joint names looked for.
        KeyError: a point that is not in :data:`SYNONYMS`.
    """
    points = tuple(points)
    known = _CACHE.setdefault(skeleton, {})
    if points in known:
        return known[points]
    unknown = [p for p in points if p not in SYNONYMS]
    if unknown:
        raise KeyError(f"unknown body points {unknown}; known: {', '.join(SYNONYMS)}")
    names = {}
    for j, n in enumerate(skeleton.names):
        names.setdefault(normalise(n), j)
    found, missing = [], []
    for p in points:
        j = next((names[s] for s in SYNONYMS[p] + _STANDS_FOR.get(p, ()) if s in names), None)
        if j is None:
            j = next(
                (
                    names[s]
                    for s in _TIP_STANDS_FOR.get(p, ())
                    if s in names
                    and not np.any((skeleton.parents == names[s]) & ~skeleton.end_site)
                ),
                None,
            )
        (missing.append(p) if j is None else found.append(j))
    if missing:
        detail = "; ".join(f"{p} (looked for {', '.join(SYNONYMS[p][:4])} ...)" for p in missing)
        reason = f"cannot find these body points among its joints: {detail}"
        raise SkeletonMismatchError(f"{what}: {reason}", reason)
    out = np.array(found, dtype=np.intp)
    known[points] = out
    return out


def body_points(
    motion: Motion,
    points: Sequence[str] = BODY_POINTS,
    positions: np.ndarray | None = None,
    body_centred: bool = False,
) -> np.ndarray:
    """(F, P, 3) positions in mm of ``points`` over ``motion`` (world or body-centred).

    ``positions``: the motion's world (or, with ``body_centred``, body-centred)
    joint positions, if already computed.
    """
    idx = body_point_index(motion.skeleton, points, motion.name or "motion")
    if positions is None:
        positions = motion.body_centred_positions() if body_centred else motion.positions()
    return positions[:, idx]


# ------------------------------------------------------------------ a body of points alone
#: Parent of each body point (index into :data:`BODY_POINTS`, -1 for the pelvis): the
#: spine up to the head, the arms from the neck, the legs from the pelvis.
POINT_PARENTS: tuple[int, ...] = tuple(
    {
        "pelvis": -1,
        "spine": 0,
        "chest": 1,
        "neck": 2,
        "head": 3,
        **{f"{s}_shoulder": 3 for s in ("left", "right")},
        **{f"{s}_hip": 0 for s in ("left", "right")},
    }.get(p, BODY_POINTS.index(p) - 1)
    for p in BODY_POINTS
)

#: A standing body's rest offsets of the points from their parents (mm, Y up, facing +Z,
#: the person's left at +X): only what a skeleton needs to tell its legs and sides apart.
_REST: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 950.0, 0.0),
    "spine": (0.0, 100.0, 0.0),
    "chest": (0.0, 200.0, 0.0),
    "neck": (0.0, 200.0, 0.0),
    "head": (0.0, 150.0, 0.0),
    "shoulder": (170.0, 0.0, 0.0),
    "elbow": (0.0, -290.0, 0.0),
    "wrist": (0.0, -250.0, 0.0),
    "hip": (90.0, -60.0, 0.0),
    "knee": (0.0, -420.0, 0.0),
    "ankle": (0.0, -410.0, 0.0),
    "toe": (0.0, -60.0, 140.0),
}


def _rest_offset(point: str) -> tuple[float, float, float]:
    side, _, part = point.partition("_")
    if not part:
        return _REST[point]
    x, y, z = _REST[part]
    return (x if side == "left" else -x, y, z)


#: A skeleton whose joints are the 19 body points, named as them (so that
#: :func:`body_point_index`, the dual HMM's input check and the virtual markers find them).
POINT_SKELETON = Skeleton(
    BODY_POINTS,
    np.array(POINT_PARENTS),
    np.array([_rest_offset(p) for p in BODY_POINTS]),
    tuple(
        ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
        if j == 0
        else ("Zrotation", "Xrotation", "Yrotation")
        for j in range(len(BODY_POINTS))
    ),
)


def points_motion(points: np.ndarray, fps: float, name: str = "points") -> Motion:
    """A Motion of :data:`POINT_SKELETON` whose joints are at ``points`` (F, 19, 3) mm (the
    body points in :data:`BODY_POINTS` order): every rotation the identity, every joint's
    translation its offset from its parent in that frame. Models that read people by their
    body points (the dual HMM's ``points="body"``, virtual markers) take it as any capture;
    the bones' lengths change from frame to frame as the points do, and limbs have no twist
    (a virtual marker off its bone sits off it in the world's axes)."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 3 or points.shape[1:] != (len(BODY_POINTS), 3):
        raise ValueError(f"points must be (F, {len(BODY_POINTS)}, 3), got {points.shape}")
    parents = np.array(POINT_PARENTS)
    translations = points.copy()
    translations[:, 1:] -= points[:, parents[1:]]
    rotations = np.zeros((len(points), len(BODY_POINTS), 4))
    rotations[..., 3] = 1.0
    return Motion(POINT_SKELETON, rotations, translations, fps, name)


def bone_lengths(points: np.ndarray) -> np.ndarray:
    """(P,) each body point's median distance (mm) from its parent (:data:`POINT_PARENTS`)
    over the frames (F, P, 3) where both are finite; NaN for the pelvis."""
    parents = np.asarray(POINT_PARENTS)
    child = np.nonzero(parents >= 0)[0]
    d = np.linalg.norm(points[:, child] - points[:, parents[child]], axis=-1)
    out = np.full(len(POINT_PARENTS), np.nan)
    seen = np.isfinite(d).any(axis=0)
    if seen.any():
        out[child[seen]] = np.nanmedian(d[:, seen], axis=0)
    return out


def with_bone_lengths(points: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(F, P, 3) body points whose segments have ``lengths`` (P,) (:func:`bone_lengths`):
    from the pelvis out, each point moved along its own direction from its (moved) parent.
    A tracker that finds each frame's points alone (MediaPipe) gives the same person bones
    of a different length every frame; a person's bones do not change."""
    out = np.array(points, dtype=float, copy=True)
    for j, parent in enumerate(POINT_PARENTS):  # parents come before their children
        if parent < 0 or not np.isfinite(lengths[j]):
            continue
        v = points[:, j] - points[:, parent]
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        out[:, j] = out[:, parent] + v / np.maximum(n, 1e-9) * lengths[j]
    return out

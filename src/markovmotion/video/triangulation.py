"""MediaPipe in every calibrated view, triangulated; and the guide it gives the particle filter.

Issue 24 asks for MediaPipe Pose "alone and to start or guide the annealed particle filter in
multi-view video" (the dual-HMM paper's tracker, §3, Deutscher et al. 2000). Two uses:

1. **Triangulation** (``track --method triangulate``). MediaPipe Pose
   (:mod:`markovmotion.video.monocular`) runs over each camera's video; each of the 33
   landmarks is triangulated per frame from the views that see it (visibility at least
   :data:`~markovmotion.video.monocular.MIN_VISIBILITY`) by the linear (DLT) method with each
   view's two rows weighted by its visibility: for a camera ``P = [R | t]`` and the landmark's
   normalised image point ``(x, y) = K^-1 (u, v, 1)``, the rows ``w (x P_3 - P_1)`` and
   ``w (y P_3 - P_2)`` of ``A``, and the point is the right singular vector of ``A`` with the
   smallest singular value (Hartley and Zisserman, *Multiple View Geometry*, §12.2), refined by
   three Gauss-Newton steps on the visibility-weighted squared reprojection error (the
   geometric error of their §12.1).
   **Robust** (MSAC, Torr and Zisserman 2000): every subset of 2 or more of the seeing views
   is triangulated and scored over all seeing views by ``sum_v w_v min(e_v^2, tau^2)``, with
   ``e_v`` the reprojection error in pixels and ``tau`` :data:`OUTLIER_ANGLE` focal lengths;
   the best subset's inliers (``e_v < tau``) are triangulated again. A view whose MediaPipe put
   the landmark elsewhere (a left/right swap seen from behind, an arm hidden by the body) is
   thus rejected when the others agree. (Dropping the worst view greedily while 3 or more
   remain, tried first, can end on a wrong pair: on the real video's frame 80 it kept two
   views that put the right wrist on the floor.) The landmarks map to the 19 body points by
   the monocular path's weight matrix (:func:`~markovmotion.video.monocular.to_body_points`).
   Before it, the views that saw someone else in a frame are left out and MediaPipe looks
   again around the tracked person there (:func:`one_person`, :func:`look_again`: MediaPipe
   finds one person per image, and with two people in the room each camera may pick another),
   and MediaPipe's left and right are made to agree across the views
   (:func:`consistent_views`, default ``views``: :func:`views_sides`), since the camera behind
   the person sees it mirrored. After it, a landmark that leaves its path for a frame or two
   is taken out (:meth:`Triangulated.despiked`, a Hampel filter) and the paths are smoothed
   over time by a Gaussian whose width is chosen on the video by leaving one view out
   (:func:`choose_smoothing`).
2. **Guide** (``track --guide mediapipe``). :class:`Guide` adds to the particle filter's cost
   (the ``E`` of ``w = exp(-beta E)``) a term for the distance between a particle's 12 limb
   joints projected into each view and MediaPipe's 2-D landmarks there, weighted by
   visibility and by whether triangulation kept that view: per view and joint the robust
   ``d^2 / (d^2 + sigma^2)`` with ``sigma`` = :data:`GUIDE_ANGLE` focal lengths, averaged, so
   the term lies in [0, 1] and one wrong landmark costs at most its share.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from markovmotion.errors import MotionFormatError
from markovmotion.features.body_points import BODY_POINTS
from markovmotion.video.body_model import BodyModel
from markovmotion.video.cameras import CalibratedCamera, capture_centre, lone_video
from markovmotion.video.monocular import (
    LANDMARK_WEIGHTS,
    LANDMARKS,
    MIN_VISIBILITY,
    REFERENCE_JOINTS,
    Landmarks,
    detect_landmarks,
    reference_report,
)
from markovmotion.video.render import (
    expected_frames,
    header_shortfall,
    read_frames,
    shortest_note,
)

#: A view whose reprojection error exceeds this many focal lengths (radians) is dropped when
#: at least 3 views see the landmark (0.03: 12 px at the real video's 272x480, focal ~400 px;
#: its reference's own residual is about 5 px).
OUTLIER_ANGLE = 0.03
#: Nearest depth (mm) in front of a camera a triangulated point may lie.
MIN_DEPTH = 1.0
#: Scale of the guide's robust distance, in focal lengths (0.025: 10 px at focal 400 px).
GUIDE_ANGLE = 0.025
#: Scale (mm) of the robust loss fitting the body model to the triangulated points.
FIT_SCALE = 50.0


def _dlt(proj: list[np.ndarray], xy: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Points (N, 3) by the weighted DLT (module docstring) from normalised image points
    ``xy`` (V, N, 2) with weights ``w`` (V, N) (0: view not used); NaN where fewer than 2
    views are used, and where the point is not in front of every view used (the cheirality
    test, Hartley and Zisserman §21.6: rays that do not meet before the cameras, as when two
    views see two different people, meet behind them or at infinity)."""
    v_n, n = w.shape
    rows = np.zeros((n, 2 * v_n, 4))
    for v in range(v_n):
        rows[:, 2 * v] = w[v, :, None] * (xy[v, :, :1] * proj[v][2] - proj[v][0])
        rows[:, 2 * v + 1] = w[v, :, None] * (xy[v, :, 1:] * proj[v][2] - proj[v][1])
    out = np.full((n, 3), np.nan)
    ok = (w > 0).sum(axis=0) >= 2
    if ok.any():
        h = np.linalg.svd(rows[ok])[2][:, -1]
        out[ok] = h[:, :3] / np.where(np.abs(h[:, 3:]) > 1e-12, h[:, 3:], 1e-12)
    return _in_front(proj, w, out)


def _refine(
    cameras: Sequence[CalibratedCamera],
    pixels: np.ndarray,
    w: np.ndarray,
    points: np.ndarray,
    steps: int = 3,
) -> np.ndarray:
    """Points (N, 3) moved by Gauss-Newton steps to minimise the weighted squared reprojection
    error ``sum_v w_v |pi_v(X) - x_v|^2`` from the DLT's (the geometric error, Hartley and
    Zisserman §12.1, rather than the DLT's algebraic one)."""
    ok = np.isfinite(points).all(axis=1) & ((w > 0).sum(axis=0) >= 2)
    x = points[ok].copy()
    for _ in range(steps):
        jtj = np.zeros((len(x), 3, 3))
        jtr = np.zeros((len(x), 3))
        for c, pix, wv in zip(cameras, pixels[:, ok], w[:, ok], strict=True):
            cam = x @ c.R.T + c.t
            z = np.maximum(cam[:, 2:], MIN_DEPTH)
            res = np.nan_to_num(c.project(x)[0] - pix)  # (n, 2)
            ju = c.K[0, 0] * (c.R[0] - cam[:, :1] / z * c.R[2]) / z  # (n, 3)
            jv = c.K[1, 1] * (c.R[1] - cam[:, 1:2] / z * c.R[2]) / z
            jac = np.stack([ju, jv], axis=1) * wv[:, None, None] ** 0.5  # (n, 2, 3)
            jtj += np.einsum("nki,nkj->nij", jac, jac)
            jtr += np.einsum("nki,nk->ni", jac, res * wv[:, None] ** 0.5)
        # Levenberg's damping, relative to the system's scale: a point whose views nearly
        # agree on one ray only (rank 1) still takes a finite step along the others
        damp = 1e-9 * (np.trace(jtj, axis1=1, axis2=2) + 1.0)
        x -= np.linalg.solve(jtj + damp[:, None, None] * np.eye(3), jtr[..., None])[..., 0]
    out = points.copy()
    out[ok] = x
    return _in_front([np.c_[c.R, c.t] for c in cameras], w, out)


def _in_front(proj: list[np.ndarray], w: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (N, 3) with NaN where a point is not in front of every view (``proj``: each
    camera's ``[R | t]``) whose weight (``w`` (V, N)) is positive (the cheirality test of
    :func:`_dlt`; NaN points stay NaN)."""
    depth = np.stack([points @ p[2, :3] + p[2, 3] for p in proj])  # (V, N)
    out = points.copy()
    out[((w > 0) & ~(depth > MIN_DEPTH)).any(axis=0)] = np.nan
    return out


def _normalised(cameras: Sequence[CalibratedCamera], pixels: np.ndarray) -> np.ndarray:
    """(V, N, 2) normalised image points ``K^-1 (u, v, 1)`` of ``pixels`` (V, N, 2) (NaN as 0:
    their weight says they are not seen)."""
    return np.stack(
        [
            (np.c_[np.nan_to_num(p), np.ones(len(p))] @ np.linalg.inv(c.K).T)[:, :2]
            for p, c in zip(pixels, cameras, strict=True)
        ]
    )


def _tau2(cameras: Sequence[CalibratedCamera], angle: float) -> np.ndarray:
    """(V, 1) squared pixel scale of ``angle`` focal lengths in each camera."""
    return np.array([(angle * c.focal) ** 2 for c in cameras])[:, None]


def _errors2(cameras: Sequence[CalibratedCamera], pixels: np.ndarray, points: np.ndarray):
    """(V, N) squared pixel errors of points (N, 3) projected against ``pixels`` (V, N, 2)."""
    return np.stack(
        [
            ((c.project(np.nan_to_num(points))[0] - np.nan_to_num(p)) ** 2).sum(-1)
            for c, p in zip(cameras, pixels, strict=True)
        ]
    )


def triangulate_points(
    cameras: Sequence[CalibratedCamera],
    pixels: np.ndarray,
    weights: np.ndarray,
    outlier_angle: float = OUTLIER_ANGLE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (N, 3) triangulated from ``pixels`` (V, N, 2) seen with ``weights`` (V, N) (0: not
    seen) by the weighted DLT, robustly (module docstring): every subset of 2 or more seeing
    views is a candidate, scored over all seeing views by ``sum w min(e^2, tau^2)`` (MSAC;
    ``e`` the reprojection error, ``tau`` = ``outlier_angle`` focal lengths); the best one's
    inliers (``e < tau``, at least its own views) are triangulated again. Also the views used
    (V, N) and their largest reprojection error (N,) in pixels. Points seen by fewer than 2
    views are NaN."""
    from itertools import combinations

    v_n, n = weights.shape
    if len(cameras) != v_n or pixels.shape != (v_n, n, 2):
        raise ValueError("one pixel array and one weight row per camera")
    seen = (weights > 0) & np.isfinite(pixels).all(axis=-1)
    w = np.where(seen, weights, 0.0)
    proj = [np.c_[c.R, c.t] for c in cameras]  # (3, 4) in normalised coordinates
    xy = _normalised(cameras, pixels)
    tau2 = _tau2(cameras, outlier_angle)

    def errors2(points: np.ndarray) -> np.ndarray:
        return _errors2(cameras, pixels, points)

    best = np.full(n, np.inf)
    choice = np.zeros((v_n, n), bool)
    for k in range(2, v_n + 1):
        for subset in combinations(range(v_n), k):
            mask = np.zeros((v_n, 1), bool)
            mask[list(subset)] = True
            ok = seen[list(subset)].all(axis=0)
            if not ok.any():
                continue
            pts = _dlt(proj, xy, np.where(mask & ok, w, 0.0))
            score = (w * np.minimum(errors2(pts), tau2)).sum(axis=0)
            score = np.where(ok, score - 1e-9 * k, np.inf)  # ties: the larger subset
            better = score < best
            best = np.where(better, score, best)
            inl = seen & ((errors2(pts) < tau2) | mask)
            choice[:, better] = inl[:, better]
    used = choice & seen
    points = _refine(
        cameras, pixels, np.where(used, w, 0.0), _dlt(proj, xy, np.where(used, w, 0.0))
    )
    used &= np.isfinite(points).all(axis=1)[None]
    worst = np.where(used, errors2(points), -1.0).max(axis=0)
    worst = np.where(used.any(axis=0), np.sqrt(np.maximum(worst, 0.0)), np.nan)
    return points, used, worst


def landmarks_to_body_points(landmarks: np.ndarray) -> np.ndarray:
    """(..., 19, 3) body points of (..., 33, 3) landmarks; NaN only where a landmark a point
    is made of is NaN (the others do not spread)."""
    known = np.isfinite(landmarks).all(axis=-1)  # (..., 33)
    pts = np.einsum("pl,...lc->...pc", LANDMARK_WEIGHTS, np.nan_to_num(landmarks))
    missing = np.einsum("pl,...l->...p", (LANDMARK_WEIGHTS > 0).astype(float), (~known) * 1.0)
    return np.where(missing[..., None] > 0, np.nan, pts)


@dataclass
class ViewLandmarks:
    """MediaPipe's 2-D landmarks in every camera: ``pixels`` (V, F, 33, 2), ``visibility``
    (V, F, 33) (0 where no person was found), and the seconds MediaPipe took."""

    cameras: list[CalibratedCamera]
    pixels: np.ndarray
    visibility: np.ndarray
    seconds: float = 0.0
    #: MediaPipe's hip-centred world points (V, F, 33, 3) mm, if kept (``continuity`` needs them).
    world: np.ndarray | None = None
    #: One line per camera's video that ended before the others' (:func:`ended_notes`).
    notes: list[str] = field(default_factory=list)

    @classmethod
    def from_videos(
        cls,
        videos: Sequence[str | os.PathLike[str]],
        cameras: Sequence[CalibratedCamera],
        max_frames: int | None = None,
    ) -> ViewLandmarks:
        """MediaPipe Pose over each camera's video (``scripts/install-camera``), over the
        frames at least two of them have: a video that ends before the others (cut short, or
        damaged in its middle: OpenCV stops at a frame it cannot decode) gives no landmarks
        after its end, as a view that does not see the person, and the others carry on
        (:func:`ended_notes` says so). They had all been cut to the shortest: one damaged
        video of four had left 18 of 100 frames tracked."""
        got: list[Landmarks] = [
            detect_landmarks(
                read_frames(v, c),
                max_frames,
                f"MediaPipe {c.name}",
                expected_frames([v], max_frames, [c]),
            )
            for v, c in zip(videos, cameras, strict=True)
        ]
        lengths = [len(g.found) for g in got]
        n = two_views_have(lengths)

        def padded(a: np.ndarray, fill: float) -> np.ndarray:  # cut or padded to n frames
            out = np.full((n, *a.shape[1:]), fill)
            out[: min(n, len(a))] = a[:n]
            return out

        short = [
            header_shortfall(v, k, c, max_frames)
            for v, k, c in zip(videos, lengths, cameras, strict=True)
        ]
        return cls(
            list(cameras),
            np.stack([padded(g.pixels, np.nan) for g in got]),
            np.stack([padded(np.where(g.found[:, None], g.visibility, 0.0), 0.0) for g in got]),
            sum(g.seconds for g in got),
            np.stack([padded(g.world, np.nan) for g in got]),
            ended_notes([Path(v).name for v in videos], lengths, short),
        )


def ended_notes(names: Sequence[str], lengths: Sequence[int], short: Sequence[str]) -> list[str]:
    """One line per view whose video (``names``) gave fewer frames (``lengths``) than the
    others', with its header's count when that is more (``short``,
    :func:`~markovmotion.video.render.header_shortfall`), and what is done: the frames after
    its end come from the views that still have video (at least two), and a view alone past
    the others' ends is cut (a point needs two views)."""
    if len(lengths) == 1:
        note = shortest_note(names, lengths, short)
        return [note] if note else []
    n = two_views_have(lengths)
    out = []
    for name, k, why in zip(names, lengths, short, strict=True):
        if k < n:
            out.append(
                f"note: {name} ended after {k} frames{why}, before the other views: they "
                f"carry on without it over frames {k}-{n - 1}"
            )
        elif why:
            out.append(f"note: {name} ended after {k} frames{why}")
    if max(lengths) > n:
        longest = names[int(np.argmax(lengths))]
        out.append(
            f"note: {longest} alone goes on after the others end: {n} frames tracked "
            "(a point needs two views)"
        )
    return out


#: Cost per frame (torso lengths) of taking, of a labelling and its mirror, the one that swaps
#: every seeing view's labels, against the one that keeps them all (:func:`views_sides`).
#: Chosen by leaving one kind of motion out over 11 rendered held-out kinds among 0, 0.25,
#: 0.5, 1, 2 and 4 (``benchmarks/mirror_cost.py``; every fold chose 0.25; docs/video.md).
MIRROR_COST = 0.25
#: How MediaPipe's left and right are made consistent before triangulation
#: (:func:`consistent_views`).
LEFT_RIGHT: tuple[str, ...] = ("views", "continuity", "both", "mediapipe")


def views_sides(
    views: ViewLandmarks,
    min_visibility: float = MIN_VISIBILITY,
    over_time: bool = True,
    mirror_cost: float = MIRROR_COST,
) -> tuple[ViewLandmarks, np.ndarray]:
    """MediaPipe's landmarks with left and right made to agree across the views, and which
    views' groups were swapped back (V, F, len(SIDE_GROUPS)).

    One view cannot tell a person seen from behind from one facing it, and MediaPipe, assuming
    the face, mirrors the whole body or some limbs (on the rendered held-out kinds, the camera
    behind the person swaps a group in 40-80 % of the frames); several calibrated views can,
    because a wrong labelling does not triangulate. Per frame and per group of
    :data:`~markovmotion.video.left_right.SIDE_GROUPS`, every labelling of the views (each
    view's pairs kept or swapped; a labelling and its mirror, every view swapped, triangulate
    the same points and count as one) is triangulated by :func:`triangulate_points` and scored
    as its MSAC does, ``sum_v w_v min(e_v^2, tau^2)`` over the group's landmarks; the best is
    kept. Of it and its mirror, the one that swaps less of the views' visibility is taken
    (MediaPipe's labels where most views agree); ties keep MediaPipe's labels."""
    from itertools import product

    from markovmotion.video.left_right import (
        SIDE_GROUPS,
        continuity_costs,
        decode_labels,
        landmark_pair,
        relabel,
        torso_lengths,
    )

    v_n, f_n, l_n = views.visibility.shape
    w = np.where(views.visibility >= min_visibility, views.visibility, 0.0)
    plain = triangulate_views(views, min_visibility).landmarks  # torso: the same either way
    torso = torso_lengths(plain)
    torso = float(np.nanmedian(torso)) if np.isfinite(torso).any() else 1.0
    pixels, vis, world = views.pixels.copy(), views.visibility.copy(), views.world
    world = None if world is None else world.copy()
    swapped = np.zeros((v_n, f_n, len(SIDE_GROUPS)), dtype=bool)
    labellings = np.array([(0, *s) for s in product((0, 1), repeat=v_n - 1)], dtype=bool)
    tau2 = _tau2(views.cameras, OUTLIER_ANGLE)
    for g, stems in enumerate(SIDE_GROUPS):
        pairs = [landmark_pair(s) for s in stems]
        li, ri = (list(x) for x in zip(*pairs, strict=True))
        own, other = li + ri, ri + li
        c_n, n = len(labellings), len(own)
        # (V, C, F, 2n): each labelling's pixels and weights of the group's landmarks
        px = np.where(
            labellings.T[:, :, None, None, None],
            views.pixels[:, None][:, :, :, other],
            views.pixels[:, None][:, :, :, own],
        )
        wc = np.where(
            labellings.T[:, :, None, None], w[:, None][:, :, :, other], w[:, None][:, :, :, own]
        )
        pts, _, _ = triangulate_points(views.cameras, px.reshape(v_n, -1, 2), wc.reshape(v_n, -1))
        e2 = _errors2(views.cameras, px.reshape(v_n, -1, 2), pts)
        score = (wc.reshape(v_n, -1) * np.minimum(e2, tau2)).sum(axis=0)
        score = np.where(np.isfinite(pts).all(axis=1), score, 0.0).reshape(c_n, f_n, n).sum(-1)
        pick = np.argmin(score, axis=0)  # (F,); ties: the first, all kept
        best = labellings[pick]  # (F, V)
        seen = w[:, :, own].sum(axis=-1).T  # (F, V) each view's weight of the group
        share = (seen * best).sum(axis=1) / np.maximum(seen.sum(axis=1), 1e-9)
        mirror = share > 0.5
        best ^= mirror[:, None]
        share = np.where(mirror, 1.0 - share, share)  # of the views' weight swapped
        if over_time:
            # the triangulated group (the majority's labels) over time: a mirror chosen
            # against the frames around it is a jump of its left and right points
            got = pts.reshape(c_n, f_n, n, 3)[pick, np.arange(f_n)]
            got = np.where(mirror[:, None, None], got[:, np.r_[n // 2 : n, 0 : n // 2]], got)
            body = np.full((f_n, l_n, 3), np.nan)
            body[:, own] = got
            ones = np.ones((f_n, l_n))
            cont = [continuity_costs(body, ones, pairs, lag, torso) for lag in (1, 2)]
            unary = mirror_cost * np.c_[share, 1.0 - share]
            best ^= decode_labels(cont[0], unary, cont[1]).astype(bool)[:, None]
        swapped[:, :, g] = best.T
        for v in range(v_n):
            arrays = (pixels[v], vis[v]) if world is None else (pixels[v], vis[v], world[v])
            relabel(arrays, best[:, v], pairs)
    out = ViewLandmarks(views.cameras, pixels, vis, views.seconds, world)
    return out, swapped


#: A view sees the tracked person when its mirror-invariant points lie within this many focal
#: lengths (median) of the person triangulated from other views (:func:`one_person`; 0.05: 21
#: px at the real video's 272x480, where two people half a metre apart at 3 m are 0.17 apart).
PERSON_ANGLE = 0.05
#: Speed (mm/s) that :func:`one_person` takes as one unit of cost per frame of the tracked
#: person's centre moving: a view of someone else a metre away costs tens of units, far more
#: than losing every view (at most one unit each).
PERSON_SPEED = 1500.0
#: Cost per frame and metre of a candidate person's centre from where the cameras look
#: (:func:`capture_centre`), beyond the nearest candidate's: of people seen by as many views,
#: the one the cameras are aimed at is followed (a metre further out weighs as much as one
#: view fewer); a person alone pays nothing, however far out.
PERSON_CENTRE_COST = 1.0
#: MediaPipe's left/right landmark stems whose midpoints (with the nose) are the same whether
#: a view mirrors the body or not: what :func:`one_person` compares across the views.
MIDLINE_STEMS: tuple[str, ...] = ("ear", "shoulder", "elbow", "wrist", "hip", "knee", "ankle")


#: ``track --person``: the person named is the one nearest the ray through its pixel over the
#: video's first this many seconds.
PERSON_PICK_SECONDS = 0.5


@dataclass(frozen=True)
class Aim:
    """Where :func:`one_person` looks for the person to follow: a point (mm; where the
    cameras are aimed, :func:`capture_centre`) or, with a ``direction`` (unit), the line
    through it over the first ``frames`` frames (the ray through a pixel a user names,
    :func:`person_ray`)."""

    origin: np.ndarray
    direction: np.ndarray | None = None
    frames: int | None = None

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(...) mm from points (..., 3) to the point, or to the line."""
        d = np.asarray(points, dtype=float) - self.origin
        if self.direction is not None:
            d = d - (d @ self.direction)[..., None] * self.direction
        return np.linalg.norm(d, axis=-1)


def person_ray(cameras: Sequence[CalibratedCamera], text: str, fps: float = 30.0) -> Aim:
    """``track --person CAMERA:U,V``: the ray through pixel (U, V) of the camera named CAMERA
    (its name in the camera file, or its number from 0), in the video's own pixels (through
    the lens's distortion when the camera has one), over the first
    :data:`PERSON_PICK_SECONDS` of a video at ``fps``: the person there at the start.

    Raises:
        ValueError: one line: not CAMERA:U,V, no such camera, or a pixel outside its image.
    """
    name, _, pixel = str(text).rpartition(":")
    try:
        if not name:
            raise ValueError
        u, v = (float(x) for x in pixel.split(","))
    except ValueError:
        raise ValueError(f"{text!r} is not CAMERA:U,V (e.g. cam0:135,240)") from None
    names = [c.name for c in cameras]
    k = names.index(name) if name in names else int(name) if name.isdigit() else -1
    if not 0 <= k < len(cameras):
        raise ValueError(f"no camera {name!r} (the cameras: {', '.join(names)})")
    cam = cameras[k]
    if not (0 <= u < cam.width and 0 <= v < cam.height and np.isfinite([u, v]).all()):
        raise ValueError(f"pixel {u:g},{v:g} is outside {cam.name}'s {cam.width}x{cam.height}")
    xy = np.array([u, v])
    if any(cam.distortion):
        import cv2

        xy = cv2.undistortPoints(
            xy.reshape(1, 1, 2), cam.K, np.asarray(cam.distortion, float), P=cam.K
        ).reshape(2)
    frames = max(1, int(round(PERSON_PICK_SECONDS * fps)))
    return Aim(cam.centre, cam.ray(xy), frames)


def _where_named(aim: Aim, centres: np.ndarray, cost: np.ndarray) -> Aim | None:
    """A ray's person as a point: the median centre, over the ray's first frames, of the
    candidate (``centres`` (F, C, 3), finite ``cost`` (F, C)) nearest the ray in each; None
    when no one is seen then."""
    first = slice(0, aim.frames)
    away = np.where(np.isfinite(cost[first]), aim.distance(centres[first]), np.inf)
    seen = np.isfinite(away).any(axis=1)
    if not seen.any():
        return None
    pick = centres[first][seen, np.argmin(away[seen], axis=1)]
    return Aim(np.median(pick, axis=0))


def midline_points(
    views: ViewLandmarks, min_visibility: float = MIN_VISIBILITY
) -> tuple[np.ndarray, np.ndarray]:
    """Each view's mirror-invariant points: the nose and the midpoint of each left/right pair
    of :data:`MIDLINE_STEMS`, pixels (V, F, P, 2) and weights (V, F, P) (the pair's smaller
    visibility; 0 below ``min_visibility``). A camera behind the person, which MediaPipe sees
    mirrored, gives the same points as if it had not mirrored it."""
    from markovmotion.video.left_right import landmark_pair

    w = np.where(views.visibility >= min_visibility, views.visibility, 0.0)
    nose = LANDMARKS.index("nose")
    pairs = [landmark_pair(s) for s in MIDLINE_STEMS]
    left, right = (list(x) for x in zip(*pairs, strict=True))
    pixels = np.concatenate(
        [views.pixels[:, :, [nose]], 0.5 * (views.pixels[:, :, left] + views.pixels[:, :, right])],
        axis=2,
    )
    weights = np.concatenate([w[:, :, [nose]], np.minimum(w[:, :, left], w[:, :, right])], axis=2)
    return pixels, weights


def one_person(
    views: ViewLandmarks,
    fps: float,
    min_visibility: float = MIN_VISIBILITY,
    angle: float = PERSON_ANGLE,
    aim: Aim | None = None,
) -> tuple[ViewLandmarks, np.ndarray]:
    """MediaPipe's landmarks with every view that saw someone else in a frame dropped
    (visibility 0), and which views were kept (V, F).

    MediaPipe Pose (0.10.21's bundled model) finds one person per image. With two or more
    people in the room, each camera may pick another (in Pose2Sim's multi-person demo, two of
    four cameras see the woman in front of the man), and triangulating landmarks of different
    people puts points between them. Per frame, with each view's :func:`midline_points`
    (mirror-invariant, so the camera behind the person still counts), every subset of 2 or
    more seeing views is triangulated (the weighted DLT) and each seeing view scored by the
    visibility-weighted median reprojection error of its points, ``e_v`` in focal lengths;
    a subset whose own views all lie within ``angle`` is a candidate person, with the views
    within ``angle`` (its inliers) and the MSAC cost ``sum_v min(e_v, angle)^2 / angle^2``
    (a view without the person costs 1), plus :data:`PERSON_CENTRE_COST` per metre that the
    candidate's centre is further than the nearest candidate's from where the cameras are
    aimed (:func:`capture_centre`), or from ``aim``: a ray through a pixel a user named
    (:func:`person_ray`) stands for where the person nearest it over its first frames stood
    then. Over time
    the path of least cost through the
    candidates (and "no one": every view costs 1), each frame's step costing the distance
    between the two candidates' centres over :data:`PERSON_SPEED` per frame (Viterbi, Rabiner
    eqs. 32-35, with costs that depend on the frame), follows one person: the one most views
    see over the take (of people seen alike, the one the cameras are aimed at), kept while
    the views find them. "No one" holds where the person was lost, so that coming back as
    someone else costs the distance too (:func:`_person_path`).

    Written here, not taken from a library: multi-person association across calibrated views
    (as in Pose2Sim's ``personAssociation``) needs every person's detection in every view;
    MediaPipe's bundled model gives one, so the question is only which views agree on it.
    """
    from itertools import combinations

    v_n, f_n, _ = views.visibility.shape
    if v_n < 2:
        return views, views.visibility.max(axis=2) > 0
    pixels, weights = midline_points(views, min_visibility)
    p_n = pixels.shape[2]
    cams = views.cameras
    proj = [np.c_[c.R, c.t] for c in cams]
    xy = _normalised(cams, pixels.reshape(v_n, -1, 2))  # (V, F P, 2)
    focal = np.array([c.focal for c in cams])
    seeing = weights.sum(axis=2) > 0  # (V, F)
    subsets = [s for k in range(2, v_n + 1) for s in combinations(range(v_n), k)]
    if aim is None:
        middle = capture_centre(cams)
        aim = Aim(middle) if middle is not None else None
    c_n = len(subsets) + 1  # the last: no one
    cost = np.full((f_n, c_n), np.inf)
    cost[:, -1] = v_n
    inliers = np.zeros((f_n, c_n, v_n), dtype=bool)
    centres = np.full((f_n, c_n, 3), np.nan)
    wflat = weights.reshape(v_n, -1)
    for c, subset in enumerate(subsets):
        mask = np.zeros((v_n, 1), bool)
        mask[list(subset)] = True
        pts = _dlt(proj, xy, np.where(mask, wflat, 0.0)).reshape(f_n, p_n, 3)
        err = np.full((v_n, f_n), np.inf)
        for v, cam in enumerate(cams):
            e = np.linalg.norm(cam.project(np.nan_to_num(pts))[0] - pixels[v], axis=-1)
            e = np.where(np.isfinite(pts).all(axis=-1) & (weights[v] > 0), e / focal[v], np.nan)
            err[v] = _weighted_median(e, weights[v])
        ok = np.isfinite(err) & (err < angle)  # (V, F)
        valid = ok[list(subset)].all(axis=0) & seeing[list(subset)].all(axis=0)
        score = np.where(ok, (err / angle) ** 2, 1.0).sum(axis=0)
        cost[valid, c] = score[valid]
        inliers[:, c] = ok.T
        centres[:, c] = _nanmean_points(pts)
    if aim is not None and aim.direction is not None:
        aim = _where_named(aim, centres[:, :-1], cost[:, :-1])
    if aim is not None:  # relative to the nearest candidate: a lone person far out is
        # still better than no one
        away = aim.distance(centres[:, :-1]) / 1e3
        away = np.where(np.isfinite(cost[:, :-1]), away, np.inf)
        nearest = np.min(away, axis=1, keepdims=True)
        cost[:, :-1] += PERSON_CENTRE_COST * (away - np.where(np.isfinite(nearest), nearest, 0.0))
    cost = np.where(np.isfinite(cost), cost, np.inf)
    step = PERSON_SPEED / max(float(fps), 1e-9)
    path = _person_path(cost, centres, step, float(v_n))
    kept = inliers[np.arange(f_n), path].T  # (V, F)
    vis = np.where(kept[:, :, None], views.visibility, 0.0)
    out = ViewLandmarks(views.cameras, views.pixels, vis, views.seconds, views.world)
    return out, kept


#: Seconds over which :func:`look_again` looks for a person lost in every view where they
#: were last (or will next be) triangulated.
LOST_SECONDS = 0.5
#: Margin around the tracked person's projected landmarks, as a share of the box's longer side,
#: of the image :func:`look_again` gives MediaPipe.
CROP_MARGIN = 0.25


def look_again(
    views: ViewLandmarks,
    videos: Sequence[str | os.PathLike[str]],
    fps: float,
    min_visibility: float = MIN_VISIBILITY,
    aim: Aim | None = None,
) -> tuple[ViewLandmarks, ViewLandmarks]:
    """``views`` with MediaPipe run again, on a crop around the tracked person, in every view
    and frame that saw someone else or no one (:func:`one_person`); and those views with the
    views of someone else left out (:func:`one_person` of them, decided once).

    The person the most views agree on is triangulated from them; in each other view the
    square around the projection of their landmarks (with :data:`CROP_MARGIN`) is cut out
    and given to MediaPipe on its own (static-image mode), and what it finds there is put
    back in the view's pixels. :func:`one_person` then keeps it only if it agrees with the
    other views: a crop that still holds someone else in front is dropped as before."""
    from markovmotion.video.monocular import frame_landmarks, pose_estimator

    agreed, kept = one_person(views, fps, min_visibility, aim=aim)
    redo = ~kept  # (V, F)
    if not redo.any() or not kept.any():
        return views, agreed
    body = triangulate_views(agreed, min_visibility).landmarks  # (F, 33, 3)
    known = np.isfinite(body).all(axis=-1).sum(axis=1) >= 8
    body, known = _held_over_gaps(body, known, int(round(fps * LOST_SECONDS)))
    redo &= known[None]
    if not redo.any():
        return views, agreed
    pixels, vis = views.pixels.copy(), views.visibility.copy()
    world = None if views.world is None else views.world.copy()
    t0 = time.perf_counter()
    with pose_estimator(static=True) as est:
        for v, (video, cam) in enumerate(zip(videos, views.cameras, strict=True)):
            if not redo[v].any():
                continue
            for f, rgb in enumerate(read_frames(video, cam)):
                if f >= redo.shape[1]:
                    break
                if not redo[v, f]:
                    continue
                xy = cam.project(body[f][np.isfinite(body[f]).all(axis=-1)])[0]
                box = _crop_box(xy, rgb.shape[1], rgb.shape[0])
                if box is None:
                    continue
                x0, y0, x1, y1 = box
                got = frame_landmarks(est, rgb[y0:y1, x0:x1])
                if got is None:
                    continue
                pixels[v, f] = got[0] + (x0, y0)
                vis[v, f] = got[2]
                if world is not None:
                    world[v, f] = got[1]
    seconds = views.seconds + time.perf_counter() - t0
    found = ViewLandmarks(views.cameras, pixels, vis, seconds, world)
    return found, one_person(found, fps, min_visibility, aim=aim)[0]


def _held_over_gaps(body: np.ndarray, known: np.ndarray, frames: int):
    """Landmarks (F, 33, 3) with each frame not ``known`` (F,) given the nearest known frame's,
    if one is at most ``frames`` away; and which frames now have one."""
    idx = np.flatnonzero(known)
    if not len(idx) or frames <= 0:
        return body, known
    at = np.arange(len(body))
    nearest = idx[np.clip(np.searchsorted(idx, at), 0, len(idx) - 1)]
    before = idx[np.clip(np.searchsorted(idx, at, side="right") - 1, 0, len(idx) - 1)]
    nearest = np.where(np.abs(before - at) <= np.abs(nearest - at), before, nearest)
    near = np.abs(nearest - at) <= frames
    return np.where(near[:, None, None], body[nearest], body), near


def _crop_box(xy: np.ndarray, width: int, height: int) -> tuple[int, int, int, int] | None:
    """The square (x0, y0, x1, y1) around pixels ``xy`` (N, 2) with :data:`CROP_MARGIN`, cut
    to the image; None when it leaves fewer than 32 pixels a side."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    side = (1.0 + 2.0 * CROP_MARGIN) * float((hi - lo).max())
    mid = 0.5 * (lo + hi)
    x0, y0 = (int(max(0.0, c - side / 2)) for c in mid)
    x1, y1 = int(min(width, mid[0] + side / 2)), int(min(height, mid[1] + side / 2))
    if x1 - x0 < 32 or y1 - y0 < 32:
        return None
    return x0, y0, x1, y1


def _nanmean_points(points: np.ndarray) -> np.ndarray:
    """(F, 3) mean of each frame's finite points (F, P, 3); NaN where none is."""
    ok = np.isfinite(points).all(axis=-1)
    total = np.where(ok[..., None], points, 0.0).sum(axis=1)
    count = ok.sum(axis=1)[:, None]
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per row of ``values`` (F, P) (NaN: not counted), the weighted median; NaN for a row
    with nothing counted."""
    w = np.where(np.isfinite(values), weights, 0.0)
    order = np.argsort(np.where(w > 0, values, np.inf), axis=1)
    v = np.take_along_axis(values, order, axis=1)
    cw = np.cumsum(np.take_along_axis(w, order, axis=1), axis=1)
    total = cw[:, -1:]
    at = np.argmax(cw >= 0.5 * total, axis=1)
    out = v[np.arange(len(v)), at]
    return np.where(total[:, 0] > 0, out, np.nan)


def someone_else_count(found: ViewLandmarks, kept: ViewLandmarks) -> int:
    """(view, frame) pairs in which MediaPipe ``found`` someone but :func:`one_person` (in
    ``kept``) left the view out: someone else than the person tracked."""
    return int(((found.visibility.max(axis=2) > 0) & (kept.visibility.max(axis=2) <= 0)).sum())


#: A view of whose landmarks the triangulation kept less than this share, where it kept at
#: least :data:`AGREEING_VIEWS` of another view's, is named (:func:`lone_views`). On the real
#: 4-view video every view gives 87-99 % (30 or 100 frames); with two videos swapped those
#: two give 3-31 % and the others 70-82 % (30 frames), 1-2 % and 97 % (100).
LONE_VIEW = 0.5
AGREEING_VIEWS = 0.7


def lone_views(found: ViewLandmarks, tri: Triangulated) -> list[str]:
    """One note per camera whose person the other views do not see where it does: MediaPipe
    ``found`` the person's landmarks in its frames, but the triangulation (``tri``) kept few
    of them. A video given for the wrong camera (a calibration names its cameras by serial
    number, and ``video cameras`` takes the videos in its order) or a camera calibrated
    wrong looks so: on the real video with two videos swapped, the only word had been that
    186 camera frames showed "no one or someone else". Of three views or fewer, the two
    that agree may be the wrong ones (two cameras each given the next camera's video agree
    with one another, and the one right camera was blamed): the note then says which view
    disagrees, not which is wrong."""
    seen = found.visibility >= MIN_VISIBILITY  # (V, F, 33)
    # a landmark counts where another view saw it too: one no other camera sees (the person
    # out of their fields) can never be triangulated, and says nothing of this camera
    shared = seen & (seen.sum(axis=0) > seen)  # another view saw it as well
    kept = tri.used & shared
    share = kept.sum(axis=(1, 2)) / np.maximum(shared.sum(axis=(1, 2)), 1)
    notes = []
    for v, cam in enumerate(found.cameras):
        others = np.delete(share, v)
        if shared[v].sum() < 100 or not len(others) or others.max() < AGREEING_VIEWS:
            continue
        if share[v] < LONE_VIEW and len(found.cameras) <= 3:
            video = f" ({Path(cam.video).name})" if cam.video else ""
            notes.append(
                f"note: {cam.name} disagrees with the other views (they agreed with "
                f"{share[v]:.0%} of the person's landmarks MediaPipe saw in it, with up to "
                f"{others.max():.0%} of another view's): either its video{video} or theirs is "
                "not the camera's, or a calibration is wrong (`video cameras` takes the videos "
                "in the calibration's camera order)"
            )
        elif share[v] < LONE_VIEW:
            video = Path(cam.video).name or "its video"
            notes.append(
                f"note: {cam.name}: the other views agreed with {share[v]:.0%} of the person's "
                f"landmarks MediaPipe saw in it (with up to {others.max():.0%} of another "
                f"view's): is {video} this camera's video, and its calibration right? "
                "(`video cameras` takes the videos in the calibration's camera order)"
            )
    return notes


def _person_path(cost: np.ndarray, centres: np.ndarray, step: float, switch: float) -> np.ndarray:
    """(F,) the candidates (columns of ``cost`` (F, C); the last is "no one") of least total
    cost, each frame's change of candidate costing the distance between their ``centres``
    (F, C, 3) over ``step`` (mm per frame). "No one" holds the centre of the person it was
    entered from (the person is lost, not gone: coming back elsewhere costs the distance from
    where they were lost); before anyone was seen, leaving it costs ``switch``."""
    f_n, c_n = cost.shape
    total = cost[0].copy()
    back = np.zeros((f_n, c_n), dtype=int)
    held = np.full(3, np.nan)  # where "no one"'s best path lost its person
    for t in range(1, f_n):
        before = centres[t - 1].copy()
        before[-1] = held
        move = np.linalg.norm(before[:, None] - centres[t][None], axis=-1) / step
        move[:, -1] = 0.0  # losing the person costs the frames without them
        move[-1, :-1] = np.where(np.isfinite(held).all(), move[-1, :-1], switch)
        move[-1, -1] = 0.0
        move = np.where(np.isfinite(move), move, np.inf)
        through = total[:, None] + move  # (from, to)
        back[t] = np.argmin(through, axis=0)
        total = through[back[t], np.arange(c_n)] + cost[t]
        if back[t, -1] != c_n - 1:
            held = centres[t - 1, back[t, -1]]
    path = np.zeros(f_n, dtype=int)
    path[-1] = int(np.argmin(total))
    for t in range(f_n - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


def consistent_views(views: ViewLandmarks, left_right: str = "views") -> ViewLandmarks:
    """Every view's MediaPipe landmarks with left and right made consistent (:data:`LEFT_RIGHT`):
    ``views`` across the views (:func:`views_sides`); ``continuity`` each view over time
    (:func:`~markovmotion.video.left_right.consistent_sides`, the monocular path's, which needs
    the world points); ``both`` the one then the other; ``mediapipe`` its own labels. One view
    has nothing to agree with: ``views`` leaves it as it is. The views of someone else are left
    out before (:func:`look_again`)."""
    from markovmotion.video.left_right import consistent_sides

    check_left_right(left_right)
    if left_right in ("continuity", "both"):
        if views.world is None:
            raise ValueError("left_right continuity needs MediaPipe's world points")
        got = [
            consistent_sides(p, wo, vi)
            for p, wo, vi in zip(views.pixels, views.world, views.visibility, strict=True)
        ]
        views = ViewLandmarks(
            views.cameras, *(np.stack([g[k] for g in got]) for k in (0, 2)), views.seconds,
            np.stack([g[1] for g in got]),
        )  # fmt: skip
    if left_right in ("views", "both") and len(views.cameras) > 1:
        views = views_sides(views)[0]
    return views


@dataclass
class PersonViews:
    """MediaPipe in every camera, narrowed to one person (:func:`person_views`)."""

    #: MediaPipe's landmarks, with the views looked at again on crops (:func:`look_again`).
    found: ViewLandmarks
    #: Those of the person followed, left and right made consistent (:func:`consistent_views`).
    agreed: ViewLandmarks
    #: Where the person named with ``--person`` was looked for (None: where the cameras aim).
    aim: Aim | None
    #: (view, frame) pairs of someone else, left out (:func:`someone_else_count`).
    someone_else: int
    #: One line when a camera's video ended before the others'.
    notes: list[str]


def person_views(
    videos: Sequence[str | os.PathLike[str]],
    cameras: Sequence[CalibratedCamera],
    fps: float,
    max_frames: int | None = None,
    person: str | None = None,
    left_right: str = "views",
) -> PersonViews:
    """MediaPipe over every camera's video, narrowed to one person (the one at the pixel
    ``person`` names, :func:`person_ray`, else the one the views agree on near where the
    cameras aim: :func:`look_again`), left and right made consistent: what
    ``--method triangulate`` and the particle filter's guide both start from."""
    aim = person_ray(cameras, person, fps) if person is not None else None  # before MediaPipe
    detected = ViewLandmarks.from_videos(videos, cameras, max_frames)
    found, kept = look_again(detected, videos, fps, aim=aim)
    return PersonViews(
        found,
        consistent_views(kept, left_right),
        aim,
        someone_else_count(found, kept),
        detected.notes,
    )


def check_left_right(left_right: str) -> None:
    """Raise ValueError (one line) unless ``left_right`` is one of :data:`LEFT_RIGHT`."""
    if left_right not in LEFT_RIGHT:
        raise ValueError(f"left_right must be one of {', '.join(LEFT_RIGHT)}, got {left_right!r}")


@dataclass
class Triangulated:
    """Landmarks (F, 33, 3) mm triangulated from :class:`ViewLandmarks`, the views kept
    (V, F, 33), the largest reprojection error (F, 33) px, and the body points (F, 19, 3)."""

    landmarks: np.ndarray
    used: np.ndarray
    residual: np.ndarray
    points: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.points = landmarks_to_body_points(self.landmarks)

    def despiked(self, fps: float) -> tuple[Triangulated, int]:
        """These landmarks with their glitches (a landmark that leaves its path for a frame or
        two) replaced by their path's median (:func:`~markovmotion.features.smoothing.despike`),
        the views that gave a glitch no longer counted as used; and how many were replaced."""
        from markovmotion.features.smoothing import despike

        landmarks, spiked = despike(self.landmarks, fps)
        used = self.used & ~spiked[None]
        return replace(self, landmarks=landmarks, used=used), int(spiked.sum())

    def filled(self, views: ViewLandmarks) -> tuple[Triangulated, int]:
        """These landmarks where fewer than two views saw them with visibility at least
        ``MIN_VISIBILITY`` filled from every view that found the person, weighted by its
        visibility however low (:func:`triangulate_points`, robust as ever); and how many
        were filled. A landmark MediaPipe is unsure of in all but one view (a hand seen
        edge-on) is nearer the person so than missing: on 11 rendered kinds of motion the
        triangulation then places every limb joint in every frame (72-100 % before, salsa's
        wrists never) at about the error of the rest (docs/video.md)."""
        missing = ~np.isfinite(self.landmarks).all(axis=-1)
        if not missing.any():
            return self, 0
        # only the missing ones are triangulated again (each point is triangulated alone)
        pts, used_low, worst = triangulate_points(
            views.cameras, views.pixels[:, missing], views.visibility[:, missing]
        )
        got = np.isfinite(pts).all(axis=-1)
        fill = np.zeros_like(missing)
        fill[missing] = got
        landmarks, used, residual = self.landmarks.copy(), self.used.copy(), self.residual.copy()
        landmarks[fill] = pts[got]
        used[:, fill] = used_low[:, got]
        residual[fill] = worst[got]
        return replace(self, landmarks=landmarks, used=used, residual=residual), int(fill.sum())

    def smoothed(self, seconds: float, fps: float) -> Triangulated:
        """These landmarks smoothed over time by a Gaussian of ``seconds``
        (:func:`~markovmotion.features.smoothing.smooth_gaps`; 0: unchanged)."""
        from markovmotion.features.smoothing import smooth_gaps

        return replace(self, landmarks=smooth_gaps(self.landmarks, seconds * fps))


def triangulate_views(views: ViewLandmarks, min_visibility: float = MIN_VISIBILITY) -> Triangulated:
    """Every frame's landmarks triangulated from the views that see them
    (:func:`triangulate_points`, weighted by visibility)."""
    v_n, f_n, l_n = views.visibility.shape
    w = np.where(views.visibility >= min_visibility, views.visibility, 0.0)
    pts, used, worst = triangulate_points(
        views.cameras, views.pixels.reshape(v_n, f_n * l_n, 2), w.reshape(v_n, f_n * l_n)
    )
    return Triangulated(
        pts.reshape(f_n, l_n, 3), used.reshape(v_n, f_n, l_n), worst.reshape(f_n, l_n)
    )


#: The widths (s, the Gaussian's sigma) :func:`choose_smoothing` tries: none to 0.1 s.
SMOOTHING_S: tuple[float, ...] = (0.0, 1 / 120, 1 / 60, 1 / 40, 1 / 30, 1 / 20, 1 / 15, 1 / 10)
#: The width with two cameras, where no view can be left out to choose one (or a clip too
#: short to choose on): what :func:`choose_smoothing` chose on the real 4-view video (60 fps;
#: docs/video.md).
SMOOTHING_TWO_VIEWS_S = 1 / 30


@dataclass
class SmoothingChoice:
    """The smoothing's width (s, the Gaussian's sigma), how it was set (``chosen_by``), and,
    chosen by :func:`choose_smoothing`, each width's mean reprojection error (px) in the
    cameras left out."""

    seconds: float
    errors_px: dict[float, float]
    chosen_by: str = "left-out cameras"

    def summary(self) -> dict:
        """JSON-ready: ``smoothing_s``, ``smoothing_chosen_by`` and
        ``smoothing_left_out_px`` (``"sigma 33.3 ms"``: the left-out cameras' error)."""
        return {
            "smoothing_s": round(self.seconds, 4),
            "smoothing_chosen_by": self.chosen_by,
            "smoothing_left_out_px": {
                f"sigma {1000 * w:.1f} ms": round(e, 3) for w, e in self.errors_px.items()
            },
        }


def choose_smoothing(
    views: ViewLandmarks, fps: float, widths: Sequence[float] = SMOOTHING_S
) -> SmoothingChoice:
    """How much to smooth the triangulated landmarks over time, chosen on the video itself by
    leaving one view out: each camera's landmarks are triangulated from the other cameras
    (robustly, glitches out: :meth:`Triangulated.despiked`), smoothed by each width
    (:meth:`Triangulated.smoothed`), projected into the camera left out and compared with its
    own MediaPipe landmarks (visibility at least ``MIN_VISIBILITY``; each error capped at the
    triangulation's outlier distance, :data:`OUTLIER_ANGLE` focal lengths, so a landmark that
    view put on the other arm counts as an outlier, not as a score). The left-out view's own
    detection noise is independent of the others', so the width with the least error is the
    one whose triangulation lies nearest the person in that view: cross-validation, no
    reference. Smoothing trades MediaPipe's frame-to-frame jitter against lag at fast
    motion; the best width depends on the frame rate, the image size and the motion. With
    fewer than 3 cameras, or a clip shorter than four of the widest sigmas,
    :data:`SMOOTHING_TWO_VIEWS_S`."""
    v_n, f_n = len(views.cameras), views.visibility.shape[1]
    widths = sorted({float(w) for w in widths})
    if v_n < 3:
        return SmoothingChoice(SMOOTHING_TWO_VIEWS_S, {}, "fixed: fewer than 3 cameras")
    if f_n < 4 * max(widths) * fps + 1:  # too short to tell the widest sigma from the others
        return SmoothingChoice(SMOOTHING_TWO_VIEWS_S, {}, "fixed: too few frames to choose")
    tau = np.sqrt(_tau2(views.cameras, OUTLIER_ANGLE))[:, 0]
    total = np.zeros(len(widths))
    count = 0
    for v in range(v_n):
        rest = [i for i in range(v_n) if i != v]
        others = ViewLandmarks(
            [views.cameras[i] for i in rest], views.pixels[rest], views.visibility[rest]
        )
        tri = triangulate_views(others).despiked(fps)[0]
        for k, width in enumerate(widths):
            points = tri.smoothed(width, fps).landmarks
            seen = (views.visibility[v] >= MIN_VISIBILITY) & np.isfinite(points).all(-1)
            if k == 0:
                count += int(seen.sum())
            px = views.cameras[v].project(np.nan_to_num(points[seen]))[0]
            total[k] += np.minimum(
                np.linalg.norm(px - views.pixels[v][seen], axis=-1), tau[v]
            ).sum()
    if count == 0:
        return SmoothingChoice(SMOOTHING_TWO_VIEWS_S, {}, "fixed: no landmark to compare")
    errors = total / count
    return SmoothingChoice(
        widths[int(np.argmin(errors))], dict(zip(widths, errors.tolist(), strict=True))
    )


#: The body points the guide compares (each one MediaPipe landmark).
GUIDE_POINTS: tuple[str, ...] = REFERENCE_JOINTS


@dataclass
class Guide:
    """The particle filter's MediaPipe term (module docstring, 2): 2-D targets ``pixels``
    (V, F, J, 2) of the :data:`GUIDE_POINTS` in each camera, with ``weights`` (V, F, J) (0:
    not seen, or rejected by triangulation)."""

    cameras: list[CalibratedCamera]
    pixels: np.ndarray
    weights: np.ndarray
    angle: float = GUIDE_ANGLE
    seconds: float = 0.0
    #: The triangulated body points (F, 19, 3) mm, NaN where unknown: the poses the filter
    #: is restarted from (:meth:`pose`); None: the 2-D term only.
    points: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.index = np.array([BODY_POINTS.index(p) for p in GUIDE_POINTS])
        self.sigma2 = np.array([(self.angle * c.focal) ** 2 for c in self.cameras])

    @classmethod
    def from_views(cls, views: ViewLandmarks, tri: Triangulated | None = None) -> Guide:
        """The guide of MediaPipe's landmarks in every view; with ``tri``, only the views its
        triangulation kept (a landmark MediaPipe put elsewhere in one view does not pull)."""
        lm = [LANDMARKS.index(p) for p in GUIDE_POINTS]
        w = np.where(views.visibility >= MIN_VISIBILITY, views.visibility, 0.0)[..., lm]
        if tri is not None:
            w = np.where(tri.used[..., lm], w, 0.0)
        pts = None if tri is None else tri.points
        return cls(views.cameras, views.pixels[:, :, lm], w, seconds=views.seconds, points=pts)

    @property
    def frames(self) -> int:
        return self.pixels.shape[1]

    def cost(self, joints: np.ndarray, frame: int) -> np.ndarray | None:
        """(M,) cost in [0, 1] of body points (M, 19, 3) in ``frame``: the visibility-weighted
        mean over views and guide points of ``d^2 / (d^2 + sigma^2)``; None when MediaPipe
        gave no landmark for that frame (the filter then goes by the images alone)."""
        if not 0 <= frame < self.frames:
            return None
        w = self.weights[:, frame]  # (V, J)
        total = w.sum()
        if total <= 0:
            return None
        out = np.zeros(len(joints))
        pts = joints[:, self.index]
        for v, cam in enumerate(self.cameras):
            if not w[v].any():
                continue
            p, _ = cam.project(pts)  # (M, J, 2)
            d2 = ((p - self.pixels[v, frame]) ** 2).sum(axis=-1)
            out += (np.nan_to_num(d2 / (d2 + self.sigma2[v]), nan=1.0) * w[v]).sum(axis=1)
        return out / total

    def pose(self, body: BodyModel, frame: int, start: np.ndarray) -> np.ndarray | None:
        """The body model's state (D,) nearest the triangulated guide points of ``frame``
        (:func:`fit_state` from ``start``), or None when fewer than 6 of them are known."""
        if self.points is None or not 0 <= frame < self.frames:
            return None
        return fit_state(body, self.points[frame], start)


def fit_state(
    body: BodyModel, target: np.ndarray, start: np.ndarray, scale: float = FIT_SCALE
) -> np.ndarray | None:
    """The state (D,) within the body model's limits whose :data:`GUIDE_POINTS` lie nearest
    the body points ``target`` (19, 3) mm (NaN: unknown), by robust least squares (soft L1,
    ``scale`` mm) from ``start`` (D,); None when fewer than 6 of them are known."""
    from scipy.optimize import least_squares

    idx = np.array([BODY_POINTS.index(p) for p in GUIDE_POINTS])
    goal = target[idx]
    known = np.isfinite(goal).all(axis=1)
    if known.sum() < 6:
        return None
    lo, hi = body.lower, body.upper
    inside = 1e-6 * np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    x0 = np.clip(start, lo + inside, hi - inside)  # least_squares starts strictly inside
    step = np.where(np.arange(len(x0)) < 3, 1.0, 1e-3)

    def residual(x: np.ndarray) -> np.ndarray:
        return (body.joint_positions(x)[0, idx][known] - goal[known]).ravel()

    def jacobian(x: np.ndarray) -> np.ndarray:  # forward differences, all at once
        xs = x + np.vstack([np.zeros(len(x)), np.diag(step)])
        r = (body.joint_positions(xs)[:, idx][:, known] - goal[known]).reshape(len(xs), -1)
        return ((r[1:] - r[0]) / step[:, None]).T

    fit = least_squares(
        residual, x0, jac=jacobian, bounds=(lo, hi), loss="soft_l1", f_scale=scale, max_nfev=30
    )
    return fit.x


@dataclass
class TriangulatedTrack:
    """Body points (F, 19, 3) mm (NaN where fewer than 2 views saw them), confidence (F,)
    (mean visibility over views and landmarks), frame rate and timing."""

    points: np.ndarray
    confidence: np.ndarray
    fps: float
    seconds: float
    triangulated: Triangulated = field(repr=False)

    @property
    def placed(self) -> np.ndarray:
        return np.isfinite(self.points).all(axis=(1, 2))


def track_triangulated_video(
    video: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
    max_frames: int | None = None,
    reference: str | os.PathLike[str] | None = None,
    views: int | None = None,
    left_right: str = "views",
    person: str | None = None,
    smooth: float | None = None,
) -> tuple[TriangulatedTrack, dict]:
    """Track a multi-view video (a folder with ``cameras.json``, or that file) by MediaPipe in
    every view, triangulated (module docstring, 1); the track and a JSON-ready summary (with
    ``reference``, its errors); ``left_right`` (:data:`LEFT_RIGHT`): how MediaPipe's left and
    right are made consistent across the views first (:func:`consistent_views`); ``person``
    (``CAMERA:U,V``, :func:`person_ray`): of several people, follow the one at that pixel
    (the summary's ``from_person_m``: how far the person followed stood from its ray);
    ``smooth``: the landmarks' smoothing over time (s, a Gaussian's sigma; None: chosen by
    leaving one view out, :func:`choose_smoothing`)."""
    from markovmotion.video.cameras import camera_file, camera_videos, load_cameras

    check_left_right(left_right)  # before MediaPipe's minutes
    t0 = time.perf_counter()
    where = camera_file(video, cameras)
    file_notes: list[str] = []
    cams, doc = load_cameras(where, file_notes)
    if lone_video(video):
        raise MotionFormatError(video, "--method triangulate needs the folder of every camera")
    videos = camera_videos(where, cams)
    if views is not None:
        cams, videos = cams[:views], videos[:views]
    if len(cams) < 2:
        raise MotionFormatError(where, "--method triangulate needs at least 2 cameras")
    fps = float(doc["fps"])
    one = person_views(videos, cams, fps, max_frames, person, left_right)
    lm = one.agreed
    tri, filled = triangulate_views(lm).filled(lm)
    tri, spikes = tri.despiked(fps)
    chosen = (
        choose_smoothing(lm, fps) if smooth is None else SmoothingChoice(smooth, {}, "--smooth")
    )
    tri = tri.smoothed(chosen.seconds, fps)
    seconds = time.perf_counter() - t0
    conf = lm.visibility.mean(axis=(0, 2))
    tr = TriangulatedTrack(tri.points, conf, float(doc["fps"]), seconds, tri)
    if not np.isfinite(tr.points).all(axis=2).any():  # as --method monocular says
        raise MotionFormatError(where, "no person found in this video (no frame placed)")
    n = len(tr.points)
    seen = lm.visibility >= MIN_VISIBILITY
    summary = {
        "method": "triangulate",
        "views": len(cams),
        "frames": n,
        "frames_placed": int(tr.placed.sum()),
        "fps": round(n / max(seconds, 1e-9), 2),
        "video_fps": tr.fps,
        "views_of_someone_else": one.someone_else,
        **whom(tr.points, cams, one.aim),
        "landmark_views_dropped": dropped_views(seen, tri),
        "landmarks_despiked": spikes,
        "landmarks_filled_low_visibility": filled,
        **chosen.summary(),
        "landmarks_seen": int(seen.sum()),
        "median_residual_px": round(float(np.nanmedian(tri.residual)), 2),
        "left_right": left_right,
        "notes": [*file_notes, *one.notes, *lone_views(one.found, tri)],
        "confidence": [round(float(c), 3) for c in conf],
    }
    if reference is not None:
        errors, said = reference_report(tr.points, reference, tr.fps, cams[0].skip, max_frames)
        # flat, as before, and under "reference" as the particle filter's summary has them
        summary.update(errors, reference=errors)
        summary["notes"] += [said] if said else []
    return tr, summary


def two_views_have(lengths: Sequence[int]) -> int:
    """The frames at least two of the views' videos have (of ``lengths``, one per view; one
    view: its own): the frames a point can be triangulated in."""
    return sorted(lengths)[-2] if len(lengths) > 1 else lengths[0]


def dropped_views(seen: np.ndarray, tri: Triangulated) -> int:
    """How many views saw a landmark surely (``seen``: visibility at least ``MIN_VISIBILITY``,
    (V, F, 33)) and were not used for it: left out by the robust triangulation, or as a
    glitch. Counted as the views seen less those used, it went negative (-58, -203 in a new
    user's trial): :meth:`Triangulated.filled` uses views seen unsurely too."""
    return int((seen & ~tri.used).sum())


def whom(points: np.ndarray, cameras: Sequence[CalibratedCamera], aim: Aim | None) -> dict:
    """Whom a track followed, for the summaries: the median distance (m) of its body points'
    centre (``points`` (F, P, 3)) from where the ``cameras`` are aimed,
    ``from_capture_centre_m``, and with a person named (``aim``, :func:`person_ray`) from its
    ray over the first frames, where the person was named, ``from_person_m``."""
    centre = _nanmean_points(points)
    middle = capture_centre(cameras)
    out = {
        "from_capture_centre_m": (
            _median_m(np.linalg.norm(centre - middle, axis=1)) if middle is not None else None
        )
    }
    if aim is not None:
        out["from_person_m"] = _median_m(aim.distance(centre[: aim.frames]))
    return out


#: Metres from where the cameras are aimed beyond which :func:`whom_notes` says whom a
#: track followed.
FAR_FROM_CENTRE_M = 1.0
#: A person named (``--person``) whose centre stood further than this (m) from the ray
#: through the pixel named is not the one named (a ray through a body passes within its
#: width).
FAR_FROM_RAY_M = 0.5


def whom_notes(summary: dict, named: bool = False) -> list[str]:
    """The lines that say whom MediaPipe followed, when it may not be the one meant, from a
    summary with :func:`whom`'s keys and ``views_of_someone_else``: views of someone else
    left out, a person followed far from where the cameras are aimed, or (``named``: a
    person named with a pixel) far from that pixel's ray."""
    lines = []
    if count := summary.get("views_of_someone_else", 0):
        lines.append(
            f"note: {count} camera frames showed no one or someone else than the person "
            "tracked (MediaPipe finds one person per image); they were left out"
        )
    if named:
        away = summary.get("from_person_m")
        if away is not None and away > FAR_FROM_RAY_M:
            lines.append(
                f"note: the person tracked stands {away:.1f} m from the ray of --person: "
                "no camera's MediaPipe found anyone nearer (it finds one person per image)"
            )
        return lines
    away = summary.get("from_capture_centre_m")
    if away is not None and away > FAR_FROM_CENTRE_M:
        lines.append(
            f"note: the person tracked stands {away:.1f} m from where the cameras are "
            "aimed; MediaPipe finds one person per image, so with several people in view "
            "the one the views agree on is followed"
        )
    return lines


def _median_m(distances: np.ndarray) -> float | None:
    """The median of distances (mm) in metres, to the centimetre; None when none is finite."""
    d = np.asarray(distances, dtype=float)
    return round(float(np.nanmedian(d)) / 1e3, 2) if np.isfinite(d).any() else None

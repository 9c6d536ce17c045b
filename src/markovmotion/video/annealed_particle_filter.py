"""Annealed particle filtering of a person's 3-D articulated motion in multi-view video.

The procedure of Deutscher, Blake and Reid, "Articulated body motion capture
by annealed particle filtering" (CVPR 2000), used by the dual-HMM paper (§3)
to track person A before the partner is generated:

1. **Body model** (:mod:`markovmotion.video.body_model`): a kinematic tree
   with ~28 degrees of freedom, joint limits from motion capture, flesh of
   tapered capsules.
2. **Image features**, per frame and camera: a foreground map (difference to
   a background estimated as the per-pixel median of frames spread over the
   video) and an edge map (the smoothed gradient of the foreground).
3. **Weighting function** ``w(x) = exp(-beta E(x))`` with ``E`` the mean over
   cameras of three costs of the projected model: points sampled inside each
   capsule that fall on background (silhouette), foreground pixels that no
   capsule covers (coverage), and points on the capsules' outlines that fall
   on no edge (edge). All particles are projected and scored at once
   (:func:`_costs`, compiled by Numba).
4. **Annealing** per frame over ``layers`` layers (10): weight the particles
   with ``beta_m`` chosen so that the survival rate -- the effective number of
   particles over their number -- is ``survival`` (0.5); resample; diffuse
   with Gaussian noise whose scale shrinks by ``sqrt(survival)`` per layer;
   the last layer's weighted mean is the pose.
5. **Initialisation** on the first frame by a coarse search from the standing
   pose: the root placed where the cameras' foreground centroids meet,
   heading and joints spread widely, annealed over twice as many layers.
   The same search is the **recovery** when the weights collapse (the best
   particle's cost above ``recover_cost``).
6. **Sides** (our addition; optional, ``sides``): silhouettes cannot tell a body
   from the same body turned round with its limbs mirrored, so a pose that
   MediaPipe's left and right (:mod:`markovmotion.video.sides`) find turned
   front to back is searched again from the pose turned round, or, if that
   fails, has its cost raised by ``flip_cost`` (its confidence lowered).
7. **Guide** (our addition; optional, ``guide``): MediaPipe's 2-D landmarks in every view
   (:class:`~markovmotion.video.triangulation.Guide`) add a term ``G(x)`` in [0, 1] for the
   distance of the particle's projected limb joints to them; the weighting function is then
   ``w = exp(-beta (E + g G) / (1 + g))`` with ``g`` = ``guide_weight``, so costs, recovery
   and confidence stay on the same [0, 1] scale (a frame without landmarks: ``E`` alone).
   Each frame a share ``restart`` of the particles starts again from the body model fitted
   to the triangulated points (:func:`~markovmotion.video.triangulation.fit_state`).

Without annealing (``layers=1``) this is a plain particle filter
(SIR/CONDENSATION), the comparison of ``benchmarks/tracker_bench.py``.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numba
import numpy as np
from threadpoolctl import threadpool_limits

from markovmotion.errors import MotionFormatError
from markovmotion.progress import track
from markovmotion.video.background import BackgroundCheck, background_note
from markovmotion.video.body_model import BODY_SHAPE, BodyModel
from markovmotion.video.cameras import (
    CalibratedCamera,
    camera_file,
    camera_of_video,
    camera_videos,
    load_cameras,
    lone_video,
)
from markovmotion.video.monocular import mediapipe_installed
from markovmotion.video.render import (
    expected_frames,
    header_shortfall,
    read_frames,
    shortest_note,
)

if TYPE_CHECKING:
    from markovmotion.video.sides import SideCheck
    from markovmotion.video.triangulation import Guide

#: Foreground threshold on the largest channel difference to the background (grey levels).
FG_LOW, FG_HIGH = 30.0, 60.0
#: A frame whose foreground covers less than this share of every view holds no one: its
#: pose is a guess (confidence 0), and a video of such frames alone has no person. A person
#: covers 3-10 % of the real 272x480 views.
EMPTY_COVER = 0.002
#: Foreground pixels sampled per view for the coverage cost.
COVER_SAMPLES = 80
EDGE_WEIGHT = 0.5
#: Sobel response of an image edge counted as certain (a 30-grey-level step at sigma 1).
EDGE_CONTRAST = 100.0
BACKGROUND_FRAMES = 31
#: Height (mm) of a standing person, for the first guess of depth from one view.
STATURE = 1700.0


# ----------------------------------------------------------------------------- image features
def estimate_background(
    video: str | os.PathLike[str],
    frames: int = BACKGROUND_FRAMES,
    camera: CalibratedCamera | None = None,
) -> np.ndarray:
    """(H, W, 3) uint8 per-pixel median of up to ``frames`` frames spread over the video
    (``camera``'s: undistorted, :func:`~markovmotion.video.render.read_frames`)."""
    from markovmotion.video.render import spread_frames

    return np.median(np.stack(spread_frames(video, frames, camera)), axis=0).astype(np.uint8)


def read_image(path: Path, camera: CalibratedCamera) -> np.ndarray:
    """An RGB image (H, W, 3) uint8 of ``camera``'s size (W, H), undistorted as its frames."""
    size = (camera.width, camera.height)
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise MotionFormatError(path, "not an image")
    if (img.shape[1], img.shape[0]) != tuple(size):
        raise MotionFormatError(
            path, f"background is {img.shape[1]}x{img.shape[0]}, camera {size[0]}x{size[1]}"
        )
    rgb = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    fix = camera.undistorter()
    return rgb if fix is None else fix(rgb)


def _sobel(smooth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The x and y Sobel responses (float32) of a smoothed image."""
    return (
        cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3),
        cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3),
    )


@numba.njit(cache=True)
def _hypot32(x, y):  # pragma: no cover - compiled
    """``np.hypot`` of two float32 values, to the bit: in float64 (exact squares), rounded."""
    a = np.float64(x)
    b = np.float64(y)
    return np.float32(math.sqrt(a * a + b * b))


@numba.njit(cache=True)
def _edge_map(ox, oy, outline_scale, ix, iy, inner_scale, smooth, near):  # pragma: no cover
    """max(outline, inner) (H, W) float32: each the gradient magnitude (float32 ``np.hypot``
    of the Sobel responses) over its scale, clipped to [0, 1]; the inner edges only where the
    smoothed foreground exceeds ``near``."""
    h, w = ox.shape
    out = np.empty((h, w), np.float32)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for y in range(h):
        for x in range(w):
            a = min(max(_hypot32(ox[y, x], oy[y, x]) / outline_scale, zero), one)
            b = min(max(_hypot32(ix[y, x], iy[y, x]) / inner_scale, zero), one)
            out[y, x] = max(a, b) if smooth[y, x] > near else a
    return out


@dataclass
class ViewFeatures:
    """Foreground (V, H, W), edges (V, H, W) and sampled foreground pixels (V, K, 2) of one frame
    (the first ``n_samples`` of each view, whole pixels, kept sorted by row for the coverage
    cost, also as ``sample_x`` and ``sample_y`` (V, K); ``rows`` (V, H + 1) counts each view's
    samples above every row)."""

    fg: np.ndarray
    edge: np.ndarray
    samples: np.ndarray
    n_samples: np.ndarray
    centroids: list[np.ndarray | None] = field(default_factory=list)
    heights: list[float] = field(default_factory=list)
    #: (V,) the share of each view's pixels in the foreground (None: not measured).
    coverage: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.samples = np.array(self.samples, dtype=float)
        if not np.array_equal(self.samples, np.round(self.samples)):
            raise ValueError("foreground samples must be whole pixels")
        self.rows = np.zeros((len(self.samples), self.fg.shape[1] + 1), np.intp)
        for v, n in enumerate(self.n_samples):
            pts = self.samples[v, :n]
            self.samples[v, :n] = pts[np.lexsort((pts[:, 0], pts[:, 1]))]
            self.rows[v] = np.searchsorted(self.samples[v, :n, 1], np.arange(self.fg.shape[1] + 1))
        self.sample_x = np.ascontiguousarray(self.samples[..., 0])
        self.sample_y = np.ascontiguousarray(self.samples[..., 1])


def view_features(
    frames: Sequence[np.ndarray], backgrounds: Sequence[np.ndarray], seed: int = 0
) -> ViewFeatures:
    """Foreground and edge maps of one frame per camera (RGB uint8, same size per camera)."""
    rng = np.random.default_rng(seed)
    h = max(f.shape[0] for f in frames)
    w = max(f.shape[1] for f in frames)
    v = len(frames)
    fg = np.zeros((v, h, w), np.float32)
    edge = np.zeros((v, h, w), np.float32)
    samples = np.zeros((v, COVER_SAMPLES, 2))
    n_samples = np.zeros(v, np.intp)
    centroids, heights = [], []
    coverage = np.zeros(v)
    for k, (frame, bg) in enumerate(zip(frames, backgrounds, strict=True)):
        channels = cv2.split(cv2.absdiff(frame, bg))  # the largest channel difference
        diff = channels[0]
        for c in channels[1:]:
            diff = cv2.max(diff, c)
        diff = cv2.GaussianBlur(diff.astype(np.float32), (0, 0), 1.0)
        f = np.clip((diff - FG_LOW) / (FG_HIGH - FG_LOW), 0, 1)
        f = cv2.morphologyEx(f, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        smooth = cv2.GaussianBlur(f, (0, 0), 2.0)
        grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY).astype(np.float32)
        both = _edge_map(
            *_sobel(smooth),
            np.float32(8 * 0.15),  # the outline: Sobel gain 8; sigma-2 step 0.2
            *_sobel(cv2.GaussianBlur(grey, (0, 0), 1.0)),
            np.float32(EDGE_CONTRAST),  # inner edges near the foreground
            smooth,
            np.float32(0.05),
        )
        fh, fw = f.shape
        fg[k, :fh, :fw] = f
        edge[k, :fh, :fw] = cv2.GaussianBlur(both, (0, 0), 1.0)
        found = cv2.findNonZero((f > 0.5).view(np.uint8))  # x, y in row order (np.nonzero's)
        if found is not None:
            found = found.reshape(-1, 2)
            coverage[k] = len(found) / (fh * fw)
            xs, ys = found[:, 0], found[:, 1]
            pick = rng.choice(len(xs), min(COVER_SAMPLES, len(xs)), replace=False)
            samples[k, : len(pick)] = found[pick]
            n_samples[k] = len(pick)
            centroids.append(np.array([xs.mean(), ys.mean()]))
            heights.append(float(ys.max() - ys.min() + 1))
        else:
            centroids.append(None)
            heights.append(0.0)
    return ViewFeatures(fg, edge, samples, n_samples, centroids, heights, coverage)


# ----------------------------------------------------------------------------- the weighting function
#: The body's primitives: point indices (S, 2) and radii in mm (S, 2), made once.
_SEGMENTS = BODY_SHAPE.segments()
_T_CAPSULE = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
_ACROSS = np.array([-0.6, 0.0, 0.6])
_BALL_COS = np.cos(np.pi / 4 + np.arange(4) * np.pi / 2)
_BALL_SIN = np.sin(np.pi / 4 + np.arange(4) * np.pi / 2)


@numba.njit(cache=True)
def _lookup(img, v, x, y):  # pragma: no cover - compiled
    xi = int(x + 0.5)
    yi = int(y + 0.5)
    if xi < 0 or yi < 0 or yi >= img.shape[1] or xi >= img.shape[2]:
        return 0.0
    return img[v, yi, xi]


@numba.njit(cache=True, fastmath=True)
def _costs(pix, rad, seg, fg, edge, sx, sy, n_samples, rows, edge_weight, out):  # pragma: no cover
    """Cost (M,) of every particle: mean over views of silhouette + coverage + edge terms.

    pix (M, V, Q, 2) projected model points; rad (M, V, S, 2) capsule end radii in
    pixels; seg (S, 2) point indices (a == b for a ball); sx, sy (V, K) columns and rows of the
    first n_samples foreground samples of each view, sorted by row, whole pixels, and rows
    (V, H + 1) the number of samples above each row, as :class:`ViewFeatures` keeps them.
    """
    m_n, v_n = pix.shape[0], pix.shape[1]
    s_n = seg.shape[0]
    n_t = _T_CAPSULE.shape[0]
    n_o = _ACROSS.shape[0]
    for m in numba.prange(m_n):
        geo = np.empty((s_n, 9))  # per capsule: ax, ay, dx, dy, l2, ra, rb, x range
        ylo = np.empty(s_n)
        yhi = np.empty(s_n)
        covered = np.empty(sx.shape[1], np.bool_)
        n_rows = rows.shape[1] - 1
        total = 0.0
        for v in range(v_n):
            e_in = 0.0
            n_in = 0
            e_ed = 0.0
            n_ed = 0
            for s in range(s_n):
                ax = pix[m, v, seg[s, 0], 0]
                ay = pix[m, v, seg[s, 0], 1]
                dx = pix[m, v, seg[s, 1], 0] - ax
                dy = pix[m, v, seg[s, 1], 1] - ay
                ra = rad[m, v, s, 0]
                rb = rad[m, v, s, 1]
                l2 = dx * dx + dy * dy
                rmax = max(ra, rb)
                geo[s, 0] = ax
                geo[s, 1] = ay
                geo[s, 2] = dx
                geo[s, 3] = dy
                geo[s, 4] = l2
                geo[s, 5] = ra
                geo[s, 6] = rb
                geo[s, 7] = min(ax, ax + dx) - rmax
                geo[s, 8] = max(ax, ax + dx) + rmax
                ylo[s] = min(ay, ay + dy) - rmax
                yhi[s] = max(ay, ay + dy) + rmax
                if l2 > 1e-12:
                    length = math.sqrt(l2)
                    nx = -dy / length
                    ny = dx / length
                    for ti in range(n_t):
                        t = _T_CAPSULE[ti]
                        cx = ax + t * dx
                        cy = ay + t * dy
                        r = ra + t * (rb - ra)
                        for oi in range(n_o):
                            o = _ACROSS[oi]
                            e_in += 1.0 - _lookup(fg, v, cx + o * r * nx, cy + o * r * ny)
                        n_in += n_o
                        e_ed += 2.0 - _lookup(edge, v, cx + r * nx, cy + r * ny)
                        e_ed -= _lookup(edge, v, cx - r * nx, cy - r * ny)
                        n_ed += 2
                else:  # a ball
                    e_in += 1.0 - _lookup(fg, v, ax, ay)
                    n_in += 1
                    for k in range(4):
                        c = _BALL_COS[k]
                        sn = _BALL_SIN[k]
                        e_in += 1.0 - _lookup(fg, v, ax + 0.6 * ra * c, ay + 0.6 * ra * sn)
                        e_ed += 1.0 - _lookup(edge, v, ax + ra * c, ay + ra * sn)
                        n_in += 1
                        n_ed += 1
            # coverage: the samples in each capsule's rows (they are sorted by row)
            k_n = n_samples[v]
            for k in range(k_n):
                covered[k] = False
            for s in range(s_n):
                k0 = rows[v, int(math.ceil(min(max(ylo[s], 0.0), n_rows)))]
                k1 = rows[v, int(math.floor(min(max(yhi[s] + 1.0, 0.0), n_rows)))]
                ax = geo[s, 0]
                ay = geo[s, 1]
                dx = geo[s, 2]
                dy = geo[s, 3]
                inv = 1.0 / geo[s, 4] if geo[s, 4] > 1e-12 else 0.0
                ra = geo[s, 5]
                dr = geo[s, 6] - ra
                bx = sx[v, k0:k1]
                by = sy[v, k0:k1]
                bc = covered[k0:k1]
                for k in range(bx.shape[0]):  # on slices from 0: a loop LLVM vectorises
                    px = bx[k]
                    py = by[k]
                    t = min(max(((px - ax) * dx + (py - ay) * dy) * inv, 0.0), 1.0)
                    ex = ax + t * dx - px
                    ey = ay + t * dy - py
                    r = ra + t * dr
                    bc[k] |= ex * ex + ey * ey <= r * r
            hit = 0
            for k in range(k_n):
                hit += covered[k]
            e_cov = (k_n - hit) / k_n if k_n > 0 else 0.0
            total += e_in / max(n_in, 1) + e_cov + edge_weight * e_ed / max(n_ed, 1)
        out[m] = total / (v_n * (2.0 + edge_weight))


@numba.njit(cache=True)
def _coverage(pix, rad, seg, width, height):  # pragma: no cover - compiled
    """(H, W) bool: pixels whose centre lies in a capsule (the tracker's view of one pose)."""
    out = np.zeros((height, width), np.bool_)
    for y in range(height):
        for x in range(width):
            for s in range(seg.shape[0]):
                ax = pix[seg[s, 0], 0]
                ay = pix[seg[s, 0], 1]
                dx = pix[seg[s, 1], 0] - ax
                dy = pix[seg[s, 1], 1] - ay
                l2 = dx * dx + dy * dy
                t = 0.0
                if l2 > 1e-12:
                    t = min(max(((x - ax) * dx + (y - ay) * dy) / l2, 0.0), 1.0)
                ex = ax + t * dx - x
                ey = ay + t * dy - y
                r = rad[s, 0] + t * (rad[s, 1] - rad[s, 0])
                if ex * ex + ey * ey <= r * r:
                    out[y, x] = True
                    break
    return out


@numba.njit(cache=True)
def _project(pts, rot, trans, intr, focal, seg, radii):  # pragma: no cover - compiled
    """Pixels (M, V, Q, 2), depths (M, V, Q) and capsule radii in pixels (M, V, S, 2) of points
    (M, Q, 3) in V cameras (rot (V, 3, 3), trans (V, 3), intr (V, 4) fx fy cx cy, focal (V,)):
    :meth:`CalibratedCamera.project` of every camera at once."""
    m_n, q_n = pts.shape[0], pts.shape[1]
    v_n, s_n = rot.shape[0], seg.shape[0]
    pix = np.empty((m_n, v_n, q_n, 2))
    depth = np.empty((m_n, v_n, q_n))
    rad = np.empty((m_n, v_n, s_n, 2))
    for m in range(m_n):
        for v in range(v_n):
            for q in range(q_n):
                x, y, z = pts[m, q, 0], pts[m, q, 1], pts[m, q, 2]
                cx = x * rot[v, 0, 0] + y * rot[v, 0, 1] + z * rot[v, 0, 2] + trans[v, 0]
                cy = x * rot[v, 1, 0] + y * rot[v, 1, 1] + z * rot[v, 1, 2] + trans[v, 1]
                cz = x * rot[v, 2, 0] + y * rot[v, 2, 1] + z * rot[v, 2, 2] + trans[v, 2]
                cz = max(cz, 1.0)
                pix[m, v, q, 0] = intr[v, 0] * cx / cz + intr[v, 2]
                pix[m, v, q, 1] = intr[v, 1] * cy / cz + intr[v, 3]
                depth[m, v, q] = cz
            for s in range(s_n):
                rad[m, v, s, 0] = focal[v] * radii[s, 0] / depth[m, v, seg[s, 0]]
                rad[m, v, s, 1] = focal[v] * radii[s, 1] / depth[m, v, seg[s, 1]]
    return pix, rad, depth


def project_model(
    joints: np.ndarray, cameras: Sequence[CalibratedCamera]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projected model points (M, V, Q, 2), capsule radii in pixels (M, V, S, 2), depths (M, V, Q).

    ``joints`` (M, 19, 3) are body points in mm; Q counts them and the balls' centres.
    """
    seg, radii = _SEGMENTS
    pts = BODY_SHAPE.points(joints)  # (M, Q, 3)
    rot = np.array([c.R for c in cameras], dtype=float)
    trans = np.array([c.t for c in cameras], dtype=float)
    intr = np.array([[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2]] for c in cameras])
    focal = np.array([c.focal for c in cameras])
    return _project(np.ascontiguousarray(pts), rot, trans, intr, focal, seg, radii)


def model_coverage(joints: np.ndarray, camera: CalibratedCamera) -> np.ndarray:
    """(H, W) bool silhouette of one pose (19, 3) as the weighting function sees it."""
    seg, _ = BODY_SHAPE.segments()
    pix, rad, _ = project_model(joints[None], [camera])
    return _coverage(pix[0, 0], rad[0, 0], seg, camera.width, camera.height)


def costs(
    body: BodyModel, states: np.ndarray, cameras: Sequence[CalibratedCamera], feats: ViewFeatures
) -> np.ndarray:
    """E(x) (M,) in [0, 1] of particles (M, D) against one frame's features."""
    return joint_costs(body.joint_positions(states), cameras, feats)


def joint_costs(
    joints: np.ndarray, cameras: Sequence[CalibratedCamera], feats: ViewFeatures
) -> np.ndarray:
    """E (M,) in [0, 1] of body points (M, 19, 3) mm against one frame's features."""
    seg, _ = _SEGMENTS
    pix, rad, _ = project_model(joints, cameras)
    out = np.empty(len(joints))
    _costs(
        pix, rad, seg, feats.fg, feats.edge, feats.sample_x, feats.sample_y, feats.n_samples,
        feats.rows, EDGE_WEIGHT, out,
    )  # fmt: skip
    return out


# ----------------------------------------------------------------------------- the filter
def survival_beta(cost: np.ndarray, survival: float) -> float:
    """beta such that the weights exp(-beta (E - min E)) keep ``survival`` of the particles alive.

    The survival rate is the effective sample size (sum w)^2 / sum w^2 over the
    number of particles (Deutscher et al. §4); it falls as beta grows.
    """
    return float(_survival_beta(np.asarray(cost, dtype=float), float(survival)))


@numba.njit(cache=True)
def _survival_rate(e, b):  # pragma: no cover - compiled
    s1 = 0.0
    s2 = 0.0
    for i in range(e.shape[0]):
        w = math.exp(-b * e[i])
        s1 += w
        s2 += w * w
    return s1 * s1 / (e.shape[0] * s2)


@numba.njit(cache=True)
def _survival_beta(cost, survival):  # pragma: no cover - compiled
    """:func:`survival_beta`: beta bracketed by quadrupling, then 30 bisections."""
    e = cost - cost.min()
    lo, hi = 0.0, 1.0
    while _survival_rate(e, hi) > survival and hi < 1e8:
        hi *= 4
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if _survival_rate(e, mid) > survival:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def triangulate(
    cameras: Sequence[CalibratedCamera],
    pixels: Sequence[np.ndarray | None],
    heights: Sequence[float] | None = None,
    stature: float = STATURE,
) -> np.ndarray | None:
    """Least-squares meeting point (3,) of the rays through ``pixels`` (None: view not used).

    With one view, the point on its ray at the depth where a person of ``stature``
    (mm) is as tall as the foreground's ``heights`` (pixels) in that view.
    """
    used = [
        (c, p, h)
        for c, p, h in zip(cameras, pixels, heights or [0.0] * len(cameras), strict=True)
        if p is not None
    ]
    if not used:
        return None
    if len(used) == 1:
        c, p, h = used[0]
        d = c.ray(p)
        depth = c.focal * stature / h if h > 0 else 4000.0  # along the optical axis
        return c.centre + d * depth / max(float(c.R[2] @ d), 1e-3)
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for c, p, _ in used:
        d = c.ray(p)
        proj = np.eye(3) - np.outer(d, d)
        a += proj
        b += proj @ c.centre
    return np.linalg.solve(a + 1e-9 * np.eye(3), b)


@dataclass
class AnnealedParticleFilter:
    """Deutscher et al.'s annealed particle filter over a :class:`BodyModel` (module docstring).

    Args:
        body: the body model (state, limits, diffusion scales).
        cameras: calibrated cameras of the views.
        particles: particles per layer.
        layers: annealing layers per frame (1: a plain particle filter).
        survival: target survival rate of every layer (sets beta_m).
        fps: frame rate of the video (scales the diffusion).
        spread: diffusion of the first layer, in multiples of a frame's typical motion.
        recover_cost: cost of the best particle above which the filter starts again.
        seed: random seed.
        arms_again: restart the arms' diffusion half way through the layers.
        refine: candidates per limb of the limb search after annealing (0: none).
        start: the first frame's pose (a state), if known; else a coarse search finds it.
        sides: MediaPipe's left and right in the cameras (:class:`~markovmotion.video.sides.SideCheck`):
            a pose it finds turned front to back starts the search again from the pose turned
            round, and a flip the search cannot undo costs ``flip_cost`` (lowers the frame's
            confidence).
        flip_cost: added to the best cost of a frame left flipped.
        flip_slack: how much more the pose turned round may cost and still be taken (the
            silhouettes fit both about equally; MediaPipe's sides can be wrong too).
        guide: MediaPipe's 2-D landmarks in the views (module docstring, 7), or None.
        guide_weight: the guide term's weight ``g`` against the image cost.
        restart: with a guide, the share of particles started again each frame from the body
            model fitted to the triangulated points (module docstring, 7).
    """

    body: BodyModel
    cameras: Sequence[CalibratedCamera]
    particles: int = 200
    layers: int = 10
    survival: float = 0.5
    fps: float = 30.0
    spread: float = 3.0
    recover_cost: float = 0.45
    seed: int = 0
    arms_again: bool = True
    refine: int = 30
    start: np.ndarray | None = None
    sides: SideCheck | None = None
    flip_cost: float = 0.3
    flip_slack: float = 0.05
    guide: Guide | None = None
    guide_weight: float = 3.0
    restart: float = 0.25
    evaluations: int = field(default=0, init=False)
    recoveries: int = field(default=0, init=False)
    flips: int = field(default=0, init=False)
    flipped: int = field(default=0, init=False)
    frame: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.x: np.ndarray | None = None
        self._current = 0  # the frame being tracked (the guide's)
        self._last: np.ndarray | None = None  # the last frame's pose
        self.second_pass = self.body.limb_mask(("elbow", "wrist")) if self.arms_again else None
        self.limbs = [
            m
            for m in (
                self.body.limb_mask((f"{side}_{a}", f"{side}_{b}"))
                for side in ("right", "left")
                for a, b in (("elbow", "wrist"), ("knee", "ankle"))
            )
            if m.any()
        ]
        step = self.body.speed / self.fps
        floor = np.full(self.body.n_dof, 0.02)
        floor[:3] = 10.0
        self.step_std = np.maximum(step * self.spread, floor)

    def _score(self, x: np.ndarray, feats: ViewFeatures) -> np.ndarray:
        self.evaluations += len(x)
        joints = self.body.joint_positions(x)
        e = joint_costs(joints, self.cameras, feats)
        if self.guide is None:
            return e
        g = self.guide.cost(joints, self._current)
        return e if g is None else (e + self.guide_weight * g) / (1.0 + self.guide_weight)

    def _anneal(
        self, x: np.ndarray, feats: ViewFeatures, layers: int, std: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """Anneal particles ``x`` over ``layers``; the estimate and its cost."""
        shrink = math.sqrt(self.survival)
        for m in range(layers):
            sd = std * shrink**m
            if self.second_pass is not None and m >= layers // 2:
                sd = np.where(self.second_pass, std * shrink ** (m - layers // 2), sd)
            x = x + self.rng.normal(size=x.shape) * sd
            self.body.clip(x)
            e = self._score(x, feats)
            beta = survival_beta(e, self.survival)
            w = np.exp(-beta * (e - e.min()))
            w /= w.sum()
            if m == layers - 1:
                est = w @ x
                self.x = x[self.rng.choice(len(x), len(x), p=w)]
                best = float(e.min())
                return est, best
            x = x[self.rng.choice(len(x), len(x), p=w)]
        raise AssertionError("unreachable")

    def _refine_limbs(self, est: np.ndarray, feats: ViewFeatures) -> tuple[np.ndarray, float]:
        """Search each limb alone around the estimate (the weighting function is nearly a sum
        over body parts, so limbs can be searched one at a time, as partitioned sampling does);
        the particles follow the estimate's change."""
        cur = float(self._score(est[None], feats)[0])
        start = est.copy()
        for scale in (2.0, 0.7):
            for mask in self.limbs:
                cand = np.tile(est, (self.refine, 1))
                cand[:, mask] += self.rng.normal(size=(self.refine, int(mask.sum()))) * (
                    scale * self.step_std[mask]
                )
                self.body.clip(cand)
                e = self._score(cand, feats)
                k = int(np.argmin(e))
                if e[k] < cur:
                    est, cur = cand[k], float(e[k])
        if self.x is not None:
            self.x = self.body.clip(self.x + (est - start))
        return est, cur

    def initialise(
        self, feats: ViewFeatures, start: np.ndarray | None = None
    ) -> tuple[np.ndarray, float]:
        """Coarse search from the standing pose (or around ``start``, a state) on one frame.

        Two stages of annealing with twice the particles: first the root alone
        (position near where the cameras' foreground centroids meet, any
        heading, the mean pose), then every joint as well.
        """
        n = 2 * self.particles
        root = np.zeros(self.body.n_dof, bool)
        root[:4] = True
        if self.body.joints and self.body.joints[0] == 0:
            root[self.body.slices[0]] = True
        std = self.step_std * 2.0
        if start is None:
            centre = triangulate(self.cameras, feats.centroids, feats.heights)
            if centre is None:
                centre = np.zeros(3)
            centre[1] = self.body.height
            x = np.tile(self.body.standing(centre), (n, 1))
            x[:, 3] = self.rng.uniform(-math.pi, math.pi, n)
            x[:, :3] += self.rng.normal(size=(n, 3)) * [150.0, 50.0, 150.0]
            std_root = np.where(root, std, 0.0)
            std_root[3] = 0.5
            self._anneal(x, feats, max(self.layers, 5), std_root)
            x = self.x[self.rng.choice(len(self.x), n)]
            span = np.where(np.isfinite(self.body.upper), self.body.upper - self.body.lower, 0.0)
            x[:, ~root] += self.rng.normal(size=(n, int((~root).sum()))) * 0.1 * span[~root]
            self.body.clip(x)
        else:
            x = np.tile(start, (n, 1))
        est, best = self._anneal(x, feats, max(self.layers, 5), std)
        self.x = self.x[: self.particles]
        return est, best

    def step(self, feats: ViewFeatures, gap: int = 1) -> tuple[np.ndarray, float]:
        """Track one frame, ``gap`` frames after the last: the pose (D,) and the best cost
        (plus ``flip_cost`` if it stays turned front to back, see ``sides``)."""
        frame, self.frame = self.frame + gap - 1, self.frame + gap
        self._current = frame
        est, best = self._track(feats, gap)
        est, best = self._check_sides(est, best, feats, frame)
        self._last = est
        return est, best

    def _check_sides(
        self, est: np.ndarray, best: float, feats: ViewFeatures, frame: int
    ) -> tuple[np.ndarray, float]:
        """A pose that MediaPipe finds turned front to back: search again around it turned
        round (its heading plus pi), keep that if it is not flipped and costs at most
        ``flip_slack`` more; else keep the pose and add ``flip_cost`` to its cost."""
        if self.sides is None or not self.sides.flipped(self.body.joint_positions(est)[0], frame):
            return est, best
        self.flips += 1
        particles = self.x
        turned = est.copy()
        turned[3] += math.pi
        est2, best2 = self.initialise(feats, turned)
        if best2 <= best + self.flip_slack and not self.sides.flipped(
            self.body.joint_positions(est2)[0], frame
        ):
            return est2, best2
        self.x = particles
        self.flipped += 1
        return est, best + self.flip_cost

    def _track(self, feats: ViewFeatures, gap: int) -> tuple[np.ndarray, float]:
        if self.x is None:
            return self.initialise(feats, self.start)
        x = self.x
        if self.guide is not None and self.restart > 0:
            # some particles start again from the body model fitted to MediaPipe's points
            fitted = self.guide.pose(self.body, self._current, self._last)
            if fitted is not None:
                k = int(round(self.restart * len(x)))
                x = x.copy()
                x[self.rng.choice(len(x), k, replace=False)] = fitted
        est, best = self._anneal(x, feats, self.layers, self.step_std * max(gap, 1))
        if self.refine:
            est, best = self._refine_limbs(est, feats)
        if best > self.recover_cost:
            self.recoveries += 1
            prev = est
            est2, best2 = self.initialise(feats)
            if best2 >= best:
                self.x = np.tile(prev, (self.particles, 1))
            else:
                est, best = est2, best2
        return est, best


# ----------------------------------------------------------------------------- whole videos
@dataclass
class TrackResult:
    """States (F, D), per-frame confidence (1 - best cost), frame rate, wall and CPU time (s)."""

    states: np.ndarray
    confidence: np.ndarray
    fps: float
    seconds: float
    views: int
    recoveries: int
    cpu_seconds: float = 0.0
    #: The video's note on its backgrounds (:attr:`MultiviewVideo.background_notes`).
    background_notes: list[str] = field(default_factory=list)
    #: One line when a camera's video ended before the others' (the track stops there).
    video_notes: list[str] = field(default_factory=list)
    #: The videos that ended before the others, cutting the track (their names).
    ended_early: list[str] = field(default_factory=list)
    #: Frames MediaPipe found turned front to back (searched again), and those left so.
    flips: int = 0
    flipped: int = 0
    #: Seconds MediaPipe took over every view for the guide (before the clock starts).
    guide_seconds: float = 0.0
    #: Share of (view, frame) pairs in which the guide has a landmark to pull towards
    #: (MediaPipe found the person and triangulation kept the view); None without a guide.
    guide_seen: float | None = None
    #: (view, frame) pairs in which MediaPipe found someone else than the person tracked
    #: (left out of the guide, :func:`~markovmotion.video.triangulation.one_person`).
    guide_someone_else: int = 0
    #: Whom the guide followed (:func:`~markovmotion.video.triangulation.whom`).
    guide_whom: dict = field(default_factory=dict)
    #: With ``size_from_views``: the segments' sizes measured and the body model so scaled,
    #: whose skeleton the states are of.
    body_size: dict = field(default_factory=dict)
    body: BodyModel | None = None


def multiview_frames(
    videos: Sequence[Path],
    max_frames: int | None = None,
    cameras: Sequence[CalibratedCamera] | None = None,
    notes: list[str] | None = None,
    ended_early: list[str] | None = None,
) -> Iterator[list[np.ndarray]]:
    """One frame per camera at a time, until the shortest video ends (undistorted by their
    ``cameras``, :func:`~markovmotion.video.render.read_frames`); a video that ends before
    the others is said in ``notes`` (:func:`~markovmotion.video.render.shortest_note`), with
    its header's count if that is more (:func:`~markovmotion.video.render.header_shortfall`:
    damaged in the middle), and its name added to ``ended_early`` (it cut the frames)."""
    cams = list(cameras) if cameras is not None else [None] * len(videos)
    readers = [read_frames(v, c) for v, c in zip(videos, cams, strict=True)]
    n = 0
    while max_frames is None or n < max_frames:
        frames = [next(r, None) for r in readers]
        if any(f is None for f in frames):
            lengths = [n + (f is not None) for f in frames]
            note = shortest_note(
                [Path(v).name for v in videos],
                lengths,
                [
                    header_shortfall(v, k, c) if f is None else ""
                    for v, k, c, f in zip(videos, lengths, cams, frames, strict=True)
                ],
            )
            if note is not None and notes is not None:
                notes.append(note)
            if ended_early is not None and n < max(lengths):
                ended_early += [
                    Path(v).name for v, k in zip(videos, lengths, strict=True) if k == n
                ]
            return
        n += 1
        yield frames


@dataclass
class MultiviewVideo:
    """The cameras, frame rate, background and frames (one per camera at a time) of a video."""

    cameras: list[CalibratedCamera]
    fps: float
    doc: dict
    backgrounds: list[np.ndarray]
    frames: Iterator[list[np.ndarray]]
    source: Path
    videos: list[Path]
    #: The note on the cameras without an empty-scene image, what their backgrounds are
    #: (one line naming them all, :func:`~markovmotion.video.background.background_note`).
    background_notes: list[str] = field(default_factory=list)
    #: The camera file's notes (:func:`~markovmotion.video.cameras.load_cameras`), and one
    #: line when a camera's video ended before the others' (filled as the frames are read).
    video_notes: list[str] = field(default_factory=list)
    #: The videos that ended before the others and so cut the frames (filled as they are read).
    ended_early: list[str] = field(default_factory=list)

    def features_of(self, frames: list[np.ndarray], index: int, seed: int = 0) -> ViewFeatures:
        """The features of one frame per camera (checked against the cameras' sizes)."""
        for c, f in zip(self.cameras, frames, strict=True):
            if f.shape[:2] != (c.height, c.width):
                raise MotionFormatError(
                    self.source,
                    f"camera {c.name} is {c.width}x{c.height} but its video is "
                    f"{f.shape[1]}x{f.shape[0]}",
                )
        return view_features(frames, self.backgrounds, seed + index)

    def features(self, seed: int = 0) -> Iterator[ViewFeatures]:
        """Every frame's features, made as they are consumed."""
        for i, frames in enumerate(self.frames):
            yield self.features_of(frames, i, seed)


def open_video(
    video: str | os.PathLike[str],
    cameras_file: str | os.PathLike[str] | None = None,
    views: int | None = None,
    max_frames: int | None = None,
    learn_background: bool = True,
) -> MultiviewVideo:
    """A folder with ``cameras.json`` (or that file), or one camera's video file (with
    ``cameras_file``, or ``cameras.json`` beside it: the camera naming the file, else the
    first), ready to track: frames are decoded as they are consumed (no queue).
    ``views`` keeps only the first cameras. A camera without an empty-scene image gets the
    median of frames spread over its video, or with ``learn_background`` (and MediaPipe
    installed) the median where the person is not, and a note saying whether the plain median
    still holds the person (:mod:`markovmotion.video.background`; one note for all such
    cameras, :func:`~markovmotion.video.background.background_note`).

    Raises:
        MotionFormatError: a missing or malformed camera file, a missing video or
            background, or frames of another size than their camera's.
    """
    cams_path = camera_file(video, cameras_file)
    ended: list[str] = []  # the camera file's notes, then a video that ended before the others
    # one view read: the other cameras' videos at rates of their own are noted, not refused
    one = lone_video(video) or views == 1
    cameras, doc = load_cameras(cams_path, ended, paired=not one)
    if lone_video(video):
        k = camera_of_video(cameras, video, ended)  # one camera's video
        cameras, videos = [cameras[k]], [Path(video)]
    else:
        videos = camera_videos(cams_path, cameras)
    if views is not None:
        cameras, videos = cameras[:views], videos[:views]
    images = camera_videos(cams_path, cameras, "background")
    backgrounds = []
    checks: list[tuple[str, BackgroundCheck | None]] = []  # the cameras without an image
    learn = learn_background and mediapipe_installed()
    for v, b, c in zip(videos, images, cameras, strict=True):
        if b is not None:
            backgrounds.append(read_image(b, c))
        elif learn:
            from markovmotion.video.background import learn_background as learnt_background

            _, learnt, check = learnt_background(v, BACKGROUND_FRAMES, c)
            backgrounds.append(learnt)
            checks.append((c.name, check))
        else:
            backgrounds.append(estimate_background(v, camera=c))
            checks.append((c.name, None))
    notes = background_note(checks, "MediaPipe not installed" if learn_background else "")
    short: list[str] = []
    frames = multiview_frames(videos, max_frames, cameras, ended, short)
    return MultiviewVideo(
        cameras, float(doc["fps"]), doc, backgrounds, frames, cams_path, list(videos), notes,
        ended, short,
    )  # fmt: skip


def no_one(feats: ViewFeatures) -> bool:
    """No view of this frame shows foreground over :data:`EMPTY_COVER` of its pixels: no one
    in view, whatever pose the filter gives."""
    return feats.coverage is not None and bool(feats.coverage.max() < EMPTY_COVER)


def track_features(
    features: Iterator[ViewFeatures] | Sequence[ViewFeatures],
    apf: AnnealedParticleFilter,
    total: int | None = None,
    source: str | os.PathLike[str] = "video",
) -> TrackResult:
    """Run the filter over every frame's features, with a progress bar (of ``total``
    frames, if known); the wall time includes making them."""
    states, conf, empty = [], [], []
    t0, c0 = time.perf_counter(), time.process_time()
    # BLAS on one thread: the filter's products are small (200 particles), and OpenBLAS's
    # threads doubled its CPU for 10 % more frames/s on an idle machine (53 against 31 frames
    # per CPU second; tracker_bench.py), taking the core the partner and MediaPipe need
    with threadpool_limits(1, user_api="blas"):
        for feats in track(features, "tracking", total):
            x, best = apf.step(feats)
            states.append(x)
            empty.append(no_one(feats))
            conf.append(0.0 if empty[-1] else 1.0 - best)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if not states:
        raise MotionFormatError(source, "no frames in this video")
    if all(empty):
        raise MotionFormatError(
            source, "no person found in this video (no foreground in any view of any frame)"
        )
    result = TrackResult(
        np.array(states), np.array(conf), apf.fps, seconds, len(apf.cameras), apf.recoveries, cpu,
        flips=apf.flips, flipped=apf.flipped,
    )  # fmt: skip
    if n := sum(empty):
        first = empty.index(True)
        result.video_notes.append(
            f"note: no one in any view in {n} frames (the first: frame {first}; foreground under "
            f"{100 * EMPTY_COVER:g} % of every view): their poses are guesses, confidence 0"
        )
    return result


def track_video(
    video: str | os.PathLike[str],
    body: BodyModel,
    cameras_file: str | os.PathLike[str] | None = None,
    particles: int = 200,
    layers: int = 10,
    views: int | None = None,
    max_frames: int | None = None,
    seed: int = 0,
    start: np.ndarray | None = None,
    learn_background: bool = True,
    sides: bool = False,
    guide: bool = False,
    left_right: str = "views",
    person: str | None = None,
    size_from_views: bool = False,
) -> TrackResult:
    """Track the person of a video (see :func:`open_video`) with the annealed particle filter,
    from the pose ``start`` (a state) if given; with ``sides``, MediaPipe's left and right in
    every camera catch front/back flips (:mod:`markovmotion.video.sides`); with ``guide``,
    MediaPipe's landmarks in every camera, triangulated to reject the views that disagree,
    guide the filter (:mod:`markovmotion.video.triangulation`; ``left_right``: how its left
    and right are made consistent first, :data:`~markovmotion.video.triangulation.LEFT_RIGHT`).
    MediaPipe runs before the clock starts (``guide_seconds`` of the result; ``guide_seen``: the share of views and
    frames it gave the filter landmarks in); ``person`` (``CAMERA:U,V``): of several people,
    MediaPipe follows the one at that pixel
    (:func:`~markovmotion.video.triangulation.person_ray`); ``size_from_views``: the body's
    segments scaled to the person's, measured from the same triangulated landmarks
    (:func:`~markovmotion.video.body_size.segment_sizes_from_points`; the result's ``body``).

    Raises:
        MotionFormatError: ... or the body's size cannot be measured."""
    mv = open_video(video, cameras_file, views, max_frames, learn_background)
    check = guided = None
    sizes: dict = {}
    if sides or guide or size_from_views:  # MediaPipe once over every camera, for every use
        from markovmotion.video.sides import SideCheck
        from markovmotion.video.triangulation import (
            Guide,
            lone_views,
            person_views,
            triangulate_views,
            whom,
        )

        # views of someone else dropped and left and right made consistent first
        # (triangulation.consistent_views): a camera behind the person, whose MediaPipe
        # mirrors the body, is put right by the others
        one = person_views(mv.videos, mv.cameras, mv.fps, max_frames, person, left_right)
        agreed = one.agreed
        check = SideCheck.from_landmarks(agreed) if sides else None
        # glitches out (Triangulated.despiked): a restart or a segment's size from a
        # landmark on the wrong arm for a frame or two is a pose no body took
        points = triangulate_views(agreed).despiked(mv.fps)[0] if guide or size_from_views else None
        if size_from_views:
            from markovmotion.video.body_size import segment_body, segment_sizes_from_points

            try:
                sizes = segment_sizes_from_points(body, points.points, mv.video_notes)
            except ValueError as exc:
                raise MotionFormatError(
                    mv.source, f"cannot measure the body size ({exc})"
                ) from None
            body = segment_body(body, sizes)
        if guide:
            guided = Guide.from_views(agreed, points)
            followed = whom(points.points, mv.cameras, one.aim)
        if points is not None:
            mv.video_notes.extend(lone_views(one.found, points))
    apf = AnnealedParticleFilter(
        body, mv.cameras, particles, layers, fps=mv.fps, seed=seed, start=start, sides=check,
        guide=guided,
    )  # fmt: skip
    total = expected_frames(mv.videos, max_frames, mv.cameras)
    result = track_features(mv.features(seed), apf, total, mv.source)
    result.background_notes = mv.background_notes
    result.video_notes = [*mv.video_notes, *result.video_notes]
    result.ended_early = mv.ended_early
    result.guide_seconds = guided.seconds if guided is not None else 0.0
    if guided is not None:
        result.guide_seen = float((guided.weights > 0).any(axis=-1).mean())
        result.guide_someone_else = one.someone_else
        result.guide_whom = followed
    if size_from_views:
        result.body_size, result.body = sizes, body
    return result

"""Silhouette tracker for a static camera (interaction paper, §2; after Baumberg and Hogg).

Per frame: background subtraction against a background image (the per-pixel
median of frames sampled over the whole video, so people who move are not
part of it), a threshold at a multiple of the estimated sensor noise,
morphological clean-up and hole filling (OpenCV), one blob per person (the
largest blobs, ordered left to right; when two people touch and form one
blob, each of its pixels goes to the person whose mask in the previous frame
is nearer), the outer boundary of each blob, the reference point at the top of the head
(found where the vertical through the blob's centre meets the top of the
boundary, then moved along the boundary to the locally highest point), and a
closed uniform cubic B-spline with 32 control points fitted to the boundary
resampled evenly from the reference point, clockwise on screen, after each
boundary point has been moved along its normal to where the background
difference falls to half its level inside the body (sub-pixel edges). Each person's
height is the vertical extent of its boundary and its position the reference
point, in pixels (y down).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from markovmotion.features.joint_shape import Person, TwoPeople
from markovmotion.persist import load_npz, save_npz
from markovmotion.progress import track
from markovmotion.video.bspline import fit_closed_bspline, resample_closed
from markovmotion.video.render import frame_count, read_frames, video_fps

KIND = "silhouette-track"


@dataclass
class Outline:
    """One person in one frame: B-spline control points (n, 2), reference point (2,), height."""

    control: np.ndarray
    reference: np.ndarray
    height: float


def _shoelace(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) / 2)


def boundary(mask: np.ndarray) -> np.ndarray:
    """(L, 2) centres of the outer boundary pixels of the largest region of ``mask``,
    clockwise on screen."""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2))
    p = max(contours, key=cv2.contourArea)[:, 0].astype(float)
    return p[::-1] if _shoelace(p) < 0 else p


def outward_normals(points: np.ndarray) -> np.ndarray:
    """(L, 2) unit outward normals of a closed polygon clockwise on screen (y down)."""
    tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    return np.column_stack([tangent[:, 1], -tangent[:, 0]])


def refine_edges(points: np.ndarray, diff: np.ndarray, reach: float = 3.0) -> np.ndarray:
    """Move boundary points along their normals to where the background difference falls to
    half its level inside the body (sub-pixel edges); points without such a crossing stay."""
    normals = outward_normals(points)
    offsets = np.arange(-reach, reach + 0.25, 0.5)
    where = points[:, None] + offsets[None, :, None] * normals[:, None]
    profile = cv2.remap(
        diff,
        where[..., 0].astype(np.float32),
        where[..., 1].astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    inside = profile[:, :3].mean(axis=1)
    outside = profile[:, -3:].mean(axis=1)
    half = 0.5 * (inside + outside)
    above = profile >= half[:, None]
    # last offset still above half, scanning outward from the inside
    last = np.where(above[:, 0], np.argmin(above, axis=1) - 1, -1)
    ok = (last >= 0) & (last < len(offsets) - 1) & (inside - outside > 0)
    i = np.clip(last, 0, len(offsets) - 2)
    rows = np.arange(len(points))
    v0, v1 = profile[rows, i], profile[rows, i + 1]
    frac = np.clip((v0 - half) / np.maximum(v0 - v1, 1e-6), 0.0, 1.0)
    shift = np.where(ok, offsets[i] + 0.5 * frac, 0.0)
    return points + shift[:, None] * normals


def head_reference(points: np.ndarray, centre_x: float) -> int:
    """Index of the reference point: top of the boundary above the centre, moved to the
    locally highest boundary point (the middle of a flat top)."""
    n = len(points)
    y = points[:, 1]
    ys = np.convolve(np.r_[y[-2:], y, y[:2]], np.ones(5) / 5, mode="valid")
    near = np.abs(points[:, 0] - centre_x)
    band = np.flatnonzero(near <= max(near.min(), 0.0) + 2.0)
    i = int(band[np.argmin(ys[band])])
    for _ in range(n):
        lower = min((i - 1) % n, (i + 1) % n, key=lambda k: ys[k])
        if ys[lower] >= ys[i]:
            break
        i = lower
    lo = hi = 0
    while lo < n // 4 and ys[(i - lo - 1) % n] <= ys[i] + 0.25:
        lo += 1
    while hi < n // 4 and ys[(i + hi + 1) % n] <= ys[i] + 0.25:
        hi += 1
    return (i + (hi - lo) // 2) % n


def outline(
    mask: np.ndarray, diff: np.ndarray, n_control: int = 32, n_samples: int = 128
) -> Outline | None:
    """B-spline outline of the blob in ``mask`` (uint8) whose edges are refined on ``diff``
    (float32 background difference), or None if there is no blob."""
    pts = boundary(mask)
    if len(pts) < 8:
        return None
    m = cv2.moments(pts.astype(np.float32))
    centre_x = m["m10"] / m["m00"] if m["m00"] else pts[:, 0].mean()
    ref = head_reference(pts, centre_x)
    dense = refine_edges(resample_closed(pts, 4 * n_samples, start=ref), diff)
    samples = resample_closed(_from_top(dense), n_samples)
    control = fit_closed_bspline(samples, n_control)
    return Outline(control, samples[0], float(np.ptp(dense[:, 1])))


def _from_top(points: np.ndarray, reach: int = 6) -> np.ndarray:
    """The closed polygon ``points`` (starting near a local top) starting exactly at that top:
    the vertex of a parabola fitted to the heights of the points around the highest nearby."""
    n = len(points)
    near = np.r_[n - reach : n, 0 : reach + 1]
    k = near[np.argmin(points[near, 1])]
    window = (k + np.arange(-reach, reach + 1)) % n
    a, b, _ = np.polyfit(np.arange(-reach, reach + 1), points[window, 1], 2)
    shift = float(np.clip(-b / (2 * a), -reach, reach)) if a > 0 else 0.0
    i = int(np.floor(shift))
    f = shift - i
    p0, p1 = points[(k + i) % n], points[(k + i + 1) % n]
    rolled = np.roll(points, -((k + i + 1) % n), axis=0)
    return np.vstack([(1 - f) * p0 + f * p1, rolled])


class SilhouetteTracker:
    """Background subtraction, blobs and B-spline outlines of ``n_people`` people.

    Args:
        n_people: people to find per frame (1 or 2).
        n_control: control points per outline (paper: 32).
        n_samples: boundary samples per outline for the fit.
        threshold: foreground where a colour channel differs from the
            background by more than this many noise standard deviations.
        min_area: smallest blob kept, as a fraction of the frame.
    """

    def __init__(
        self,
        n_people: int = 2,
        n_control: int = 32,
        n_samples: int = 128,
        threshold: float = 6.0,
        min_area: float = 0.001,
    ):
        if n_people not in (1, 2):
            raise ValueError("the tracker follows one or two people")
        self.n_people = n_people
        self.n_control = n_control
        self.n_samples = n_samples
        self.threshold = threshold
        self.min_area = min_area
        self._previous: list[np.ndarray] | None = None

    def learn_background(self, frames: Iterable[np.ndarray]) -> SilhouetteTracker:
        """Background image (median) and sensor noise (from deviations from it) of ``frames``."""
        stack = np.stack(list(frames))
        self.background_ = np.median(stack, axis=0).astype(np.uint8)
        dev = np.abs(stack.astype(np.int16) - self.background_.astype(np.int16))
        self.noise_ = float(max(1.4826 * np.median(dev), 1.0))
        self._previous = None
        return self

    def difference(self, frame: np.ndarray) -> np.ndarray:
        """(H, W) float32 largest colour difference from the background."""
        d = cv2.absdiff(frame, self.background_)
        return cv2.max(cv2.max(d[..., 0], d[..., 1]), d[..., 2]).astype(np.float32)

    def foreground(self, diff: np.ndarray) -> np.ndarray:
        """(H, W) uint8 mask (0/255) of what differs from the background, cleaned."""
        level = self.threshold * self.noise_
        _, mask = cv2.threshold(diff, level, 255, cv2.THRESH_BINARY)
        mask = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))

    def blobs(self, mask: np.ndarray) -> tuple[list[np.ndarray], bool]:
        """One filled mask per person, left to right, and whether two people had to be cut apart."""
        parts = regions(mask, self.n_people, self.min_area * mask.size)
        merged = self.n_people == 2 and len(parts) == 1
        if merged:
            parts = self._split(parts[0][0])
        parts.sort(key=lambda r: r[1])
        masks = [m for m, _ in parts]
        if len(masks) == self.n_people:
            self._previous = masks
        return masks, merged

    def _split(self, blob: np.ndarray) -> list[tuple[np.ndarray, float]]:
        """Two people in one blob: each pixel goes to the nearer of the two people's masks in
        the previous frame; without one, the blob is cut at its thinnest column."""
        if self._previous is not None:
            near = [cv2.distanceTransform(255 - m, cv2.DIST_L2, 3) for m in self._previous]
            first = near[0] <= near[1]
            halves = [np.where(first, blob, 0), np.where(first, 0, blob)]
        else:
            x0, _, w, _ = cv2.boundingRect(blob)
            columns = (blob[:, x0 : x0 + w] > 0).sum(axis=0)
            cut = x0 + w // 4 + int(np.argmin(columns[w // 4 : max(3 * w // 4, w // 4 + 1)]))
            halves = [blob.copy(), blob.copy()]
            halves[0][:, cut:] = 0
            halves[1][:, :cut] = 0
        return [r for h in halves for r in regions(h.astype(np.uint8), 1, 1)]

    def track_frame(self, frame: np.ndarray) -> tuple[list[Outline | None], bool]:
        """Outlines of the people in ``frame`` (left to right; None where one is missing)."""
        diff = self.difference(frame)
        parts, merged = self.blobs(self.foreground(diff))
        found = [outline(p, diff, self.n_control, self.n_samples) for p in parts]
        found = [o for o in found if o is not None]
        return found + [None] * (self.n_people - len(found)), merged


def regions(mask: np.ndarray, n: int, min_area: float) -> list[tuple[np.ndarray, float]]:
    """The ``n`` largest regions of ``mask`` of at least ``min_area`` pixels, holes filled,
    each as a mask and the x of its centre."""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    areas = [cv2.contourArea(c) for c in contours]
    out = []
    for i in np.argsort(areas)[::-1][:n]:
        if areas[i] < min_area:
            break
        filled = np.zeros_like(mask)
        cv2.drawContours(filled, contours, int(i), 255, cv2.FILLED)
        m = cv2.moments(contours[i])
        out.append((filled, m["m10"] / m["m00"] if m["m00"] else 0.0))
    return out


@dataclass
class SilhouetteTrack:
    """Tracked people of a video: control points (T, P, n, 2), reference points (T, P, 2),
    heights (T, P) in pixels, ``found`` (T, P), ``merged`` (T,) (two people cut apart)."""

    control: np.ndarray
    reference: np.ndarray
    height: np.ndarray
    found: np.ndarray
    merged: np.ndarray
    fps: float
    name: str = ""

    @property
    def n_frames(self) -> int:
        return len(self.control)

    def filled(self) -> SilhouetteTrack:
        """Missing people replaced by the nearest earlier (else later) frame where they were found."""
        out = SilhouetteTrack(
            self.control.copy(),
            self.reference.copy(),
            self.height.copy(),
            self.found.copy(),
            self.merged.copy(),
            self.fps,
            self.name,
        )
        for p in range(self.found.shape[1]):
            ok = np.flatnonzero(self.found[:, p])
            if not len(ok):
                raise ValueError(f"{self.name}: person {p} is never found")
            src = ok[
                np.clip(np.searchsorted(ok, np.arange(self.n_frames), side="right") - 1, 0, None)
            ]
            src = np.where(np.arange(self.n_frames) < ok[0], ok[0], src)
            out.control[:, p] = self.control[src, p]
            out.reference[:, p] = self.reference[src, p]
            out.height[:, p] = self.height[src, p]
        return out

    def person(self, p: int) -> Person:
        t = self.filled()
        return Person(t.control[:, p], t.reference[:, p], t.height[:, p], np.zeros(self.n_frames))

    def two_people(self) -> TwoPeople:
        """The left-hand (0) and right-hand (1) individuals of a two-person track."""
        t = self.filled()
        return TwoPeople(
            t.control, t.reference, t.height, np.zeros(t.height.shape), self.fps, self.name
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        arrays = {
            "control": self.control,
            "reference": self.reference,
            "height": self.height,
            "found": self.found,
            "merged": self.merged,
        }
        save_npz(path, KIND, {"fps": self.fps, "name": self.name}, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SilhouetteTrack:
        header, a = load_npz(path, KIND)
        return cls(
            a["control"],
            a["reference"],
            a["height"],
            a["found"],
            a["merged"],
            float(header["fps"]),
            header.get("name", Path(path).name),
        )


def track_video(
    path: str | os.PathLike[str],
    n_people: int = 2,
    background_frames: int = 60,
    background: str | os.PathLike[str] | None = None,
    **options,
) -> SilhouetteTrack:
    """Track the people of a video file or image folder (two passes: background, then people).

    The background is the median of ``background_frames`` frames spread over the video, or,
    given ``background`` (a video of the empty scene), of that video's frames: a short clip
    in which people hardly move would leave them in the median of its own frames.
    ``options`` go to :class:`SilhouetteTracker`.
    """
    tracker = SilhouetteTracker(n_people=n_people, **options)
    count = frame_count(path)
    if background is not None:
        tracker.learn_background(read_frames(background))
    else:
        step = max(count // background_frames, 1)
        tracker.learn_background(f for t, f in enumerate(read_frames(path)) if t % step == 0)
    p, k = tracker.n_people, tracker.n_control
    rows = []
    for frame in track(read_frames(path), f"tracking {Path(path).name}", total=count):
        people, merged = tracker.track_frame(frame)
        rows.append(
            (
                [np.zeros((k, 2)) if o is None else o.control for o in people],
                [np.zeros(2) if o is None else o.reference for o in people],
                [0.0 if o is None else o.height for o in people],
                [o is not None for o in people],
                merged,
            )
        )
    control, reference, height, found, merged = (np.array(c) for c in zip(*rows, strict=True))
    return SilhouetteTrack(
        control.reshape(-1, p, k, 2),
        reference.reshape(-1, p, 2),
        height.reshape(-1, p),
        found.reshape(-1, p),
        merged,
        video_fps(path),
        Path(path).name,
    )

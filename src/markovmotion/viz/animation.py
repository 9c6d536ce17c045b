"""Stick-figure animations (GIF, MP4) and frame strips (PNG) of motions and marker clouds.

Every frame of a clip is seen through one fixed camera chosen from all frames
of all items: an orthographic view from 18 degrees above the ground, from the
right of the main direction of travel turned 20 degrees towards the front (or,
when nobody travels, 40 degrees from the average facing direction), so that a
walk is seen nearly in profile, going left to right, and a dance from the
front. Lengths keep their proportions on screen (equal aspect); the floor is a
grid at the lowest point ever reached, with each person's shadow on it. Bones are lines from each joint
to its parent, end sites (head, hand and foot tips) included; joints above the
pelvis (Bandai's ``joint_Root``) are not drawn. Marker clouds (any object with
``positions`` (F, M, 3) in mm and ``fps``) are drawn as points.

Frames are drawn by updating line data over a cached background (blitting)
and encoded directly: GIF with Pillow on one shared palette, MP4 (H.264) with
the ffmpeg binary of ``imageio-ffmpeg``. This is the work matplotlib's
``PillowWriter`` / ``FFMpegWriter`` do, without redrawing the whole figure for
each frame (about ten times faster).
"""

from __future__ import annotations

import os
import textwrap
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.transforms import Bbox

from markovmotion.core.motion import GROUND, UP, Motion
from markovmotion.errors import LimitError, MotionFormatError
from markovmotion.features.body_points import LEG_POINTS, figure_bones, find_points
from markovmotion.io.files import atomic_write
from markovmotion.limits import (
    MAX_ANIMATION_FRAMES,
    MAX_GIF_FRAMES,
    exceeded,
    max_animation_frames,
    max_gif_frames,
)
from markovmotion.progress import track
from markovmotion.viz.plots import check_suffix
from markovmotion.viz.video import write_mp4

OUTPUT_SUFFIXES = (".gif", ".mp4", ".png")
COLOURS = (
    "#1f77b4",
    "#d62728",
    "#2ca02c",
    "#ff7f0e",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#17becf",
)
POINT_LIGHT_BACKGROUND = "black"
POINT_LIGHT_COLOUR = "white"
ELEVATION = np.radians(18.0)
QUARTER_TRAVEL = np.radians(20.0)
QUARTER_STILL = np.radians(40.0)
MAX_ASPECT = 3.2
TRAVEL_MM = 250.0  # horizontal spread (std) above which a clip "travels"
DPI = 100
PANEL_HEIGHT = 4.5  # inches
TITLE_BAND = 0.45  # inches
CHAR_EM = 0.55  # a title's mean character width (em), to know when to wrap it
SHADOW_ALPHA = 0.35
MAX_WIDTH = 19.2  # inches
MAX_HEIGHT = 10.8
STACK_ASPECT = 1.6


class PointCloud(Protocol):
    """What the renderer needs from marker data (``core.markers.Markers``)."""

    positions: np.ndarray
    fps: float


Drawable = Motion | PointCloud


def check_output(path: str | os.PathLike[str]) -> str:
    """The output suffix of ``path``, or a :class:`MarkovMotionError` naming the ones accepted."""
    return check_suffix(path, OUTPUT_SUFFIXES, "output")


# ------------------------------------------------------------------- tracks
@dataclass(frozen=True)
class _Track:
    """One person (or marker cloud): positions in mm, bones as (child, parent) rows."""

    name: str
    positions: np.ndarray  # (F, N, 3)
    fps: float
    bones: np.ndarray  # (B, 2); for markers, those joining body points (may be empty)
    facing: np.ndarray | None  # (F, 3) horizontal unit vectors
    #: The floor's height under a body with no legs (an upper-body marker set), else None:
    #: the floor is then its lowest point (:func:`_floor_of`).
    floor: float | None = None
    #: When the whole motion ends (s), also once cut to the frames shown (:meth:`until`).
    ends: float | None = None

    @property
    def last_time(self) -> float:
        return (len(self.positions) - 1) / self.fps

    @property
    def end_time(self) -> float:
        """When the whole motion ends (s), also once cut to the frames shown."""
        return self.ends if self.ends is not None else self.last_time

    def over(self, time: float) -> bool:
        """The whole motion has ended by ``time`` (half a frame's grace: a take at 30.00003
        fps cut at 2 s is not over at 1.9333 s)."""
        return time > self.end_time + 0.5 / self.fps

    def frame_at(self, times: np.ndarray) -> np.ndarray:
        """Index of the frame shown at each time (the last one once the clip is over)."""
        idx = np.rint(np.asarray(times) * self.fps).astype(int)
        return np.clip(idx, 0, len(self.positions) - 1)

    def until(self, time: float) -> _Track:
        """The frames shown up to ``time`` (the camera is fitted to those)."""
        n = int(self.frame_at(np.array([time]))[0]) + 1
        facing = None if self.facing is None else self.facing[:n]
        return _Track(
            self.name, self.positions[:n], self.fps, self.bones, facing, self.floor, self.end_time
        )


def _to_track(item: Any, number: int, name: str | None) -> _Track:
    label = name or getattr(item, "name", "") or f"person {number + 1}"
    if isinstance(item, Motion):
        sk = item.skeleton
        pos = item.positions()
        yaw = item.heading(pos)
        facing = np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], axis=1)
        keep = sk.body_root  # joints before it form a static chain above the pelvis
        bones = np.array(
            [(j - keep, sk.parents[j] - keep) for j in range(keep + 1, sk.n_joints)], dtype=int
        ).reshape(-1, 2)
        return _Track(label, pos[:, keep:], float(item.fps), bones, facing)
    positions = getattr(item, "positions", None)
    if isinstance(positions, np.ndarray) and positions.ndim == 3 and hasattr(item, "fps"):
        names = getattr(item, "names", ())  # marker names that are body points: a stick figure
        pos = positions.astype(float)
        return _Track(label, pos, float(item.fps), figure_bones(names), None, _floor_of(pos, names))
    raise TypeError(f"cannot draw {type(item).__name__}: expected a Motion or marker positions")


#: How far below the shoulders the floor is drawn under a body of markers without legs (mm):
#: a standing adult's shoulder height (about 0.82 of a 1.75 m stature).
SHOULDER_HEIGHT = 1430.0


def _floor_of(positions: np.ndarray, names: Sequence[str]) -> float | None:
    """The floor under a marker set that names shoulders but no leg points (a depth sensor's
    upper body): :data:`SHOULDER_HEIGHT` below the shoulders' median height. Its lowest
    point would put an idle hand on the floor. None for any other set (the floor is then
    its lowest point)."""
    found = find_points(names)
    if any(p in found for p in LEG_POINTS):
        return None
    shoulders = [found[p] for p in ("left_shoulder", "right_shoulder") if p in found]
    if not shoulders:
        return None
    heights = positions[:, shoulders, 1]
    if not np.isfinite(heights).any():
        return None
    return float(np.nanmedian(heights)) - SHOULDER_HEIGHT


def _tracks(items: Drawable | Sequence[Drawable], names: Sequence[str] | None) -> list[_Track]:
    seq = [items] if isinstance(items, Motion) or hasattr(items, "positions") else list(items)
    if not seq:
        raise ValueError("nothing to draw")
    if names is not None and len(names) != len(seq):
        raise ValueError(f"{len(names)} names for {len(seq)} motions")
    tracks = [_to_track(m, i, names[i] if names else None) for i, m in enumerate(seq)]
    if len(tracks) == 1 and not (names or getattr(seq[0], "name", "")):
        tracks[0] = replace(tracks[0], name="")  # one unnamed motion: no "person 1" caption
    for m, t in zip(seq, tracks, strict=True):
        if not np.isfinite(t.positions).any():  # every marker occluded throughout
            where = getattr(m, "source", "") or getattr(m, "name", "") or "motion"
            raise MotionFormatError(where, "no point is seen in any frame: nothing to draw")
    return tracks


# ------------------------------------------------------------------- camera
@dataclass(frozen=True)
class _Camera:
    """Orthographic camera: screen axes ``right``, ``up`` and the direction ``toward`` it."""

    right: np.ndarray
    up: np.ndarray
    toward: np.ndarray

    def project(self, p: np.ndarray) -> np.ndarray:
        return np.stack([p @ self.right, p @ self.up], axis=-1)

    def depth(self, p: np.ndarray) -> np.ndarray:
        return p @ self.toward


def _finite_mean(a: np.ndarray, axis: int) -> np.ndarray:
    """Mean over ``axis`` ignoring NaN (occluded markers); NaN where nothing is left."""
    ok = np.isfinite(a)
    count = ok.sum(axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, a, 0.0).sum(axis) / np.where(count, count, np.nan)


def _centre_track(t: _Track) -> np.ndarray:
    """Per-frame horizontal position (F, 2) of the pelvis (of the centroid for markers)."""
    p = t.positions[:, 0] if t.facing is not None else _finite_mean(t.positions, axis=1)
    return p[:, GROUND]


def _camera(tracks: list[_Track]) -> _Camera:
    """The view of the module docstring, from all frames of all tracks."""
    facings = [t.facing for t in tracks if t.facing is not None]
    facing = np.vstack(facings) if facings else np.zeros((0, 3))
    facing = facing[np.isfinite(facing).all(axis=1)]  # frames of a figure not yet shown: NaN
    mean_facing = facing.mean(axis=0)[GROUND] if len(facing) else np.zeros(2)
    centres = [c[np.isfinite(c).all(axis=1)] for c in map(_centre_track, tracks)]
    centred = np.vstack([c - c.mean(axis=0) for c in centres if len(c)])
    axis = mean_facing / np.linalg.norm(mean_facing) if np.linalg.norm(mean_facing) > 0.3 else None
    quarter = QUARTER_STILL
    if len(centred) > 1:
        evals, evecs = np.linalg.eigh(np.cov(centred.T))
        if np.sqrt(evals[-1]) > TRAVEL_MM:
            travel = evecs[:, -1]
            axis = travel if axis is None or travel @ axis >= 0 else -travel
            quarter = QUARTER_TRAVEL
    if axis is None:
        axis = np.array([0.0, 1.0])  # facing +Z
    forward = np.array([axis[0], 0.0, axis[1]])
    side = np.cross(forward, UP)  # the right of a person facing ``forward``
    horizontal = np.cos(quarter) * side + np.sin(quarter) * forward
    toward = np.cos(ELEVATION) * horizontal + np.sin(ELEVATION) * UP
    right = np.cross(-toward, UP)
    right /= np.linalg.norm(right)
    return _Camera(right, np.cross(right, -toward), toward)


def _grid_step(span: float) -> float:
    """A round grid spacing giving at most 12 lines over ``span`` mm."""
    for step in (100.0, 200.0, 250.0, 500.0, 1000.0, 2000.0, 5000.0):
        if span / step <= 12:
            return step
    return 10000.0


def _label_step(step: float) -> str:
    return f"{step / 1000:g} m" if step >= 1000 else f"{step / 10:g} cm"


# ------------------------------------------------------------------- panels
@dataclass
class _Panel:
    """One axes: its tracks, floor grid and projected window (centre, half size) in mm.

    The window holds every pose and shadow of its tracks; the grid reaches a
    little beyond the tracks on the floor and is cut at the window's edges.
    """

    tracks: list[int]
    grid: np.ndarray  # (L, 2, 2) projected floor lines
    step: float
    centre: np.ndarray
    half: np.ndarray
    floor: np.ndarray  # (2, 2) the floor's extent (ground axes) the tracks cover: low, high


def _floor_grid(
    floor: np.ndarray, step: float, ground: float, cam: _Camera, margin: float
) -> np.ndarray:
    """Projected floor grid lines (L, 2, 2) over ``floor`` (low, high ground coordinates)
    widened by ``margin`` mm, on ``step`` mm lines."""
    g0 = np.floor((floor[0] - margin) / step) * step
    g1 = np.ceil((floor[1] + margin) / step) * step
    xs = np.arange(g0[0], g1[0] + step / 2, step)
    zs = np.arange(g0[1], g1[1] + step / 2, step)
    lines = [[(x, ground, g0[1]), (x, ground, g1[1])] for x in xs]
    lines += [[(g0[0], ground, z), (g1[0], ground, z)] for z in zs]
    return cam.project(np.array(lines))


def _panels(
    tracks: list[_Track], groups: list[list[int]], cam: _Camera, ground: float
) -> list[_Panel]:
    clouds = []
    for group in groups:
        pts = np.concatenate([tracks[i].positions.reshape(-1, 3) for i in group])
        pts = pts[np.isfinite(pts).all(axis=1)]
        if not len(pts):
            raise ValueError("nothing visible to draw: every position is NaN")
        clouds.append(pts)
    spans = [np.ptp(pts[:, GROUND], axis=0).max() for pts in clouds]
    step = _grid_step(float(max(spans)) + 600.0)  # one grid for all panels, like the scale
    panels = []
    for group, pts in zip(groups, clouds, strict=True):
        extent = np.stack([pts[:, GROUND].min(0), pts[:, GROUND].max(0)])
        floor = pts.copy()
        floor[:, 1] = ground
        screen = np.vstack([cam.project(pts), cam.project(floor)])
        smin, smax = screen.min(0), screen.max(0)
        centre, half = (smin + smax) / 2, (smax - smin) * 0.54 + 50.0
        # room for the captions at the top and, with several people, the names at the bottom
        below = 0.12 if len(group) > 1 else 0.0
        centre[1] += (0.14 - below) / 2 * (smax[1] - smin[1])
        half[1] += (0.14 + below) / 2 * (smax[1] - smin[1])
        grid = _floor_grid(extent, step, ground, cam, 0.25 * step)
        panels.append(_Panel(group, grid, step, centre, half, extent))
    # every panel gets the same window size, so that all are at one scale
    half = np.max([p.half for p in panels], axis=0)
    ratio = np.clip(half[0] / half[1], 0.75, MAX_ASPECT)
    half = np.maximum(half, [half[1] * ratio, half[0] / ratio])
    for p in panels:
        p.half = half
    return panels


def _figure(
    n_rows: int,
    n_cols: int,
    aspect: float,
    title: str | None,
    height: float,
    max_height: float = np.inf,
    background: str = "white",
):
    """A figure of equal panels (``aspect`` = width / height) and its axes, row by row.

    Panels are ``height`` inches high unless the figure would exceed
    ``MAX_WIDTH`` or ``max_height``, in which case all shrink alike.
    """
    size, band = 13.0, TITLE_BAND if title else 0.0
    if title:  # a title wider than the figure goes onto lines of its own, at 11 pt, not 5
        width = min(height, MAX_WIDTH / n_cols / aspect, (max_height - band) / n_rows)
        fits = int(0.96 * width * aspect * n_cols * 72 / (CHAR_EM * size))
        if len(title) > fits:
            size = 11.0
            title = "\n".join(
                textwrap.wrap(title, max(12, int(fits * 13.0 / size)), break_on_hyphens=False)
            )
            band = TITLE_BAND * (1 + 0.55 * title.count("\n"))
    panel_h = min(height, MAX_WIDTH / n_cols / aspect, (max_height - band) / n_rows)
    width = panel_h * aspect * n_cols
    fig_h = panel_h * n_rows + band
    # even pixel sizes for H.264
    w_px, h_px = 2 * round(width * DPI / 2), 2 * round(fig_h * DPI / 2)
    fig = Figure(figsize=(w_px / DPI, h_px / DPI), dpi=DPI, facecolor=background)
    FigureCanvasAgg(fig)
    axes = []
    for r in range(n_rows):
        for c in range(n_cols):
            ax = fig.add_axes(
                (c / n_cols, 1 - (band + (r + 1) * panel_h) / fig_h, 1 / n_cols, panel_h / fig_h)
            )
            ax.set_axis_off()
            axes.append(ax)
    if title:
        text = fig.text(
            0.5,
            1 - band / 2 / fig_h,
            title,
            ha="center",
            va="center",
            fontsize=size,
            color="0.6" if background == POINT_LIGHT_BACKGROUND else "black",
        )
        renderer = fig.canvas.get_renderer()
        # a title wider than a narrow figure shrinks rather than being cut off (hinting makes
        # the width not quite proportional to the size: measure again)
        while (wide := text.get_window_extent(renderer).width / (0.96 * w_px)) > 1:
            text.set_fontsize(text.get_fontsize() / wide * 0.98)
    return fig, axes


def _draw_floor(
    ax, panel: _Panel, caption: str, floor: bool = True, label: bool = True
) -> LineCollection | None:
    """The panel's window, floor grid (returned) and, with ``label``, the grid's spacing, and
    its caption."""
    ax.set_xlim(panel.centre[0] - panel.half[0], panel.centre[0] + panel.half[0])
    ax.set_ylim(panel.centre[1] - panel.half[1], panel.centre[1] + panel.half[1])
    ax.set_aspect("equal", adjustable="box")
    if not floor:  # a point-light display: nothing but the points
        return None
    grid = ax.add_collection(LineCollection(panel.grid, colors="0.82", linewidths=0.8, zorder=0))
    if label:
        ax.text(0.01, 0.01, f"grid {_label_step(panel.step)}", transform=ax.transAxes, fontsize=8)
    if caption:
        ax.text(0.01, 0.985, caption, transform=ax.transAxes, va="top", fontsize=10)
    return grid


class _Actor:
    """Per-track artists (bones, joints, shadow) that move from frame to frame."""

    def __init__(self, ax, colour: str, has_bones: bool, animated: bool, label: str):
        self.shadow = Line2D(
            [], [], color="0.6", lw=3.0, alpha=SHADOW_ALPHA, solid_capstyle="round"
        )
        self.bones = Line2D([], [], color=colour, lw=2.4, solid_capstyle="round", label=label)
        self.joints = Line2D(
            [], [], color=colour, ls="none", marker="o", ms=3.2 if has_bones else 4.5, label=label
        )
        for a in (self.shadow, self.bones, self.joints):
            a.set_animated(animated)
            ax.add_line(a)

    def fade(self, faded: bool) -> None:
        """Draw faded (a motion that is over) or as made (the shadow keeps its own alpha)."""
        self.shadow.set_alpha(0.3 * SHADOW_ALPHA if faded else SHADOW_ALPHA)
        for artist in (self.bones, self.joints):
            artist.set_alpha(0.3 if faded else None)

    def set_pose(self, screen: np.ndarray, floor: np.ndarray, bones: np.ndarray) -> None:
        if len(bones):
            seg = np.full((len(bones), 3, 2), np.nan)
            seg[:, :2] = screen[bones]
            self.bones.set_data(*seg.reshape(-1, 2).T)
            seg[:, :2] = floor[bones]
            self.shadow.set_data(*seg.reshape(-1, 2).T)
        else:
            self.shadow.set_data(*floor.T)
            self.shadow.set_marker("o")
            self.shadow.set_linestyle("none")
        self.joints.set_data(*screen.T)


@dataclass
class _Stage:
    """Everything needed to draw any time of the clip."""

    tracks: list[_Track]
    panels: list[_Panel]
    camera: _Camera
    ground: float
    point_light: bool = False

    @classmethod
    def build(
        cls,
        tracks: list[_Track],
        side_by_side: bool,
        end: float,
        point_light: bool = False,
        framed: list[_Track] | None = None,
    ) -> _Stage:
        """The stage of ``tracks`` from time 0 to ``end`` seconds; ``framed``: the tracks the
        view is made for (the camera is theirs; floor and window hold them and ``tracks``),
        not drawn: clips given the same ``framed`` share one view."""
        tracks = [t.until(end) for t in tracks]
        held = [t.until(end) for t in framed or ()]
        everyone = tracks + held  # floor and window: lowest and widest, whatever the order
        ground = float(
            min(
                t.floor if t.floor is not None else np.nanmin(t.positions[..., 1]) for t in everyone
            )
        )
        cam = _camera(held or tracks)  # the same for every clip given the same framed
        if side_by_side:
            return cls(tracks, _panels(tracks, [[i] for i in range(len(tracks))], cam, ground),
                       cam, ground, point_light)  # fmt: skip
        (panel,) = _panels(everyone, [list(range(len(everyone)))], cam, ground)
        panel.tracks = list(range(len(tracks)))
        return cls(tracks, [panel], cam, ground, point_light)

    @property
    def aspect(self) -> float:
        half = self.panels[0].half
        return float(half[0] / half[1])

    def caption(self, panel: _Panel) -> str:
        return self.tracks[panel.tracks[0]].name if len(panel.tracks) == 1 else ""

    def populate(
        self,
        ax,
        panel: _Panel,
        animated: bool,
        caption: bool = True,
        legend: bool = True,
        legend_at: str = "lower center",
        grid_label: bool = True,
    ) -> tuple[list[tuple[int, _Actor]], LineCollection | None]:
        """Floor and per-track artists of ``panel`` on ``ax``, optionally with names; the
        artists and the floor's grid (None without one)."""
        light = self.point_light
        grid = _draw_floor(
            ax, panel, self.caption(panel) if caption and not light else "", not light, grid_label
        )
        figs = [
            (
                i,
                _Actor(
                    ax,
                    POINT_LIGHT_COLOUR if light else COLOURS[i % len(COLOURS)],
                    len(self.tracks[i].bones) > 0 and not light,
                    animated,
                    self.tracks[i].name,
                ),
            )
            for i in panel.tracks
        ]
        for _, f in figs if light else ():
            f.shadow.set_visible(False)
            f.bones.set_visible(False)
        if legend and len(panel.tracks) > 1 and not light:
            ax.legend(  # in a row below the people (room left by _panels), not over them
                handles=[f.bones if len(self.tracks[i].bones) else f.joints for i, f in figs],
                loc=legend_at,
                # above the grid's label in the bottom left corner
                bbox_to_anchor=(0.5, 0.035) if legend_at == "lower center" else None,
                ncol=len(figs) if legend_at == "lower center" else 1,
                fontsize=8,
                framealpha=0.85,
                edgecolor="none",
                handlelength=1.2,
                columnspacing=1.0,
            )
        return figs, grid

    def pose(self, i: int, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Projected joints (T, N, 2), their shadows on the floor and depths (T,) at ``times``."""
        p = self.tracks[i].positions[self.tracks[i].frame_at(times)]
        floor = p.copy()
        floor[..., 1] = self.ground
        depth = np.nan_to_num(_finite_mean(self.camera.depth(p), axis=1))
        return self.camera.project(p), self.camera.project(floor), depth


# ---------------------------------------------------------------- rendering
def _sample_times(
    tracks: list[_Track], fps: float, max_seconds: float | None, path: Path, animated: bool = True
) -> np.ndarray:
    """The animation's frame times, refused (:class:`LimitError` naming ``path``) before any
    work when there would be more than ``MARKOVMOTION_MAX_ANIMATION_FRAMES`` of them (an
    animation; a strip, not ``animated``, draws a few of them whatever their number), or a
    GIF of more than ``MARKOVMOTION_MAX_GIF_FRAMES``."""
    if fps <= 0:
        raise ValueError(f"frame rate must be positive, got {fps}")
    end = max(t.last_time for t in tracks)
    n = int(np.floor(end * fps + 1e-9)) + 1
    if max_seconds is not None:
        if max_seconds <= 0:
            raise ValueError(f"max_seconds must be positive, got {max_seconds}")
        n = min(n, max(1, round(max_seconds * fps)))
    found = f"{n} frames: {(n - 1) / fps:.6g} s at {fps:g} fps"
    if animated and n > max_animation_frames():
        raise LimitError(f"{path}: {exceeded(MAX_ANIMATION_FRAMES, found)}")
    if path.suffix.lower() == ".gif" and n > max_gif_frames():
        raise LimitError(
            f"{path}: {exceeded(MAX_GIF_FRAMES, found)}: a GIF is held whole in memory until "
            "written; give .mp4 (streamed) or a shorter --max-seconds"
        )
    return np.arange(n) / fps


def _frames(
    stage: _Stage,
    times: np.ndarray,
    title: str | None,
    label: str,
    fps: float = 15.0,
    follow_people: bool = True,
) -> Iterator:
    """RGBA frames (H, W, 4) of ``stage`` at ``times`` (``fps`` apart), drawn by blitting;
    with ``follow_people``, a window that follows people who travel (:func:`_follow_window`),
    its path smoothed over :data:`FOLLOW_SMOOTH_S`."""
    n = len(stage.panels)
    every = {i: stage.pose(i, times) for i in range(len(stage.tracks))}  # once, for all below
    follow = _follow_window(stage, times, every) if follow_people else None
    if follow is not None:  # the window glides along its path, as much wider as that leaves it
        path = np.stack([_smooth_path(c, fps) for c in follow.centres])
        half = follow.half + np.abs(path - follow.centres).max(axis=(0, 1))
        _follow_floor(stage, half)
    aspect = stage.aspect
    rows, cols = (n, 1) if aspect > STACK_ASPECT else (1, n)  # wide views one above another
    fig, axes = _figure(rows, cols, aspect, title, PANEL_HEIGHT, MAX_HEIGHT, _background(stage))
    drawn = []
    for r, (ax, panel) in enumerate(zip(axes, stage.panels, strict=True)):
        figs, grid = stage.populate(ax, panel, animated=True)
        # below the panel's name, which may be as wide as the panel
        top = 0.985 - (0.05 if stage.caption(panel) and not stage.point_light else 0.0)
        clock = ax.text(0.99, top, "", transform=ax.transAxes, ha="right", va="top")
        clock.set_animated(True)
        clock.set_visible(not stage.point_light)
        poses = {i: every[i] for i, _ in figs}
        if follow is not None:  # the window moves: the people and the floor drawn shifted
            shift = path[r] - panel.centre
            poses = {
                i: (p[0] - shift[:, None], p[1] - shift[:, None], p[2]) for i, p in poses.items()
            }
            if grid is not None:
                grid.set_animated(True)
            grid_at = (grid, panel.grid, shift)
        else:
            grid_at = None
        drawn.append((ax, figs, clock, poses, grid_at, r == len(stage.panels) - 1))
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(_whole(canvas))
    for k in track(range(len(times)), label):
        canvas.restore_region(background)
        for ax, figs, clock, poses, grid_at, timed in drawn:
            if grid_at is not None and grid_at[0] is not None:
                grid, lines, shift = grid_at
                grid.set_segments(lines - shift[k])
                ax.draw_artist(grid)
            ended = []  # a motion that is over holds its last pose, faded, and says when it ended
            for i, f in figs:
                over = stage.tracks[i].over(times[k])
                if over:
                    ended.append(
                        f"{stage.tracks[i].name} ended at {stage.tracks[i].end_time:.1f} s"
                    )
                f.fade(over)
                f.set_pose(poses[i][0][k], poses[i][1][k], stage.tracks[i].bones)
                ax.draw_artist(f.shadow)
            for _, f in sorted(figs, key=lambda e: poses[e[0]][2][k]):  # far to near
                ax.draw_artist(f.bones)
                ax.draw_artist(f.joints)
            # the time once, in the last panel (side by side, a panel's time ran into the
            # next one's name); each panel says which of its motions ended
            clock.set_text("\n".join([f"t = {times[k]:.2f} s"] * timed + ended))
            ax.draw_artist(clock)
        yield np.array(canvas.buffer_rgba())


def _whole(canvas) -> Bbox:
    """The canvas's whole buffer, to restore between blitted frames: ``fig.bbox`` can round
    a column short (4.02 in at 100 dpi is 401.99... px), and the last column then kept every
    frame's pixels, a stray line at the right edge of a video."""
    return Bbox.from_bounds(0, 0, *canvas.get_width_height())


def _write_gif(frames: Iterator[np.ndarray], path: Path, fps: float) -> None:
    from PIL import Image

    images = []
    palette = None
    for f in frames:
        im = Image.fromarray(f[..., :3])
        if palette is None:
            palette = im.quantize(colors=255, method=Image.Quantize.MEDIANCUT)
        images.append(im.quantize(palette=palette, dither=Image.Dither.NONE))
    with atomic_write(path, "wb") as fh:
        images[0].save(
            fh,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=gif_durations(len(images), fps).tolist(),
            loop=0,
        )


def gif_durations(n_frames: int, fps: float) -> np.ndarray:
    """Per-frame GIF delays (ms): GIF stores centiseconds, so the frames' end times are rounded
    to 10 ms cumulatively and the animation keeps ``fps`` on average (15 fps: 70, 60, 70 ...)."""
    ends = np.round(np.arange(1, n_frames + 1) * 100.0 / fps) * 10
    return np.diff(ends, prepend=0.0).astype(int)


def render(
    items: Drawable | Sequence[Drawable],
    path: str | os.PathLike[str],
    *,
    side_by_side: bool = False,
    fps: float = 15.0,
    max_seconds: float | None = None,
    title: str | None = None,
    names: Sequence[str] | None = None,
    strip_frames: int = 6,
    point_light: bool = False,
    framed: Drawable | Sequence[Drawable] | None = None,
) -> Path:
    """Animate motions (or marker clouds) to ``path``: ``.gif``, ``.mp4`` or a ``.png`` strip.

    Args:
        items: one motion or several; several share one scene (the partners of
            a two-person take, in their common coordinate frame) unless
            ``side_by_side``, which gives one panel each at the same scale.
        path: the output; ``.png`` draws ``strip_frames`` evenly spaced frames
            of the clip as in :func:`render_frames`.
        fps: frames per second of the animation, whatever the motions' rates
            (each shows its frame nearest in time; a finished one holds its last pose).
        max_seconds: render at most this much from the start.
        title: text above the picture.
        names: one label per item (default: each item's ``name``).
        point_light: Johansson's display: white points on black, no bones, floor, names or
            clock (give marker clouds, e.g. :func:`markovmotion.viz.point_light.point_lights`).
        framed: motions the view also holds, not drawn (animations, one scene): several
            clips rendered with the same ``framed`` share one camera and one frame size, as
            the real and generated versions of a take in an observer study must (a clip's
            size had told them apart).

    Returns the path written (atomically).
    """
    path = Path(path)
    suffix = check_output(path)
    tracks = _tracks(items, names)
    times = _sample_times(tracks, fps, max_seconds, path, animated=suffix != ".png")
    end = max(t.last_time for t in tracks)
    if title and times[-1] < end - 1.0 / fps:  # cut by max_seconds: say so
        title = f"{title} (first {times[-1]:.3g} s of {end:.3g} s)"
    if suffix == ".png":
        picks = np.unique(np.rint(np.linspace(0, times[-1], strip_frames) * tracks[0].fps))
        return _strip(tracks, picks / tracks[0].fps, path, side_by_side, title, point_light)
    extra = _tracks(framed, None) if framed is not None else None
    stage = _Stage.build(tracks, side_by_side, times[-1], point_light, extra)
    # clips given one frame keep its one fixed view (a window following each clip's own
    # people would size them apart again)
    frames = _frames(stage, times, title, f"rendering {path.name}", fps, framed is None)
    (_write_gif if suffix == ".gif" else write_mp4)(frames, path, fps)
    return path


def render_continuation(
    motion: Drawable,
    start: int,
    path: str | os.PathLike[str],
    seconds_before: float = 5.0,
    title: str | None = None,
) -> Path:
    """A prediction drawn as one: the last ``seconds_before`` of what was observed (frames
    before ``start``), then the continuation from frame ``start`` on in a colour of its own,
    the observed figure left faded where it ended (``vlmm predict --animation``; the BVH of
    observed and predicted frames together does not say where the prediction starts)."""
    if not 0 < start <= motion.n_frames:
        raise ValueError(f"the prediction's first frame must be in 1..{motion.n_frames}")
    first = max(0, start - int(round(seconds_before * motion.fps)))
    clip = motion.trim(first, motion.n_frames)
    k = start - first
    observed, predicted = clip.trim(0, k), clip.copy()
    # the predicted figure appears where the observation ends: its frames before are unseen
    if isinstance(predicted, Motion):
        predicted.rotations[: k - 1] = np.nan
        predicted.translations[: k - 1] = np.nan  # the root's place too
    else:
        predicted.positions[: k - 1] = np.nan
    return render([observed, predicted], path, title=title, names=["observed", "predicted"])


def render_frames(
    items: Drawable | Sequence[Drawable],
    frames: Sequence[int],
    path: str | os.PathLike[str],
    *,
    side_by_side: bool = False,
    title: str | None = None,
    names: Sequence[str] | None = None,
) -> Path:
    """A PNG strip of the given frames (numbered at the first item's rate), in reading order.

    Each panel shows every item at that time, or with ``side_by_side`` one
    panel per item stacked under each other; one camera for all panels. Wide
    views wrap onto several rows.
    """
    tracks = _tracks(items, names)
    if len(frames) == 0:
        raise ValueError("no frames to draw")
    times = np.asarray(frames, dtype=float) / tracks[0].fps
    return _strip(tracks, times, Path(path), side_by_side, title)


def _background(stage: _Stage) -> str:
    return POINT_LIGHT_BACKGROUND if stage.point_light else "white"


#: An animation's following window moves along its path averaged over this long (s), so
#: that it glides rather than shaking with every swing of an arm.
FOLLOW_SMOOTH_S = 1.0


def _follow_floor(stage: _Stage, half: np.ndarray) -> None:
    """Give every panel the window ``half`` that follows its people, and a floor grid that
    reaches as far as that window does wherever it goes (depth is foreshortened)."""
    reach = float(half.max()) / np.sin(ELEVATION)
    for panel in stage.panels:
        panel.half = half
        panel.grid = _floor_grid(panel.floor, panel.step, stage.ground, stage.camera, reach)


def _smooth_path(centres: np.ndarray, fps: float) -> np.ndarray:
    """Window centres (T, 2) averaged over :data:`FOLLOW_SMOOTH_S` (ends held)."""
    from scipy.ndimage import uniform_filter1d

    size = max(1, int(round(FOLLOW_SMOOTH_S * fps)))
    return uniform_filter1d(centres, size, axis=0, mode="nearest")


#: A strip's or an animation's window follows the people when the clip's window is wider than this many times
#: the window one frame of them needs (a walk across a room: :func:`_follow_window`).
FOLLOW_RATIO = 2.0


@dataclass
class _Follow:
    """A window that follows the people: its half size (2,) and, per panel, its centre at
    each time (P, T, 2), in screen mm."""

    half: np.ndarray
    centres: np.ndarray


def _follow_window(
    stage: _Stage, times: np.ndarray, poses: dict[int, tuple] | None = None
) -> _Follow | None:
    """A window that holds every panel's people (and shadows) at any one of ``times``, and
    where it is at each, when the panels' windows are :data:`FOLLOW_RATIO` times wider than
    it (the people travel: a 10 m walk left each person about 70 pixels tall); else None.
    ``poses``: each track's :meth:`_Stage.pose` at ``times``, if already computed."""
    poses = poses or {i: stage.pose(i, times) for i in range(len(stage.tracks))}
    half = np.zeros(2)
    centres = []
    for panel in stage.panels:
        pts = np.concatenate(
            [np.concatenate(poses[i][:2], axis=1) for i in panel.tracks], axis=1
        )  # (T, M, 2): every track's joints and shadows
        with warnings.catch_warnings():  # a time with nothing shown (every point NaN)
            warnings.simplefilter("ignore", RuntimeWarning)
            lo, hi = np.nanmin(pts, axis=1), np.nanmax(pts, axis=1)
        seen = np.isfinite(lo).all(axis=1)
        if seen.any():
            half = np.maximum(half, ((hi - lo)[seen] * 0.54 + 50.0).max(axis=0))
        mid = np.where(seen[:, None], (lo + hi) / 2, panel.centre)
        centres.append(mid)
    if not half.all() or stage.panels[0].half[0] < FOLLOW_RATIO * half[0]:
        return None
    half[1] *= 1.14  # room for the captions at the top
    ratio = np.clip(half[0] / half[1], 0.75, MAX_ASPECT)
    half = np.maximum(half, [half[1] * ratio, half[0] / ratio])
    centres = np.stack(centres)
    centres[..., 1] += 0.07 * half[1]  # room for the captions, as _panels leaves
    return _Follow(half, centres)


def _strip(
    tracks: list[_Track],
    times: np.ndarray,
    path: Path,
    side_by_side: bool,
    title: str | None,
    point_light: bool = False,
) -> Path:
    stage = _Stage.build(tracks, side_by_side, times.max(), point_light)
    follow = _follow_window(stage, times)
    if follow is not None:
        _follow_floor(stage, follow.half)
    aspect = stage.aspect
    height = PANEL_HEIGHT * 0.6
    most = int(np.clip(MAX_WIDTH // (height * aspect), 1, len(times)))
    wraps = -(-len(times) // most)
    cols = -(-len(times) // wraps)  # rows as full as possible
    n_panels = len(stage.panels)
    fig, axes = _figure(wraps * n_panels, cols, aspect, title, height, np.inf, _background(stage))
    for r, panel in enumerate(stage.panels):
        for c, t in enumerate(times):
            ax = axes[((c // cols) * n_panels + r) * cols + c % cols]
            first = c % cols == 0  # names and the grid's spacing once per row
            figs, _ = stage.populate(
                ax, panel, False, caption=first, legend=c == 0, legend_at="upper right",
                grid_label=first,
            )  # fmt: skip
            if len(times) > 1 and not point_light:  # each cell framed: times apart
                ax.add_patch(
                    Rectangle((0, 0), 1, 1, transform=ax.transAxes, fill=False,
                              edgecolor="0.8", linewidth=0.8)
                )  # fmt: skip
            for i, f in figs:
                screen, floor, _ = stage.pose(i, np.array([t]))
                f.set_pose(screen[0], floor[0], stage.tracks[i].bones)
                f.fade(stage.tracks[i].over(t))  # over: its last pose, faded
            if follow is not None:  # this cell's window on the people at this time
                mid, half = follow.centres[r, c], follow.half
                ax.set_xlim(mid[0] - half[0], mid[0] + half[0])
                ax.set_ylim(mid[1] - half[1], mid[1] + half[1])
            over = [stage.tracks[i].name for i in panel.tracks if stage.tracks[i].over(t)]
            # bottom right: the top left holds the name caption, which a narrow panel overlaps
            # (the legend goes top right in a strip: at the bottom it covered the first time)
            if not point_light:
                ax.text(
                    0.99, 0.015, "\n".join([*(f"{n} ended" for n in over), f"t = {t:.2f} s"]),
                    transform=ax.transAxes, ha="right", va="bottom",
                )  # fmt: skip
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=DPI)
    return path

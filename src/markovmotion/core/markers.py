"""Markers: labelled 3-D marker trajectories (what a C3D file holds), in mm, Y up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markovmotion.core.words import bare_name, first_names


@dataclass(eq=False, repr=False)
class Markers:
    """Positions of named markers over frames.

    Attributes:
        names: marker labels.
        positions: (F, M, 3) in mm, Y up; NaN where a marker was not seen.
        fps: frames per second.
        name: where it came from (file name), for messages.
        source: the path it was read from, if any (what a model records it trained on).
    """

    names: tuple[str, ...]
    positions: np.ndarray
    fps: float
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        self.names = tuple(self.names)
        self.positions = np.asarray(self.positions, dtype=float)
        if self.positions.ndim != 3 or self.positions.shape[2] != 3:
            raise ValueError("positions must be (F, M, 3)")
        if self.positions.shape[1] != len(self.names):
            raise ValueError(
                f"{self.positions.shape[1]} markers in the data but {len(self.names)} names"
            )
        if np.isinf(self.positions).any():
            raise ValueError("marker positions must be finite or NaN (occluded)")
        if not self.fps > 0:
            raise ValueError(f"frame rate must be positive, got {self.fps}")

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        return self.positions.shape[1]

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.n_frames / self.fps

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        """One short line (the positions would print every frame): frames, markers, rate,
        name."""
        frames = f"{self.n_frames} frame{'' if self.n_frames == 1 else 's'}"
        return f"Markers({frames}, {self.n_markers} markers, {self.fps:g} fps" + (
            f", {self.name!r})" if self.name else ")"
        )

    def copy(self) -> Markers:
        """A deep copy."""
        return Markers(self.names, self.positions.copy(), self.fps, self.name, self.source)

    def trim(self, start: int = 0, stop: int | None = None) -> Markers:
        """Frames ``start:stop`` as new markers."""
        pos = self.positions[start:stop].copy()
        return Markers(self.names, pos, self.fps, self.name, self.source)

    def select(self, names: tuple[str, ...] | list[str]) -> Markers:
        """Only the markers ``names``, in that order, under those names (matched as
        :func:`find_markers` does; KeyError naming those not found)."""
        idx, missing = find_markers(self.names, names)
        if missing:
            raise KeyError(f"markers not found: {', '.join(missing)}")
        return Markers(tuple(names), self.positions[:, idx], self.fps, self.name, self.source)

    def has(self, names: tuple[str, ...] | list[str]) -> bool:
        """Whether every one of ``names`` is among the markers (:func:`find_markers`)."""
        return not find_markers(self.names, names)[1]

    def resample(self, fps: float) -> Markers:
        """The same trajectories sampled at ``fps`` (linear; a new sample next to an unseen
        one is unseen, NaN)."""
        from markovmotion.limits import check_rate

        fps = check_rate(fps, "resampling frame rate")
        if self.n_frames < 2 or np.isclose(fps, self.fps):
            return Markers(self.names, self.positions, float(fps), self.name, self.source)
        n = resampled_frames(self.n_frames, self.fps, fps)
        src = np.arange(n) * self.fps / fps
        lo = np.clip(np.floor(src).astype(int), 0, self.n_frames - 1)
        hi = np.minimum(lo + 1, self.n_frames - 1)
        w = (src - lo)[:, None, None]
        pos = (1 - w) * self.positions[lo] + w * self.positions[hi]
        return Markers(self.names, pos, float(fps), self.name, self.source)

    def visible(self) -> np.ndarray:
        """(F, M) whether each marker was seen in each frame."""
        return ~np.isnan(self.positions).any(axis=2)

    def never_seen(self) -> str | None:
        """``marker R_HAND never seen`` (``markers A, B and 3 more``) for the markers unseen
        in every frame, the wording of every message that names them; None if each is seen."""
        never = [self.names[m] for m in np.flatnonzero(~self.visible().any(axis=0))]
        if not never:
            return None
        return f"marker{'s' if len(never) > 1 else ''} {first_names(never, 8)} never seen"

    def summary(self) -> str:
        """A few lines for ``markovmotion info``: frames, rate, markers, occlusion, extent."""
        seen = self.visible()
        shown = ", ".join(self.names[:8]) + (" ..." if self.n_markers > 8 else "")
        rows = [
            ("frames", str(self.n_frames)),
            ("frame rate", f"{self.fps:g} fps"),
            ("duration", f"{self.duration:.2f} s"),
            ("markers", f"{self.n_markers} ({shown})"),
            ("occluded", f"{100 * (1 - seen.mean()) if seen.size else 0:.1f}% of samples"),
        ]
        if seen.any():
            pts = self.positions[seen]
            extent = pts.max(0) - pts.min(0)
            rows.append(("extent (mm)", " x ".join(f"{v:.0f}" for v in extent)))
        width = max(len(k) for k, _ in rows)
        lines = [self.name] if self.name else []
        return "\n".join(lines + [f"{k:<{width}}  {v}" for k, v in rows])


def bare_label(name: str) -> str:
    """A marker label without a subject's prefix (Vicon's ``Subject:Marker``), whatever its
    case: ``P1:R_Hand`` and ``r_hand`` are ``r_hand``."""
    return bare_name(name).strip().casefold()


def find_markers(have: tuple[str, ...], wanted: tuple[str, ...] | list[str]) -> tuple[list, list]:
    """(indices into ``have`` of each of ``wanted``, those of ``wanted`` not found). A name
    is found as it is, else by its letters whatever their case when exactly one of
    ``have`` matches so (``R_Hand`` is ``R_HAND``: capture software and people's labelling
    differ in case, and one label differing only in case would otherwise refuse a take),
    else so without a subject's prefix on either (``P1:R_HAND``, Vicon's
    ``Subject:Marker``: :func:`bare_label`) when exactly one label matches so (a model
    learnt on ``Anna:R_HAND`` finds ``Ben:R_HAND``)."""
    exact = {n: i for i, n in enumerate(have)}
    folded: dict[str, list[int]] = {}
    bare: dict[str, list[int]] = {}
    for i, n in enumerate(have):
        folded.setdefault(n.casefold(), []).append(i)
        bare.setdefault(bare_label(n), []).append(i)
    idx, missing = [], []
    for n in wanted:
        if n in exact:
            idx.append(exact[n])
        elif len(alike := folded.get(n.casefold(), [])) == 1:
            idx.append(alike[0])
        elif len(alike := bare.get(bare_label(n), [])) == 1:
            idx.append(alike[0])
        else:
            missing.append(n)
    return idx, missing


def not_found(have: tuple[str, ...] | list[str], missing: list[str] | tuple[str, ...]) -> str:
    """``markers not found: ...``, with the labels the take has (its first eight): a take
    labelled another way shows how at once."""
    return (
        f"markers not found: {', '.join(missing)} (the take has {first_names(have, 8) or 'none'})"
    )


def resampled_frames(n_frames: int, fps: float, to_fps: float) -> int:
    """How many frames ``n_frames`` at ``fps`` give at ``to_fps`` (:meth:`Markers.resample`,
    as :meth:`~markovmotion.core.motion.Motion.resample`: the same span, its last frame at
    or before the input's)."""
    if n_frames < 2 or np.isclose(fps, to_fps):
        return n_frames
    return max(1, int(np.floor((n_frames - 1) * to_fps / fps + 1e-9)) + 1)

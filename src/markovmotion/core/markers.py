"""Markers: labelled 3-D marker trajectories (what a C3D file holds), in mm, Y up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(eq=False)
class Markers:
    """Positions of named markers over frames.

    Attributes:
        names: marker labels.
        positions: (F, M, 3) in mm, Y up; NaN where a marker was not seen.
        fps: frames per second.
        name: where it came from (file name), for messages.
    """

    names: tuple[str, ...]
    positions: np.ndarray
    fps: float
    name: str = ""

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

    def visible(self) -> np.ndarray:
        """(F, M) whether each marker was seen in each frame."""
        return ~np.isnan(self.positions).any(axis=2)

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

"""Moving-window temporal smoothing."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d, uniform_filter1d

from markovmotion.features.base import FeatureStep
from markovmotion.state import register


@register
class TemporalSmoothing(FeatureStep):
    """Centred moving average over ``window`` frames (edges repeat the end frames).

    Smoothing loses information, so ``inverse_transform`` passes data through.
    """

    def __init__(self, window: int = 5):
        self.window = window

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        if self.window < 1:
            raise ValueError("window must be at least one frame")
        return [
            uniform_filter1d(np.asarray(s, dtype=float), self.window, axis=0, mode="nearest")
            for s in sequences
        ]

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s) for s in sequences]


#: Half the window of :func:`despike` (s): the median of ±0.05 s, 7 frames at 60 fps, 3 at
#: 30 fps (at least one frame either side), outvotes a glitch of up to half as many frames.
SPIKE_WINDOW_S = 0.05

#: How far (mm) a point may lie from its window's median before :func:`despike` takes it for
#: a glitch: in the collection's skeleton takes (1.7 million joint-frames of the 12 limb
#: joints, every rate) 0.01 % lie further than 122 mm from their ±0.05 s median
#: (``python3 benchmarks/spike_threshold.py``); chosen on motion capture, not on video.
SPIKE_MM = 120.0


def despike(
    points: np.ndarray,
    fps: float,
    half_window_s: float = SPIKE_WINDOW_S,
    threshold_mm: float = SPIKE_MM,
) -> tuple[np.ndarray, np.ndarray]:
    """Point trajectories (F, P, 3) mm with their glitches replaced, and where (F, P) bool.

    A Hampel filter (Hampel 1974; Pearson 2002, "Outliers in process modeling and
    identification") on each point's path: a point further than ``threshold_mm`` from the
    per-axis median of its window (``half_window_s`` either side, NaN left out) is replaced
    by that median. Smooth motion lies on its window's median (a straight path exactly), so
    the filter leaves real motion alone and takes out what a body cannot do: a wrist that
    leaves for a frame or two and comes back, as a triangulated landmark does when a view's
    detector puts it on the other arm. Written here because SciPy's ``median_filter`` has
    no NaN (a point unseen in a frame) and no distance between 3-D points."""
    pts = np.asarray(points, dtype=float)
    k = max(1, int(round(half_window_s * fps)))
    out, spiked = pts.copy(), np.zeros(pts.shape[:2], dtype=bool)
    if len(pts) < 3:
        return out, spiked
    padded = np.concatenate(
        [np.full((k, *pts.shape[1:]), np.nan), pts, np.full((k, *pts.shape[1:]), np.nan)]
    )
    chunk = max(1, 2_000_000 // max(1, pts[0].size * (2 * k + 1)))  # bounded memory
    for s in range(0, len(pts), chunk):
        e = min(len(pts), s + chunk)
        windows = np.lib.stride_tricks.sliding_window_view(padded[s : e + 2 * k], 2 * k + 1, axis=0)
        with warnings.catch_warnings():  # a window with the point unseen throughout
            warnings.simplefilter("ignore", RuntimeWarning)
            median = np.nanmedian(windows, axis=-1)
        # judged only where the window holds a majority the point is not part of: with two
        # samples (a clip's edge, beside a gap) the median is their mean, half a glitch from
        # the good one, which was then replaced
        enough = np.isfinite(windows).all(axis=-2).sum(axis=-1) >= max(3, k + 2)
        far = enough & (np.linalg.norm(pts[s:e] - median, axis=-1) > threshold_mm)  # NaN: False
        out[s:e][far] = median[far]
        spiked[s:e] = far
    return out, spiked


def smooth_gaps(points: np.ndarray, sigma_frames: float) -> np.ndarray:
    """Point trajectories (F, P, 3) smoothed over time by a Gaussian of ``sigma_frames``
    frames, a point unseen in a frame (NaN) left out and left NaN.

    Normalised convolution (Knutsson and Westin 1993): SciPy's ``gaussian_filter1d`` of the
    seen values over the same filter of where they were seen, so a gap or a clip's edge
    averages what is there rather than zeros (``mode="nearest"``). ``sigma_frames`` 0 returns
    the points unchanged."""
    pts = np.asarray(points, dtype=float)
    if sigma_frames <= 0 or len(pts) < 2:
        return pts.copy()
    seen = np.isfinite(pts).all(axis=-1)
    total = gaussian_filter1d(
        np.where(seen[..., None], pts, 0.0), sigma_frames, axis=0, mode="nearest"
    )
    weight = gaussian_filter1d(seen.astype(float), sigma_frames, axis=0, mode="nearest")
    out = total / np.maximum(weight, 1e-12)[..., None]
    out[~seen] = np.nan
    return out

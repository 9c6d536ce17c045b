"""Cubic Hermite interpolation between successive configurations (VLMM paper §3.2.1, eq. 8).

A generated sequence of prototypes is a list of knots, each a configuration
``C_r`` with its time derivative ``dC_r``. Between two knots the curve is the
cubic with those end points and end tangents (tangents scaled by the segment's
time interval); sampling it at the frame rate gives a temporally regular motion.
"""

from __future__ import annotations

import numpy as np


def constant_acceleration_intervals(
    configs: np.ndarray,
    velocities: np.ndarray,
    min_interval: float = 1.0,
    max_interval: float = np.inf,
) -> np.ndarray:
    """Time intervals between successive knots under constant acceleration (eq. 8).

    ``tau_r = 2 |C_{r+1} - C_r| / (|dC_{r+1}| + |dC_r|)``, in the time unit of
    ``velocities`` (per frame: intervals in frames), clipped to
    ``[min_interval, max_interval]`` (two knots at rest would be infinitely far apart).

    Args:
        configs: (..., R, d) knot configurations.
        velocities: (..., R, d) their time derivatives.

    Returns:
        (..., R - 1) intervals.
    """
    dist = np.linalg.norm(np.diff(configs, axis=-2), axis=-1)
    speed = np.linalg.norm(velocities, axis=-1)
    mean_speed = speed[..., 1:] + speed[..., :-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(mean_speed > 0, 2.0 * dist / mean_speed, np.inf)
    return np.clip(tau, min_interval, max_interval)


def hermite_basis(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The four cubic Hermite basis functions h00, h10, h01, h11 at ``s`` in [0, 1]."""
    s2 = s * s
    s3 = s2 * s
    return 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2


def hermite_sample(
    knots: np.ndarray, tangents: np.ndarray, knot_times: np.ndarray, times: np.ndarray
) -> np.ndarray:
    """Sample the piecewise cubic Hermite curve through ``knots`` at ``times``.

    Args:
        knots: (..., R, d) configurations, R >= 2; leading axes are independent paths.
        tangents: (..., R, d) time derivatives at the knots (per unit of ``knot_times``).
        knot_times: (..., R) strictly increasing times of the knots.
        times: (S,) or (..., S) sample times; times outside the knots are clamped
            to the first or last knot.

    Returns:
        (..., S, d) samples; at a knot time the curve equals that knot and its
        derivative equals the tangent.
    """
    knots = np.asarray(knots)
    tangents = np.asarray(tangents)
    knot_times = np.asarray(knot_times, dtype=float)
    lead = knots.shape[:-2]
    r = knots.shape[-2]
    if r < 2:
        raise ValueError("Hermite interpolation needs at least two knots")
    t = np.broadcast_to(np.asarray(times, dtype=float), lead + np.shape(times)[-1:])
    t = np.clip(t, knot_times[..., :1], knot_times[..., -1:])
    # segment of each sample: number of interior knot times at or before it (one path: a
    # binary search, O(S log R); the all-pairs count made an S x R array, 1.5 TiB for a VLMM
    # routine of a day; several paths, as the chain's hypotheses, are short)
    if knot_times.ndim == 1:
        seg = np.searchsorted(knot_times[1:-1], t, side="right")
    else:
        seg = (t[..., :, None] >= knot_times[..., None, 1:-1]).sum(axis=-1)
    t0 = np.take_along_axis(knot_times, seg, axis=-1)
    t1 = np.take_along_axis(knot_times, seg + 1, axis=-1)
    tau = t1 - t0
    h00, h10, h01, h11 = hermite_basis((t - t0) / tau)
    idx = seg[..., None]

    def at(a: np.ndarray, i: np.ndarray) -> np.ndarray:
        return np.take_along_axis(a, i, axis=-2)

    out = h00[..., None] * at(knots, idx)
    out += (h10 * tau)[..., None] * at(tangents, idx)
    out += h01[..., None] * at(knots, idx + 1)
    out += (h11 * tau)[..., None] * at(tangents, idx + 1)
    return out

"""Prediction error against horizon, E_T (VLMM paper §3.2.3, eq. 9, Figs. 4 and 10).

On every frame t of every test sequence a predictor extrapolates the next
``horizon`` frames (``n_samples`` stochastic predictions: Monte Carlo); the
error of one trial at horizon T is the mean Euclidean distance, in mm, between
predicted and true joint positions at t + T. E_T is the mean over all trials
for which t + T lies in the sequence; its spread is the mean absolute
deviation (the paper's error bars).

A predictor has three methods: ``prepare(features)`` (whatever it needs per
sequence, e.g. the recognised state at each frame),
``predict_configurations(features, prepared, frames, horizon, n_samples, rng)``
-> (len(frames), n_samples, horizon, d), and ``configuration_positions(C)``
-> (M, J, 3) mm.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markovmotion.progress import progress_bar
from markovmotion.viz.plots import new_figure, save_figure

#: Horizons reported by ``vlmm evaluate`` (seconds).
REPORT_SECONDS = (0.5, 1.0, 2.0, 3.0)


def trial_errors(predicted: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Mean joint distance (..., H) between predicted (..., H, J, 3) and true (H, J, 3) positions."""
    return np.linalg.norm(predicted - truth, axis=-1).mean(axis=-1)


@dataclass
class HorizonCurve:
    """E_T (mm) for T = 1..H frames, with the mean absolute deviation and trial counts."""

    name: str
    fps: float
    mean: np.ndarray
    mad: np.ndarray
    count: np.ndarray

    @classmethod
    def from_errors(cls, name: str, fps: float, errors: np.ndarray) -> HorizonCurve:
        """From per-trial errors (n_trials, H), NaN where t + T is past the sequence (eq. 9)."""
        count = np.sum(~np.isnan(errors), axis=0)
        with np.errstate(invalid="ignore"):
            mean = np.nanmean(errors, axis=0) if len(errors) else np.full(errors.shape[1], np.nan)
            mad = np.nanmean(np.abs(errors - mean), axis=0) if len(errors) else mean
        return cls(name, fps, mean, mad, count)

    def at(self, seconds: float) -> float:
        """E_T at ``seconds`` ahead (the nearest frame)."""
        t = int(round(seconds * self.fps))
        if not 1 <= t <= len(self.mean):
            raise ValueError(f"horizon {seconds} s is outside 1..{len(self.mean)} frames")
        return float(self.mean[t - 1])


class ZeroVelocity:
    """The baseline that holds the last observed pose, over another predictor's features."""

    def __init__(self, model):
        self.model = model

    def prepare(self, features: np.ndarray) -> None:
        return None

    def predict_configurations(self, features, prepared, frames, horizon, n_samples, rng):
        c = features[np.asarray(frames), : self.model.n_dims]
        return np.broadcast_to(c[:, None, None, :], (len(c), 1, horizon, c.shape[1]))

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        return self.model.configuration_positions(configs)


def evaluate_horizon(
    predictor,
    sequences: Sequence[np.ndarray],
    horizon: int,
    fps: float,
    n_samples: int = 50,
    stride: int = 1,
    seed: int = 0,
    name: str = "",
    max_chunk_values: int = 4_000_000,
) -> HorizonCurve:
    """E_T for T = 1..``horizon`` frames on the frames ``0, stride, 2 stride, ...`` of each sequence.

    ``sequences`` are feature arrays (F, 2d) from the predictor's pipeline; the
    ground truth is the positions of their configurations.
    """
    rng = np.random.default_rng(seed)
    errors = []
    with progress_bar() as bar:
        total = sum(len(range(0, len(s) - 1, stride)) for s in sequences)
        task = bar.add_task(f"E_T {name}".strip(), total=total)
        for feats in sequences:
            d = feats.shape[1] // 2
            truth = predictor.configuration_positions(feats[:, :d])
            prepared = predictor.prepare(feats)
            frames = np.arange(0, len(feats) - 1, stride)
            chunk = max(1, max_chunk_values // (n_samples * horizon * d))
            for lo in range(0, len(frames), chunk):
                fr = frames[lo : lo + chunk]
                pred = predictor.predict_configurations(
                    feats, prepared, fr, horizon, n_samples, rng
                )
                s = pred.shape[1]
                pos = predictor.configuration_positions(pred.reshape(-1, d))
                pos = pos.reshape(len(fr), s, horizon, *pos.shape[1:])
                err = np.full((len(fr), s, horizon), np.nan, dtype=np.float32)
                for i, t in enumerate(fr):
                    h = min(horizon, len(feats) - 1 - t)
                    err[i, :, :h] = trial_errors(pos[i, :, :h], truth[t + 1 : t + 1 + h])
                errors.append(err.reshape(-1, horizon))
                bar.advance(task, len(fr))
    return HorizonCurve.from_errors(name, fps, np.concatenate(errors))


def plot_horizon_curves(
    curves: Sequence[HorizonCurve], path: str | os.PathLike[str], title: str = ""
) -> None:
    """E_T against horizon in seconds, error bars mean +- MAD (paper Figs. 4 and 10), as a PNG."""
    fig, ax = new_figure(7.0, 4.5)
    for k, c in enumerate(curves):
        t = np.arange(1, len(c.mean) + 1) / c.fps
        every = max(1, len(t) // 15)
        ax.errorbar(
            t, c.mean, yerr=c.mad, errorevery=(k % every, every), capsize=2, label=c.name, lw=1.4
        )
    ax.set_xlabel("prediction horizon T (s)")
    ax.set_ylabel("mean joint error E_T (mm)")
    ax.set_title(title or "Prediction error against horizon (mean ± MAD)")
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path)

"""Gait synthesis speed: MLPG against nnmnkwii, MLPG with global variance, HSMM forward-backward.

- MLPG: T = 10,000 frames x 54 static dimensions (162 observation dims), random
  means and variances, solved by ``markovmotion.algorithms.mlpg.mlpg`` (one
  compiled banded LDL' pass over all dimensions) and by
  ``nnmnkwii.paramgen.mlpg`` (Cython banded Cholesky per dimension) on the
  same input, taking turns. At the first and last two frames the delta windows
  differ (we replicate edge frames, as the training features do; nnmnkwii
  truncates the windows), so there the delta and delta-delta variances are
  made huge: the two problems are then the same and their solutions must
  agree everywhere. Our first call, which builds the band operators for this
  T and loads the compiled kernels, is reported apart.
- MLPG with global variance (eqs. 12-15) on the same input, 20 iterations.
- HSMM forward-backward (explicit durations, log space) on real neutral walks
  of Bandai dataset-2 with a model trained on them: frames per second.

    python3 benchmarks/gait_bench.py [--repeats 5] [--walks 8]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.algorithms.gaussian import log_gaussian_diag
from markovmotion.algorithms.hsmm_recursions import duration_log_pmf, forward_backward
from markovmotion.algorithms.mlpg import global_variance, mlpg, mlpg_gv
from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.models.gait.synthesizer import GaitSynthesizer

#: nnmnkwii's windows for eqs. (2) and (3): (left, right, coefficients).
WINDOWS = [
    (0, 0, np.array([1.0])),
    (1, 1, np.array([-0.5, 0.0, 0.5])),
    (2, 2, np.array([0.25, 0.0, -0.5, 0.0, 0.25])),
]


def timed(fn, *args):
    start = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - start, out


def bench_mlpg(repeats: int, t_len: int = 10_000, dims: int = 54) -> list[tuple[str, str]]:
    from nnmnkwii.paramgen import mlpg as nnmnkwii_mlpg

    rng = np.random.default_rng(0)
    means = rng.normal(size=(t_len, 3 * dims))
    variances = rng.uniform(0.1, 2.0, size=(t_len, 3 * dims))
    variances[[0, 1, -2, -1], dims:] = 1e12  # where the two edge conventions differ
    first, ours = timed(mlpg, means, variances)
    t_ours, t_ref = [], []
    for _ in range(repeats):
        t, ours = timed(mlpg, means, variances)
        t_ours.append(t)
        t, ref = timed(nnmnkwii_mlpg, means, variances, WINDOWS)
        t_ref.append(t)
    diff = np.abs(ours - ref).max()
    target = 2.0 * global_variance(ours)
    t_gv, _ = timed(mlpg_gv, means, variances, target, 0.01 * target**2)
    a, b = np.median(t_ours), np.median(t_ref)
    return [
        ("MLPG input", f"T = {t_len} frames x {dims} dims (x3 with deltas)"),
        ("markovmotion mlpg, first call", f"{first:.3f} s"),
        ("markovmotion mlpg, median", f"{a:.3f} s"),
        ("nnmnkwii.paramgen.mlpg, median", f"{b:.3f} s"),
        ("speed-up over nnmnkwii", f"{b / a:.1f}x"),
        ("largest difference from nnmnkwii", f"{diff:.1e}"),
        ("mlpg_gv (20 iterations)", f"{t_gv:.2f} s"),
    ]


def bench_forward_backward(n_walks: int, repeats: int) -> list[tuple[str, str]]:
    index = MocapIndex.load()
    train, _ = held_out_every(gait_entries(index, "normal"))
    motions = [index.load_motion(e) for e in train[:n_walks]]
    model = GaitSynthesizer(n_iter=1).fit(motions)
    data = model.walk_set(motions)
    h = model.hsmm_
    frames = sum(len(x) for x in data.obs)
    inputs = []
    for x, c in zip(data.obs, data.contexts, strict=True):
        out, dur = h.chain(c)
        log_b = log_gaussian_diag(x, h.means_, h.variances_)[:, out]
        inputs.append(
            (log_b, duration_log_pmf(h.dur_means_, h.dur_variances_, h.max_duration_)[dur])
        )
    forward_backward(*inputs[0])  # compile / load the kernel
    t_all, t_rec = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        for x, c in zip(data.obs, data.contexts, strict=True):
            h.posteriors(x, c)
        t_all.append(time.perf_counter() - start)
        start = time.perf_counter()
        for args in inputs:
            forward_backward(*args)
        t_rec.append(time.perf_counter() - start)
    t, r = float(np.median(t_all)), float(np.median(t_rec))
    states = int(np.mean([len(c) for c in data.contexts]) * h.n_states)
    return [
        (
            "forward-backward input",
            f"{n_walks} walks, {frames} frames, {data.obs[0].shape[1]} dims",
        ),
        ("chain states per walk, max duration", f"~{states}, {h.max_duration_} frames"),
        ("forward-backward recursions alone, median", f"{r:.3f} s"),
        ("forward-backward frames/s (recursions alone)", f"{frames / r:,.0f}"),
        ("E-step frames/s (emissions + recursions)", f"{frames / t:,.0f}"),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--walks", type=int, default=8)
    args = parser.parse_args()
    table = Table(title="gait synthesis benchmark")
    table.add_column("measure")
    table.add_column("value", justify="right")
    for row in bench_mlpg(args.repeats) + bench_forward_backward(args.walks, args.repeats):
        table.add_row(*row)
    Console().print(table)


if __name__ == "__main__":
    main()

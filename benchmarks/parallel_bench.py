"""EM with its E-step over chunks of sequences: one job against two, threads against processes.

- Gaussian HMM: every CMU BVH take of the collection (salsa partners, Indian
  dance, martial arts) at 30 fps, body-centred joint positions + PCA (95 %
  energy), N = 32 states (the dual HMM's default): 17 minutes of motion,
  taken ``--copies`` times over as a stand-in for hours (4: about two hours,
  120,000 frames). From one k-means start, ``--iters`` EM iterations
  (``tol=-inf``, so every run does the same work).
- HSMM: every walk of Bandai dataset-2 (seven styles) with the gait model's
  features and context-dependent step chains (a :class:`GaitSynthesizer`
  trained once with one EM iteration), then ``--iters`` more EM iterations
  (:meth:`HSMM.em`) from copies of it.

Each model is fitted with ``n_jobs=1`` (no joblib: the E-step is called
directly) and with ``n_jobs=2`` on joblib's threading and loky (process)
backends, taking turns for ``--repeats`` rounds so that load from elsewhere
spreads over all; the loky workers are started before the clock. The table
gives the median seconds, the ratio to one job, and the largest relative
difference of the log-likelihood history from one job's. Before and after,
the ceiling: how much faster two loky workers spin a pure-Python loop than
one process does (2x on two idle cores; less when other work holds a core).
BLAS runs on one
thread (threadpoolctl), as loky's workers do: on a small shared machine
OpenBLAS's threads only fight each other and the jobs.

    python3 benchmarks/parallel_bench.py [--iters 5] [--repeats 3] [--copies 4]
"""

from __future__ import annotations

import argparse
import copy
import time
from contextlib import nullcontext

import joblib
import numpy as np
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from markovmotion.data import MocapIndex
from markovmotion.data.kinds import largest_group
from markovmotion.data.walks import gait_entries
from markovmotion.features import PCA, FeaturePipeline, JointPositions
from markovmotion.models.gait.synthesizer import GaitSynthesizer
from markovmotion.models.hmm.gaussian import GaussianHMM
from markovmotion.progress import track

N_STATES, FPS = 32, 30.0
RUNS = (("1 job", None, 1), ("2 jobs, threads", "threading", 2), ("2 jobs, loky", "loky", 2))


def hmm_runner(index: MocapIndex, iters: int, copies: int):
    """The Gaussian HMM's data (described) and its fit: ``n_jobs`` -> log-likelihood history."""
    entries = [e for e in index.query(source="cmu") if e.file.startswith("cmu/bvh")]
    motions = [index.load_motion(e).resample(FPS) for e in track(entries, "CMU BVH takes")]
    # one skeleton: the collection's CMU BVH takes come on two (cgspeed's 57 joints, and the
    # 38 of the CMU 18/19 interaction takes), which one pipeline cannot read together
    keep, _ = largest_group(motions, [e.file for e in entries])
    motions = [motions[i] for i in keep]
    xs = FeaturePipeline([JointPositions(), PCA(0.95)]).fit_transform(motions)
    xs = xs * copies
    x, lengths = np.vstack(xs), [len(s) for s in xs]
    start = GaussianHMM(N_STATES, n_iter=0, random_state=0).fit(x, lengths)  # k-means only

    def fit(n_jobs: int) -> np.ndarray:
        hmm = copy.deepcopy(start).set_params(
            n_iter=iters, tol=-np.inf, init_params="", n_jobs=n_jobs
        )
        return hmm.fit(x, lengths).history_

    what = (
        f"{len(xs) // copies} takes x {copies}, {len(x):,} frames x {x.shape[1]} dims, N={N_STATES}"
    )
    return what, fit


def hsmm_runner(index: MocapIndex, iters: int):
    """The gait HSMM's data (described) and its EM: ``n_jobs`` -> log-likelihood history."""
    motions = [index.load_motion(e) for e in track(gait_entries(index), "Bandai walks")]
    model = GaitSynthesizer(n_iter=1).fit(motions)
    data = model.walk_set(motions)
    start = model.hsmm_.set_params(n_iter=iters, tol=-np.inf)

    def fit(n_jobs: int) -> np.ndarray:
        hsmm = copy.deepcopy(start).set_params(n_jobs=n_jobs)
        return hsmm.em(data.obs, data.contexts).log_likelihood_[-iters:]

    frames = sum(len(x) for x in data.obs)
    what = (
        f"{len(data.obs)} walks, {data.n_steps} steps, {frames:,} frames x "
        f"{data.obs[0].shape[1]} dims, {len(start.means_)} output densities"
    )
    return what, fit


def _spin(n: int) -> int:
    total = 0
    for i in range(n):
        total += i
    return total


def ceiling(work: int = 3_000_000) -> float:
    """Speed-up of two loky workers over one process on pure-Python work, here and now."""
    begin = time.perf_counter()
    for _ in range(4):
        _spin(work)
    serial = time.perf_counter() - begin
    begin = time.perf_counter()
    joblib.Parallel(n_jobs=2, backend="loky")(joblib.delayed(_spin)(work) for _ in range(4))
    return serial / (time.perf_counter() - begin)


def compare(fit, repeats: int) -> dict[str, tuple[float, np.ndarray]]:
    """Median seconds and log-likelihood history of each run in :data:`RUNS`, taking turns."""
    times: dict[str, list[float]] = {name: [] for name, _, _ in RUNS}
    history: dict[str, np.ndarray] = {}
    for _ in range(repeats):
        for name, backend, n_jobs in RUNS:
            with joblib.parallel_config(backend=backend) if backend else nullcontext():
                begin = time.perf_counter()
                history[name] = fit(n_jobs)
                times[name].append(time.perf_counter() - begin)
    return {name: (float(np.median(times[name])), history[name]) for name, _, _ in RUNS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=5, help="EM iterations per fit")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--copies", type=int, default=4, help="times the CMU takes are used")
    args = parser.parse_args()
    index = MocapIndex.load()
    table = Table(title=f"EM, {args.iters} iterations, E-step over chunks of sequences")
    ceilings = []
    for col in ("model and data", "run", "seconds (median)", "vs 1 job", "log-lik. rel. diff."):
        table.add_column(col, justify="left" if col in ("model and data", "run") else "right")
    with threadpool_limits(1):
        ceiling()  # loky's workers started
        ceilings.append(ceiling())
        runners = (
            lambda: hmm_runner(index, args.iters, args.copies),
            lambda: hsmm_runner(index, args.iters),
        )
        for runner in runners:
            what, fit = runner()
            fit(1)  # compiled kernels loaded before the clock, and in loky's workers
            with joblib.parallel_config(backend="loky"):
                fit(2)
            results = compare(fit, args.repeats)
            base_t, base_ll = results["1 job"]
            for name, (t, ll) in results.items():
                diff = np.max(np.abs(ll - base_ll) / np.abs(base_ll))
                table.add_row(what, name, f"{t:.2f}", f"{base_t / t:.2f}x", f"{diff:.1e}")
                what = ""
        ceilings.append(ceiling())
    table.caption = "ceiling (two processes / one) before and after: " + " and ".join(
        f"{c:.2f}x" for c in ceilings
    )
    Console(width=120).print(table)


if __name__ == "__main__":
    main()

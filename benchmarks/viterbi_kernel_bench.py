"""The windowed Viterbi kernel: ns per W·N² max-plus operation, against hmmlearn.

One window of the online decoder (dual-HMM paper §3.1, eq. 4) is a Viterbi over W = 10
frames started one-hot on the state kept from the last window. Timed on random models
(N = 64 and N = 256, log emission probabilities drawn at random), median over windows:

- ours: :func:`markovmotion.algorithms.hmm_recursions.viterbi_kernel` (max-plus swept over
  predecessors, SIMD over destinations);
- scalar: the kernel it replaced (a scan over predecessors with a branch per argmax),
  kept here as the reference it must agree with state for state;
- hmmlearn: its compiled ``_hmmc.viterbi`` on the same log probabilities (the kernel
  alone), and ``GaussianHMM.decode`` per window (emissions + Viterbi, what a windowed
  decoder built on hmmlearn would call each frame; N = 64, 11 dimensions).

All three give the same states on every window (checked, printed). BLAS on one thread.

    python3 benchmarks/viterbi_kernel_bench.py [--windows 2000]
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np
from hmmlearn import _hmmc
from hmmlearn.hmm import GaussianHMM as HmmlearnGaussianHMM
from threadpoolctl import threadpool_limits

from markovmotion.algorithms.hmm_recursions import viterbi_kernel
from markovmotion.algorithms.windowed_viterbi import one_hot_log

WINDOW = 10


@numba.njit(cache=True)
def scalar_kernel(log_startprob, log_transmat_t, log_frameprob):  # pragma: no cover - numba
    """The previous kernel (main at ab0385e): scalar scan, a branch per argmax."""
    n_t, n = log_frameprob.shape
    delta = np.empty(n)
    new = np.empty(n)
    back = np.empty((n_t, n), dtype=np.int64)
    for j in range(n):
        delta[j] = log_startprob[j] + log_frameprob[0, j]
    for t in range(1, n_t):
        for j in range(n):
            best = -np.inf
            arg = 0
            for i in range(n):
                s = delta[i] + log_transmat_t[j, i]
                if s > best:
                    best = s
                    arg = i
            back[t, j] = arg
            new[j] = best + log_frameprob[t, j]
        delta[:] = new
    path = np.empty(n_t, dtype=np.int64)
    path[n_t - 1] = np.argmax(delta)
    for t in range(n_t - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path, delta[path[n_t - 1]]


def random_transmat(rng: np.random.Generator, n: int) -> np.ndarray:
    trans = rng.random((n, n)) + np.eye(n) * 3 * n
    return trans / trans.sum(axis=1, keepdims=True)


def median_ns(fn, args_list) -> tuple[float, list]:
    out, ns = [], []
    for args in args_list:
        t0 = time.perf_counter_ns()
        out.append(fn(*args))
        ns.append(time.perf_counter_ns() - t0)
    return float(np.median(ns)), out


def bench_kernel(n: int, windows: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    trans = random_transmat(rng, n)
    log_t = np.log(trans)
    log_t_t = np.ascontiguousarray(log_t.T)
    frames = rng.normal(0.0, 5.0, (windows + WINDOW, n))
    slices = [np.ascontiguousarray(frames[w : w + WINDOW]) for w in range(windows)]
    starts = [one_hot_log(n, int(k)) for k in rng.integers(0, n, windows)]
    viterbi_kernel(starts[0], log_t, slices[0])  # load the compiled code
    scalar_kernel(starts[0], log_t_t, slices[0])
    ours_ns, ours = median_ns(
        viterbi_kernel, [(s, log_t, x) for s, x in zip(starts, slices, strict=True)]
    )
    scalar_ns, scalar = median_ns(
        scalar_kernel, [(s, log_t_t, x) for s, x in zip(starts, slices, strict=True)]
    )
    with np.errstate(divide="ignore"):  # hmmlearn takes probabilities and logs them itself
        ref_ns, ref = median_ns(
            _hmmc.viterbi, [(np.exp(s), trans, x) for s, x in zip(starts, slices, strict=True)]
        )
    ops = WINDOW * n * n
    return {
        "n": n,
        "ours_ns_op": ours_ns / ops,
        "scalar_ns_op": scalar_ns / ops,
        "hmmlearn_ns_op": ref_ns / ops,
        "ours_us": ours_ns / 1e3,
        "vs_scalar": scalar_ns / ours_ns,
        "vs_hmmlearn": ref_ns / ours_ns,
        "same_scalar": all(np.array_equal(a[0], b[0]) for a, b in zip(ours, scalar, strict=True)),
        "same_hmmlearn": all(np.array_equal(a[0], b[1]) for a, b in zip(ours, ref, strict=True)),
    }


def bench_decode(windows: int, dims: int = 11, n: int = 64, seed: int = 0) -> dict:
    """Our kernel on a window against hmmlearn's ``decode`` of the same window."""
    rng = np.random.default_rng(seed)
    ref = HmmlearnGaussianHMM(n, covariance_type="full", init_params="", params="")
    ref.transmat_ = random_transmat(rng, n)
    ref.means_ = rng.normal(0, 3, (n, dims))
    a = rng.normal(0, 0.4, (n, dims, dims))
    ref.covars_ = a @ np.swapaxes(a, 1, 2) + np.eye(dims) * 0.5
    ref.startprob_ = np.full(n, 1.0 / n)
    x = ref.sample(windows + WINDOW, random_state=seed)[0]
    log_t = np.log(ref.transmat_)
    ours_ns, theirs_ns, same = [], [], True
    previous = n // 2
    for w in range(windows):
        window = x[w : w + WINDOW]
        log_b = np.ascontiguousarray(ref._compute_log_likelihood(window))  # as our buffer
        start = one_hot_log(n, previous)
        t0 = time.perf_counter_ns()
        path, _ = viterbi_kernel(start, log_t, log_b)
        ours_ns.append(time.perf_counter_ns() - t0)
        ref.startprob_ = np.exp(start)
        t0 = time.perf_counter_ns()
        _, theirs = ref.decode(window, algorithm="viterbi")
        theirs_ns.append(time.perf_counter_ns() - t0)
        same &= bool(np.array_equal(path, theirs))
        previous = int(path[1])
    return {
        "ours_us": np.median(ours_ns) / 1e3,
        "decode_us": np.median(theirs_ns) / 1e3,
        "ratio": np.median(theirs_ns) / np.median(ours_ns),
        "same": same,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--windows", type=int, default=2000, help="windows timed per size")
    args = parser.parse_args()
    with threadpool_limits(1):
        for n in (64, 256):
            r = bench_kernel(n, args.windows)
            print(
                f"N={n:3d} W={WINDOW}: ours {r['ours_ns_op']:.3f} ns/op ({r['ours_us']:.1f} µs a "
                f"window), scalar {r['scalar_ns_op']:.3f} ns/op ({r['vs_scalar']:.1f}x ours), "
                f"hmmlearn _hmmc.viterbi {r['hmmlearn_ns_op']:.3f} ns/op "
                f"({r['vs_hmmlearn']:.1f}x ours); same states: scalar {r['same_scalar']}, "
                f"hmmlearn {r['same_hmmlearn']}"
            )
        d = bench_decode(args.windows)
        print(
            f"N=64 W={WINDOW}, 11 dims: ours {d['ours_us']:.2f} µs a window, hmmlearn decode "
            f"{d['decode_us']:.1f} µs ({d['ratio']:.0f}x ours); same states {d['same']}"
        )


if __name__ == "__main__":
    main()

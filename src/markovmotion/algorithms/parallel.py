"""Per-sequence work mapped over an existing engine: joblib, and Dask through joblib.

The E-step of EM gathers sufficient statistics that add up over independent
sequences. :func:`map_sequences` cuts the sequences into a few contiguous
chunks per worker (balanced by frames), runs the model's own E-step on each
with :class:`joblib.Parallel`, and hands the partial statistics, in order, to
a function that adds them up. ``n_jobs`` has scikit-learn's meaning: None is
one job unless a :func:`joblib.parallel_config` context says otherwise, -1 is
every core. With one job the E-step is called once on all the sequences,
without joblib, so a single-job fit costs exactly what it did before.

Dask needs no code of its own: joblib's ``"dask"`` backend sends the chunks to
a ``dask.distributed`` cluster (``pip install markovmotion[dask]``)::

    import joblib
    from dask.distributed import Client

    client = Client("scheduler-address:8786")  # or Client() for a local cluster
    with joblib.parallel_config(backend="dask"):
        model.fit(x, lengths)  # n_jobs=None: a job per cluster thread

Backend: ``prefer="threads"`` (a hint; a :func:`joblib.parallel_config`
backend overrides it), chosen by measurement (``benchmarks/parallel_bench.py``,
two shared cores): five EM iterations ran 1.58x faster on two threads and
1.46x on two loky processes for the gait HSMM (141 walks), 1.13x and 1.07x
for a Gaussian HMM (121,000 frames). Threads copy no data and start no
processes; the HSMM's forward-backward and the Gaussian quadratic forms are
compiled with ``nogil=True`` and NumPy's products release the GIL, while the
HMM recursions (:mod:`~markovmotion.algorithms.hmm_recursions`, half of a
Gaussian HMM's E-step) and its M-step still run one at a time.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
from joblib import Parallel, delayed, effective_n_jobs

R = TypeVar("R")

#: Chunks per worker: enough to even out sequences of unequal lengths, few enough
#: that dispatching a chunk costs little beside its E-step.
CHUNKS_PER_WORKER = 4

#: joblib's backend hint when no ``parallel_config`` names one (see the module docstring).
PREFER = "threads"


def chunk_bounds(sizes: Sequence[int], n_chunks: int) -> list[tuple[int, int]]:
    """At most ``n_chunks`` contiguous ranges ``(i, j)`` of items, each about the same total size."""
    cum = np.cumsum(sizes)
    targets = cum[-1] * np.arange(1, n_chunks) / n_chunks
    cuts = np.searchsorted(cum, targets) + 1
    edges = np.unique(np.concatenate([[0], cuts, [len(cum)]]))
    return [(int(i), int(j)) for i, j in zip(edges[:-1], edges[1:], strict=True)]


def map_sequences(
    function: Callable[..., R],
    combine: Callable[[list[R]], R],
    sizes: Sequence[int],
    take: Callable[[int, int], tuple],
    n_jobs: int | None = None,
) -> R:
    """``function(*take(i, j))`` over chunks of sequences, the partial results ``combine``d.

    Args:
        function: the statistics of a run of whole sequences.
        combine: the statistics of all sequences from the chunks' partials (in order).
        sizes: frames of each sequence, to balance the chunks.
        take: ``function``'s arguments for sequences ``i .. j - 1``.
        n_jobs: joblib's (module docstring); with one job, ``function(*take(0, n))``.
    """
    n_workers = effective_n_jobs(n_jobs)
    if n_workers == 1 or len(sizes) == 1:
        return function(*take(0, len(sizes)))
    bounds = chunk_bounds(sizes, CHUNKS_PER_WORKER * n_workers)
    parts = Parallel(n_jobs=n_jobs, prefer=PREFER)(
        delayed(function)(*take(i, j)) for i, j in bounds
    )
    return combine(parts)

"""The windowed Viterbi algorithm: online fixed-lag decoding (dual-HMM paper §3.1, eqs. 3-4).

After Pilu (2004): Viterbi runs on a slice of ``window`` frames; of its best
path q_1 .. q_T only q_2 is kept, and the next slice, one frame later, starts
from pi one-hot on that q_2 (eq. 4). The first slice starts from the
paper's pi one-hot on the middle state (eq. 3, ``initial="middle"``) or from
the model's own pi (``initial="prior"``); it also gives frame 0 its state q_1.

Window w covers frames w .. w + T - 1 and decides frame w + 1, so frame t is
decided when frame t + T - 2 arrives: a lag of ``window - 2`` frames (frame
0, decided with frame 1, waits ``window - 1``). When the stream ends the rest
of the last slice's path is emitted, which is what sliding on to the end
would give. With a window as long as the sequence this is standard Viterbi.
"""

from __future__ import annotations

import numpy as np

from markovmotion.algorithms.hmm_recursions import viterbi_kernel

INITIAL = ("middle", "prior")


def start_distribution(log_startprob: np.ndarray, initial: str) -> np.ndarray:
    """log pi of the first slice: one-hot on the middle state N // 2 (eq. 3), or the model's."""
    if initial not in INITIAL:
        raise ValueError(f"initial must be one of {INITIAL}, got {initial!r}")
    if initial == "prior":
        return np.asarray(log_startprob, dtype=float)
    return one_hot_log(len(log_startprob), len(log_startprob) // 2)


def leavable(transmat: np.ndarray, weight: float = 1e-3) -> np.ndarray:
    """T with every absorbing row (T_kk > 1 - ``weight``) mixed with ``weight`` of the uniform row.

    EM makes a state seen only at the end of training sequences absorbing
    (T_kk = 1: nothing ever left it). Standard Viterbi is not hurt, but the
    windowed decoder, started on such a state by eq. 3 or reset to it by
    eq. 4, would never leave it again. Other rows are kept as learnt.
    """
    out = np.array(transmat, dtype=float)
    stuck = np.diagonal(out) > 1.0 - weight
    out[stuck] = (1.0 - weight) * out[stuck] + weight / out.shape[1]
    return out


def one_hot_log(n: int, state: int) -> np.ndarray:
    """log of the distribution certain of ``state`` (0 there, -inf elsewhere)."""
    out = np.full(n, -np.inf)
    out[state] = 0.0
    return out


class WindowedViterbi:
    """Online decoder: push one frame's log emission probabilities, get the states decided.

    Args:
        log_startprob: (N,) log pi of the first slice (see :func:`start_distribution`).
        log_transmat: (N, N) log transition matrix.
        window: slice length T >= 2 (the paper's 10).

    Attributes:
        lag: frames between a frame's arrival and its state's decision (``window - 2``).
    """

    def __init__(self, log_startprob: np.ndarray, log_transmat: np.ndarray, window: int = 10):
        if window < 2:
            raise ValueError(f"the window must hold at least 2 frames, got {window}")
        self.window = int(window)
        self.lag = self.window - 2
        self._log_start = np.ascontiguousarray(log_startprob, dtype=float)
        self._log_transmat = np.ascontiguousarray(log_transmat, dtype=float)
        n = len(self._log_start)
        self._buffer = np.zeros((self.window, n))
        self._count = 0
        self._one_hot = np.full(n, -np.inf)
        self._path: np.ndarray | None = None

    def push(self, log_frameprob: np.ndarray) -> list[int]:
        """Add frame t's log b_j(o_t) (N,) and return the states decided by it (0, 1 or 2)."""
        if self._count < self.window:
            self._buffer[self._count] = log_frameprob
        else:
            self._buffer[:-1] = self._buffer[1:]
            self._buffer[-1] = log_frameprob
        self._count += 1
        if self._count < self.window:
            return []
        if self._count == self.window:
            self._path, _ = viterbi_kernel(self._log_start, self._log_transmat, self._buffer)
            return [int(self._path[0]), int(self._path[1])]
        keep = self._path[1]
        self._one_hot[:] = -np.inf
        self._one_hot[keep] = 0.0
        self._path, _ = viterbi_kernel(self._one_hot, self._log_transmat, self._buffer)
        return [int(self._path[1])]

    @property
    def path(self) -> np.ndarray | None:
        """The latest slice's best path q_1 .. q_T (None before the first full slice)."""
        return self._path

    def flush(self) -> list[int]:
        """The states of the frames still undecided at the end of the stream."""
        if self._count == 0:
            return []
        if self._count < self.window:
            path, _ = viterbi_kernel(
                self._log_start, self._log_transmat, self._buffer[: self._count]
            )
            return [int(q) for q in path]
        return [int(q) for q in self._path[2:]]


def windowed_viterbi(
    log_startprob: np.ndarray, log_transmat: np.ndarray, log_frameprob: np.ndarray, window: int = 10
) -> np.ndarray:
    """States (T,) of a whole sequence decoded by :class:`WindowedViterbi`, frame by frame."""
    decoder = WindowedViterbi(log_startprob, log_transmat, window)
    states: list[int] = []
    for row in log_frameprob:
        states.extend(decoder.push(row))
    states.extend(decoder.flush())
    return np.array(states, dtype=int)

"""Variable-length Markov models (VLMM paper §3.1, eqs. 5-7; Ron, Singer and Tishby).

Training counts every context of length 0..N that precedes a token (the prefix
tree), scores each context ``aw`` against its suffix ``w`` with the weighted
Kullback-Leibler divergence

    dH(aw, w) = P(aw) sum_a' P(a'|aw) log(P(a'|aw) / P(a'|w))           (eq. 5)

with ``P(a'|w) = v(wa') / v(w)`` (eq. 6) and ``P(w) = v(w) / v0`` (eq. 7), and
keeps a context when its gain exceeds epsilon or when a longer context below
it is kept (the prediction suffix tree). The tree becomes a probabilistic
finite-state automaton M = (Q, Sigma, delta, gamma, pi) as Ron, Singer and
Tishby build it: the states are the kept memories and every prefix of one
(without the prefixes, reading ``3 0 1`` from state ``3`` would land in
``0 1`` and forget the ``3`` the tree needs), ``gamma(q, .)`` is the next-token
distribution of the longest kept memory that ends ``q``, and ``delta(q, a)``
is the longest suffix of ``q a`` that is a state; the state after any history
is then exactly its longest suffix among the states.

Everything is done level by level on NumPy arrays of context ids, so 10**6
tokens with an alphabet of hundreds and N = 20 take seconds. One exact
shortcut: a context seen ``n`` times cannot have a descendant with a gain above
``n log(n) / v0``, so contexts with ``n log n <= epsilon v0`` are not extended.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.models.base import Component
from markovmotion.state import (
    StateError,
    check_count,
    check_distribution_rows,
    check_index,
    check_indptr,
    check_shape,
    is_fitted,
    register,
    require,
)


def _lookup(sorted_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Position of each key in ``sorted_keys``, or -1 where absent."""
    pos = np.searchsorted(sorted_keys, keys)
    pos = np.minimum(pos, len(sorted_keys) - 1)
    found = sorted_keys[pos] == keys if len(sorted_keys) else np.zeros(len(keys), dtype=bool)
    return np.where(found, pos, -1)


class _Level:
    """The contexts of one length: parent ids, extending symbol, counts, next-token counts."""

    def __init__(self, parent, symbol, count, pair_keys, pair_counts, n_symbols):
        self.keys = parent * n_symbols + symbol  # sorted: lookup of a child by (w, a)
        self.parent = parent  # id of the suffix w in the level below
        self.symbol = symbol  # the oldest token a of aw
        self.count = count  # v(aw) as a predictor (followed by a token)
        self.pair_keys = pair_keys  # sorted id * K + next token
        self.pair_counts = pair_counts
        self.n_symbols = n_symbols

    @property
    def pair_context(self) -> np.ndarray:
        return self.pair_keys // self.n_symbols

    @property
    def pair_next(self) -> np.ndarray:
        return self.pair_keys % self.n_symbols


def prediction_suffix_tree(
    sequences: Sequence[np.ndarray], n_symbols: int, max_memory: int, epsilon: float
) -> tuple[list[_Level], list[np.ndarray], np.ndarray]:
    """Prefix-tree counts to length ``max_memory`` and the pruned suffix tree (eqs. 5-7).

    Returns:
        ``(levels, kept, gains)``: per context length L the contexts seen
        (``levels[L]``), a mask of those kept in the suffix tree, and the
        gains dH of every context of length >= 1 (concatenated by level).
    """
    seqs = [np.asarray(s, dtype=np.int64) for s in sequences if len(s)]
    if not seqs:
        raise ValueError("no tokens to learn from")
    tok = np.concatenate(seqs)
    if tok.min() < 0 or tok.max() >= n_symbols:
        raise ValueError(f"tokens must lie in [0, {n_symbols})")
    k = n_symbols
    v0 = len(tok)
    starts = np.repeat(np.cumsum([0] + [len(s) for s in seqs[:-1]]), [len(s) for s in seqs])
    pos = np.arange(v0)
    threshold = epsilon * v0

    # level 0: the empty context (root) before every token
    pair_keys, pair_counts = np.unique(tok, return_counts=True)
    root = _Level(np.array([-1]), np.array([-1]), np.array([v0]), pair_keys, pair_counts, k)
    levels = [root]
    gains = [np.zeros(1)]
    ctx = np.zeros(v0, dtype=np.int64)  # context id of length L before each position
    active = np.ones(v0, dtype=bool)
    for length in range(1, max_memory + 1):
        prev = levels[-1]
        count = prev.count
        expandable = count * np.log(np.maximum(count, 1)) > threshold
        active &= pos - length >= starts
        active[active] = expandable[ctx[active]]
        if not active.any():
            break
        older = tok[pos[active] - length]
        keys, inv = np.unique(ctx[active] * k + older, return_inverse=True)
        parent, symbol = keys // k, keys % k
        new_count = np.bincount(inv, minlength=len(keys))
        pk, pc = np.unique(inv * k + tok[active], return_counts=True)
        level = _Level(parent, symbol, new_count, pk, pc, k)
        # dH(aw, w) of eq. 5: compare each next-token distribution with its parent's
        p_here = pc / new_count[level.pair_context]
        where = _lookup(prev.pair_keys, parent[level.pair_context] * k + level.pair_next)
        p_parent = prev.pair_counts[where] / count[parent[level.pair_context]]
        kl = np.bincount(level.pair_context, p_here * np.log(p_here / p_parent), len(keys))
        gains.append(new_count / v0 * kl)
        levels.append(level)
        ctx[active] = inv
    # prune bottom up: keep a context if its gain exceeds epsilon or a child is kept
    kept = [np.ones(1, dtype=bool)] + [g > epsilon for g in gains[1:]]
    for length in range(len(levels) - 1, 0, -1):
        child_parents = levels[length].parent[kept[length]]
        kept[length - 1][child_parents] = True
    return levels, kept, np.concatenate(gains[1:]) if len(gains) > 1 else np.zeros(0)


#: What a fitted VLMM holds (``check_state``).
_LEARNT = (
    "n_symbols_",
    "n_tokens_",
    "memories_",
    "memory_lengths_",
    "suffix_parents_",
    "in_suffix_tree_",
    "out_indptr_",
    "out_symbols_",
    "out_probs_",
    "next_state_",
    "start_probs_",
)


@register
class VLMM(Component):
    """A variable-length Markov model over integer tokens, as a PFSA (§3.1).

    Args:
        max_memory: N, the longest memory (context length) considered.
        epsilon: threshold on the weighted KL gain dH (eq. 5); the paper uses 1e-4.

    Learnt attributes (Q states, nnz allowed transitions):
        n_symbols_: alphabet size.
        memories_: (Q, N) each state's memory, oldest token first, right-aligned
            and padded with -1 on the left; state 0 is the empty memory (root).
        memory_lengths_: (Q,) memory length of each state.
        suffix_parents_: (Q,) the state of each memory without its oldest token.
        in_suffix_tree_: (Q,) whether the state is a kept memory (else a prefix of one).
        out_indptr_, out_symbols_, out_probs_: gamma as a CSR matrix, rows are
            states; symbols sorted within each row.
        next_state_: (nnz,) delta for each allowed (state, symbol).
        start_probs_: (Q,) pi, the relative frequency of each state after the
            first token of a training sequence.
        n_tokens_: v0, the number of training tokens.
    """

    def __init__(self, max_memory: int = 5, epsilon: float = 1e-4):
        self.max_memory = max_memory
        self.epsilon = epsilon

    # ---------------------------------------------------------------- fitting
    def fit(self, sequences: Sequence[np.ndarray], n_symbols: int | None = None) -> VLMM:
        """Learn from token sequences (ints in [0, n_symbols)); returns self."""
        if self.max_memory < 0:
            raise ValueError("max_memory must be >= 0")
        seqs = [np.asarray(s, dtype=np.int64) for s in sequences]
        k = int(
            n_symbols if n_symbols is not None else max(int(s.max()) for s in seqs if len(s)) + 1
        )
        levels, kept, _ = prediction_suffix_tree(seqs, k, self.max_memory, self.epsilon)
        self._build_automaton(levels, kept, k)
        self.n_tokens_ = int(sum(len(s) for s in seqs))
        self.n_symbols_ = k
        firsts = np.array([s[0] for s in seqs if len(s)])
        start = self.transition(np.zeros(len(firsts), dtype=np.int64), firsts)
        self.start_probs_ = np.bincount(start, minlength=self.n_states) / len(start)
        return self

    def _build_automaton(self, levels: list[_Level], kept: list[np.ndarray], k: int) -> None:
        n = self.max_memory
        # Q: the suffix-tree memories and every prefix of one, so that delta is exact
        in_q = [m.copy() for m in kept]
        drop_newest: list[np.ndarray] = [np.zeros(1, dtype=np.int64)]
        if len(levels) > 1:
            drop_newest.append(np.zeros(len(kept[1]), dtype=np.int64))  # (a)[:-1] = root
        for length in range(2, len(levels)):
            lv, below = levels[length], levels[length - 1]
            # (a w)[:-1] = a (w[:-1]): the child by a of w's own truncation
            hit = _lookup(below.keys, drop_newest[length - 1][lv.parent] * k + lv.symbol)
            drop_newest.append(hit)
        for length in range(len(levels) - 1, 0, -1):
            in_q[length - 1][drop_newest[length][in_q[length]]] = True
        state_of, offset = [], 0
        for mask in in_q:
            ids = np.full(len(mask), -1, dtype=np.int64)
            ids[mask] = offset + np.arange(mask.sum())
            offset += int(mask.sum())
            state_of.append(ids)
        q = offset
        memories = np.full((q, max(n, 1)), -1, dtype=np.int32)
        lengths = np.zeros(q, dtype=np.int64)
        parents = np.full(q, -1, dtype=np.int64)
        predictor = np.zeros(q, dtype=np.int64)  # the longest suffix-tree memory ending q
        in_tree = np.zeros(q, dtype=bool)
        rows, syms, counts = [], [], []
        for length, (level, mask) in enumerate(zip(levels, in_q, strict=True)):
            sid = state_of[length][mask]
            lengths[sid] = length
            in_tree[sid] = kept[length][mask]
            if length:
                par = state_of[length - 1][level.parent[mask]]
                parents[sid] = par
                memories[sid, -length:] = memories[par, -length:]
                memories[sid, -length] = level.symbol[mask]
                predictor[sid] = np.where(in_tree[sid], sid, predictor[par])
            pair_ok = kept[length][level.pair_context]
            rows.append(state_of[length][level.pair_context[pair_ok]])
            syms.append(level.pair_next[pair_ok])
            counts.append(level.pair_counts[pair_ok])
        rows, syms, counts = (np.concatenate(a) for a in (rows, syms, counts))
        order = np.lexsort((syms, rows))
        rows, syms, counts = rows[order], syms[order], counts[order]
        tree_ptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=q))]
        probs = counts / np.bincount(rows, counts, minlength=q)[rows]
        # each state's row of gamma is its predictor's
        sizes = np.diff(tree_ptr)[predictor]
        take = np.repeat(tree_ptr[predictor] - np.r_[0, np.cumsum(sizes)[:-1]], sizes) + np.arange(
            sizes.sum()
        )
        self.memories_ = memories[:, -n:] if n else memories[:, :0]
        self.memory_lengths_ = lengths
        self.suffix_parents_ = parents
        self.in_suffix_tree_ = in_tree
        self.out_indptr_ = np.r_[0, np.cumsum(sizes)]
        self.out_symbols_ = syms[take]
        self.out_probs_ = probs[take]
        edge_rows = np.repeat(np.arange(q), sizes)
        self.next_state_ = self._longest_suffix(edge_rows, self.out_symbols_, k)

    def _longest_suffix(self, states: np.ndarray, symbols: np.ndarray, k: int) -> np.ndarray:
        """delta(q, a): the state whose memory is the longest suffix of ``q a``."""
        cur = self._child(np.zeros(len(states), dtype=np.int64), symbols, k)
        found = cur >= 0
        cur = np.where(found, cur, 0)
        mem = self.memories_
        for j in range(1, mem.shape[1] + 1):
            older = mem[states, -j]
            go = found & (older >= 0)
            nxt = np.full(len(states), -1, dtype=np.int64)
            nxt[go] = self._child(cur[go], older[go], k)
            found = go & (nxt >= 0)
            cur = np.where(found, nxt, cur)
            if not found.any():
                break
        return cur

    def _child(self, states: np.ndarray, symbols: np.ndarray, k: int) -> np.ndarray:
        """The state whose memory is ``a`` followed by the memory of ``q``, or -1."""
        if not hasattr(self, "_child_keys"):
            q = len(self.memory_lengths_)
            oldest = self.memories_[
                np.arange(1, q), self.memories_.shape[1] - self.memory_lengths_[1:]
            ]
            keys = self.suffix_parents_[1:] * k + oldest
            order = np.argsort(keys)
            self._child_keys, self._child_ids = keys[order], np.arange(1, q)[order]
        hit = _lookup(self._child_keys, states * k + symbols)
        return np.where(hit >= 0, self._child_ids[np.maximum(hit, 0)], -1)

    def check_state(self) -> None:
        """The automaton fits together: Q states with memories of symbols in
        [0, n_symbols_) (-1 padding) no longer than their rows, suffix parents and next
        states in [0, Q), gamma a CSR matrix of symbols in range whose rows are
        distributions, start_probs_ a distribution over the states."""
        if not is_fitted(self):
            return
        require(self, *_LEARNT)
        k = check_count("n_symbols_", self.n_symbols_)
        check_count("n_tokens_", self.n_tokens_, 0)
        q = len(check_shape("memory_lengths_", self.memory_lengths_, (None,)))
        mem = check_shape("memories_", self.memories_, (q, None))
        check_index("memories_", mem, k, low=-1)
        check_index("memory_lengths_", self.memory_lengths_, mem.shape[1] + 1)
        check_shape("in_suffix_tree_", self.in_suffix_tree_, (q,))
        check_index(
            "suffix_parents_", check_shape("suffix_parents_", self.suffix_parents_, (q,))[1:], q
        )
        if q < 1 or self.suffix_parents_[0] != -1 or self.memory_lengths_[0] != 0:
            raise StateError("memories_: state 0 must be the empty memory (the root)")
        nnz = len(check_shape("out_symbols_", self.out_symbols_, (None,)))
        check_indptr("out_indptr_", self.out_indptr_, q, nnz)
        check_index("out_symbols_", self.out_symbols_, k)
        check_index("next_state_", check_shape("next_state_", self.next_state_, (nnz,)), q)
        check_distribution_rows(
            "out_probs_", check_shape("out_probs_", self.out_probs_, (nnz,)), self.out_indptr_
        )
        check_distribution_rows(
            "start_probs_", check_shape("start_probs_", self.start_probs_, (q,))
        )

    # ---------------------------------------------------------------- queries
    @property
    def n_states(self) -> int:
        return len(self.memory_lengths_)

    def memory_length_histogram(self) -> np.ndarray:
        """Number of states with each memory length 0..N (paper Fig. 3)."""
        return np.bincount(self.memory_lengths_, minlength=self.max_memory + 1)

    @property
    def symbol_probs_(self) -> np.ndarray:
        """P(a), the prior used to back off on unseen events (§3.2.2): the root's row."""
        p = np.zeros(self.n_symbols_)
        sl = slice(self.out_indptr_[0], self.out_indptr_[1])
        p[self.out_symbols_[sl]] = self.out_probs_[sl]
        return p

    def output_probs(self, state: int) -> np.ndarray:
        """gamma(q, .) as a dense (n_symbols,) distribution."""
        p = np.zeros(self.n_symbols_)
        sl = slice(self.out_indptr_[state], self.out_indptr_[state + 1])
        p[self.out_symbols_[sl]] = self.out_probs_[sl]
        return p

    def _edge(self, states: np.ndarray, symbols: np.ndarray) -> np.ndarray:
        """Index into the CSR arrays of each (state, symbol), -1 where gamma is zero."""
        if not hasattr(self, "_edge_keys"):
            rows = np.repeat(np.arange(self.n_states), np.diff(self.out_indptr_))
            self._edge_keys = rows * self.n_symbols_ + self.out_symbols_
        return _lookup(self._edge_keys, np.asarray(states) * self.n_symbols_ + np.asarray(symbols))

    def transition(self, states: np.ndarray, symbols: np.ndarray) -> np.ndarray:
        """delta(q, a) for arrays of states and symbols; unseen events (gamma(q, a) = 0)
        back off to the root and take delta(root, a) (§3.2.2)."""
        states = np.asarray(states, dtype=np.int64)
        symbols = np.asarray(symbols, dtype=np.int64)
        edge = self._edge(states, symbols)
        unseen = edge < 0
        if unseen.any():
            edge[unseen] = self._edge(np.zeros(unseen.sum(), dtype=np.int64), symbols[unseen])
        # a token never seen in training leaves the model at the root
        return np.where(edge >= 0, self.next_state_[np.maximum(edge, 0)], 0)

    def recognise(self, tokens: np.ndarray, state: int = 0) -> np.ndarray:
        """The state after each token when reading ``tokens`` from ``state`` (§3.2.2)."""
        out = np.empty(len(tokens), dtype=np.int64)
        s = np.array([state])
        for i, a in enumerate(np.asarray(tokens, dtype=np.int64)):
            s = self.transition(s, np.array([a]))
            out[i] = s[0]
        return out

    def log_likelihood(self, tokens: np.ndarray, state: int = 0) -> float:
        """log P(tokens) reading from ``state`` (default: the root), in nats.

        Each token is scored by gamma(q, a) of the state q before it; an event
        unseen in q backs off to the root's P(a), as :meth:`transition` does
        (§3.2.2), so the value is a log-likelihood of the model with its
        back-off. A token never seen in training scores ``-inf``.
        """
        tokens = np.asarray(tokens, dtype=np.int64)
        if len(tokens) == 0:
            return 0.0
        before = np.r_[state, self.recognise(tokens, state)[:-1]]
        edge = self._edge(before, tokens)
        unseen = edge < 0
        if unseen.any():
            edge[unseen] = self._edge(np.zeros(unseen.sum(), dtype=np.int64), tokens[unseen])
        probs = np.where(edge >= 0, self.out_probs_[np.maximum(edge, 0)], 0.0)
        with np.errstate(divide="ignore"):
            return float(np.log(probs).sum())

    # ------------------------------------------------------------- generation
    def step(
        self, states: np.ndarray, rng: np.random.Generator | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One traversal step from each of ``states``: ``(tokens, next_states)``.

        With ``rng`` the token is sampled from gamma(q, .) (stochastic);
        without, it is the most probable one (maximum likelihood, ties to the
        lowest token).
        """
        states = np.asarray(states, dtype=np.int64)
        if rng is None:
            if not hasattr(self, "_ml_edge"):
                rows = np.repeat(np.arange(self.n_states), np.diff(self.out_indptr_))
                order = np.lexsort((np.arange(len(rows)), -self.out_probs_, rows))
                self._ml_edge = order[self.out_indptr_[:-1]]
            edge = self._ml_edge[states]
        else:
            if not hasattr(self, "_cum"):
                # row q's cumulative probabilities shifted to (q, q + 1]: one searchsorted
                sizes = np.diff(self.out_indptr_)
                csum = np.cumsum(self.out_probs_)
                cum = csum - np.repeat(np.r_[0.0, csum][self.out_indptr_[:-1]], sizes)
                cum[self.out_indptr_[1:] - 1] = 1.0
                self._cum = np.repeat(np.arange(self.n_states), sizes) + cum
            u = states + rng.random(len(states))
            edge = np.searchsorted(self._cum, u, side="right")
            edge = np.clip(edge, self.out_indptr_[states], self.out_indptr_[states + 1] - 1)
        return self.out_symbols_[edge], self.next_state_[edge]

    def start_state(self, rng: np.random.Generator | None = None) -> int:
        """A start state: sampled from pi with ``rng``, else the most probable."""
        if rng is None:
            return int(np.argmax(self.start_probs_))
        return int(rng.choice(self.n_states, p=self.start_probs_))

    def generate(
        self, n_tokens: int, rng: np.random.Generator | None = None, state: int | None = None
    ) -> np.ndarray:
        """``n_tokens`` tokens by traversing the PFSA from ``state`` (default: a start state).

        Stochastic with ``rng``, maximum likelihood (deterministic) without (§3.2.1).
        """
        s = np.array([self.start_state(rng) if state is None else state])
        out = np.empty(n_tokens, dtype=np.int64)
        for i in range(n_tokens):
            tok, s = self.step(s, rng)
            out[i] = tok[0]
        return out

"""VLMM training speed: prefix-tree counts, KL-pruned suffix tree and automaton from 10**6 tokens.

Tokens come from a random sparse second-order source over an alphabet of 100
(every pair of tokens allows four successors), the shape of prototype
sequences; the model is N = 20, epsilon = 1e-4 (the paper's). The reference is
a straightforward dict-of-counts implementation of the same algorithm (Python
dicts of context tuples, level by level, with the same exact count bound);
the two must give the same states and transitions, then the ratio is printed.

The PyPI package ``vlmc`` (0.3) estimates variable-length Markov chains too,
but selects contexts by BCT, BIC or Peres-Shields, not by the weighted KL
threshold of Ron, Singer and Tishby used here, so it is not a like-for-like
reference; ``--vlmc`` times its BCT fit on the same tokens for scale.

    python3 benchmarks/vlmm_bench.py [--tokens 1000000] [--memory 20] [--vlmc]
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter, defaultdict

import numpy as np

from markovmotion.models.vlmm.prediction_suffix_tree import VLMM


def sparse_source(n: int, k: int, seed: int = 0) -> np.ndarray:
    """n tokens of a random second-order chain whose every context allows 4 successors."""
    rng = np.random.default_rng(seed)
    successors = rng.integers(0, k, (k, k, 4))
    cum = rng.dirichlet(np.full(4, 0.5), (k, k)).cumsum(-1)
    u = rng.random(n)
    out = np.empty(n, dtype=np.int64)
    out[:2] = 0, 1
    a, b = 0, 1
    for i in range(2, n):
        c = successors[a, b, min(int(np.searchsorted(cum[a, b], u[i])), 3)]
        out[i] = c
        a, b = b, c
    return out


def reference_vlmm(tokens: list[int], n_max: int, epsilon: float) -> dict[tuple, dict]:
    """The same VLMM with dicts: {memory: {token: (probability, next memory)}}."""
    v0 = len(tokens)
    threshold = epsilon * v0
    counts: list[dict[tuple, Counter]] = [{(): Counter(tokens)}]
    for length in range(1, n_max + 1):
        prev = counts[-1]
        expandable = {
            w for w, c in prev.items() if (n := sum(c.values())) * math.log(n) > threshold
        }
        level: dict[tuple, Counter] = defaultdict(Counter)
        for i in range(length, v0):
            ctx = tuple(tokens[i - length : i])
            if ctx[1:] in expandable:
                level[ctx][tokens[i]] += 1
        if not level:
            break
        counts.append(dict(level))
    # gains (eq. 5) and bottom-up pruning
    kept = {()}
    for length in range(len(counts) - 1, 0, -1):
        with_kept_child = {k[1:] for k in kept if len(k) == length + 1}
        for ctx, c in counts[length].items():
            n = sum(c.values())
            parent = counts[length - 1][ctx[1:]]
            n_parent = sum(parent.values())
            kl = sum(v / n * math.log((v / n) / (parent[a] / n_parent)) for a, v in c.items())
            if n / v0 * kl > epsilon or ctx in with_kept_child:
                kept.add(ctx)
    # states: memories and their prefixes; gamma from the longest memory ending a state
    states = set()
    for m in kept:
        for j in range(len(m) + 1):
            states.add(m[: len(m) - j])
    model = {}
    for s in states:
        predictor = next(s[i:] for i in range(len(s) + 1) if s[i:] in kept)
        c = counts[len(predictor)][predictor]
        n = sum(c.values())
        model[s] = {
            a: (v / n, next((s + (a,))[i:] for i in range(len(s) + 2) if (s + (a,))[i:] in states))
            for a, v in c.items()
        }
    return model


def as_dict(model: VLMM) -> dict[tuple, dict]:
    mem = model.memories_
    names = [
        tuple(int(v) for v in mem[q, mem.shape[1] - n :]) if n else ()
        for q, n in enumerate(model.memory_lengths_)
    ]
    out = {}
    for q, name in enumerate(names):
        sl = slice(model.out_indptr_[q], model.out_indptr_[q + 1])
        out[name] = {
            int(a): (float(p), names[s])
            for a, p, s in zip(
                model.out_symbols_[sl], model.out_probs_[sl], model.next_state_[sl], strict=True
            )
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tokens", type=int, default=1_000_000)
    parser.add_argument("--alphabet", type=int, default=100)
    parser.add_argument("--memory", type=int, default=20)
    parser.add_argument("--epsilon", type=float, default=1e-4)
    parser.add_argument("--vlmc", action="store_true", help="also time vlmc's BCT fit")
    args = parser.parse_args()

    tokens = sparse_source(args.tokens, args.alphabet)
    print(
        f"{args.tokens} tokens, alphabet {args.alphabet}, N = {args.memory}, eps = {args.epsilon}"
    )
    times = []
    for _ in range(3):
        start = time.perf_counter()
        model = VLMM(args.memory, args.epsilon).fit([tokens], n_symbols=args.alphabet)
        times.append(time.perf_counter() - start)
    ours = min(times)
    hist = model.memory_length_histogram()
    print(
        f"markovmotion VLMM: {ours:.2f} s (best of 3) -> {model.n_states} states, "
        f"{int(model.in_suffix_tree_.sum())} suffix-tree memories, memory lengths "
        f"{ {n: int(c) for n, c in enumerate(hist) if c} }"
    )
    start = time.perf_counter()
    ref = reference_vlmm(tokens.tolist(), args.memory, args.epsilon)
    theirs = time.perf_counter() - start
    mine = as_dict(model)
    same = mine.keys() == ref.keys() and all(
        mine[s].keys() == ref[s].keys()
        and all(
            abs(mine[s][a][0] - ref[s][a][0]) < 1e-12 and mine[s][a][1] == ref[s][a][1]
            for a in ref[s]
        )
        for s in ref
    )
    print(f"dict-of-counts reference: {theirs:.2f} s -> {len(ref)} states; identical: {same}")
    print(
        f"speed-up: {theirs / ours:.1f}x  (target: under 10 s -> {'met' if ours < 10 else 'MISSED'})"
    )
    if args.vlmc:
        import vlmc

        peer = vlmc.VLMC(alphabet_size=args.alphabet, max_depth=args.memory, method="bct", beta=0.5)
        start = time.perf_counter()
        peer.fit([tokens.tolist()])
        print(
            f"vlmc {getattr(vlmc, '__version__', '')} BCT (another selection rule): "
            f"{time.perf_counter() - start:.2f} s -> {peer.context_count} contexts"
        )


if __name__ == "__main__":
    main()

"""Nested leave-one-pair-out of the dual HMM on the CMU 18/19 interaction takes.

For each held-out pair, PCA energy and blend window are chosen by leave-one-pair-out on the
other pairs alone (standard Viterbi error over the body points), then the pair is generated
with the pick: the error of settings never chosen on the pair they are reported on
(docs/hmm.md, "Settings chosen without the held-out pair").

    python3 benchmarks/dualhmm_nested.py
"""

from __future__ import annotations

import itertools

from markovmotion.data import MocapIndex
from markovmotion.evaluate.hmm import evaluate_pair
from markovmotion.evaluate.vlmm import trial_errors
from markovmotion.models.hmm.dual import DualHMM

GRID = list(itertools.product((0.95, 0.99), (1, 9)))  # energy, blend window


def _errors(model: DualHMM, a, b):
    a, b = model._rate(a), model._rate(b)
    g = model.respond(a, "standard")
    return trial_errors(model.body_positions(g), model.body_positions(b))


def main() -> None:
    """Print each fold's pick and inner errors, and the nested errors overall."""
    idx = MocapIndex.load()
    pairs = [p for p in idx.pairs() if p[0].label in ("handshake", "pull")]
    takes = [(a.name, a.label, *idx.load_pair(a, b)) for a, b in pairs]
    std, win, n = 0.0, 0.0, 0
    for i, (name, label, a, b) in enumerate(takes):
        rest = [t for j, t in enumerate(takes) if j != i]
        inner = {}
        for energy, blend in GRID:
            total, count = 0.0, 0
            for k, (_, _, ia, ib) in enumerate(rest):
                train = [(x[2], x[3]) for j, x in enumerate(rest) if j != k]
                e = _errors(DualHMM(energy=energy, blend_window=blend).fit(train), ia, ib)
                total, count = total + e.sum(), count + len(e)
            inner[(energy, blend)] = round(total / count, 1)
        pick = min(inner, key=inner.get)
        model = DualHMM(energy=pick[0], blend_window=pick[1]).fit([(x[2], x[3]) for x in rest])
        r = evaluate_pair(model, a, b, name, label)
        std += r.errors["standard"].sum()
        win += r.errors["windowed"].sum()
        n += len(r.errors["standard"])
        print(name, "pick", pick, inner, "standard", round(r.errors["standard"].mean(), 1),
              "windowed", round(r.errors["windowed"].mean(), 1), flush=True)  # fmt: skip
    print("nested overall: standard", round(std / n, 1), "windowed", round(win / n, 1))


if __name__ == "__main__":
    main()

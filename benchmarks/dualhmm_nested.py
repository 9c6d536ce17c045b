"""Nested leave-one-pair-out of the dual HMM on the CMU 18/19 interaction takes.

For each held-out pair, settings are chosen by leave-one-pair-out on the other pairs alone,
then the pair is generated with the pick: the error of settings never chosen on the pair
they are reported on (docs/hmm.md, "Settings chosen without the held-out pair"). Two studies:

- ``energy``: PCA energy and blend window, chosen by standard-Viterbi error over the body
  points (the defaults' study);
- ``initial``: the windowed decoder's first slice, the paper's one-hot on the middle state
  (eq. 3) or the model's learnt pi, chosen by windowed-Viterbi error, on the skeleton's body
  points and on 30 virtual markers (``--markers 30``).

    python3 benchmarks/dualhmm_nested.py [energy|initial]
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Callable
from functools import partial

from markovmotion.data import MocapIndex
from markovmotion.evaluate.hmm import evaluate_pair
from markovmotion.evaluate.vlmm import trial_errors
from markovmotion.models.hmm.dual import DualHMM

ENERGY_GRID = [{"energy": e, "blend_window": b} for e, b in itertools.product((0.95, 0.99), (1, 9))]
INITIAL_GRID = [{"initial": i} for i in ("middle", "prior")]


def _errors(model: DualHMM, a, b, method: str):
    a, b = model._rate(a), model._rate(b)
    g = model.respond(a, method)
    return trial_errors(model.body_positions(g), model.body_positions(b))


def nested(
    takes: list, grid: list[dict], make: Callable[..., DualHMM], method: str
) -> tuple[float, float]:
    """Print each fold's pick and inner errors; return the nested standard and windowed
    errors over all held-out frames."""
    std, win, n = 0.0, 0.0, 0
    for i, (name, label, a, b) in enumerate(takes):
        rest = [t for j, t in enumerate(takes) if j != i]
        inner = {}
        for k_set, settings in enumerate(grid):
            total, count = 0.0, 0
            for k, (_, _, ia, ib) in enumerate(rest):
                train = [(x[2], x[3]) for j, x in enumerate(rest) if j != k]
                e = _errors(make(**settings).fit(train), ia, ib, method)
                total, count = total + e.sum(), count + len(e)
            inner[k_set] = round(total / count, 1)
        pick = grid[min(inner, key=inner.get)]
        model = make(**pick).fit([(x[2], x[3]) for x in rest])
        r = evaluate_pair(model, a, b, name, label)
        std += r.errors["standard"].sum()
        win += r.errors["windowed"].sum()
        n += len(r.errors["standard"])
        print(name, "pick", pick, {str(grid[k]): v for k, v in inner.items()},
              "standard", round(r.errors["standard"].mean(), 1),
              "windowed", round(r.errors["windowed"].mean(), 1), flush=True)  # fmt: skip
    return round(std / n, 1), round(win / n, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", nargs="?", default="energy", choices=("energy", "initial"))
    study = parser.parse_args().study
    idx = MocapIndex.load()
    pairs = [p for p in idx.pairs(kind="skeleton") if p[0].label in ("handshake", "pull")]
    takes = [(a.name, a.label, *idx.load_pair(a, b)) for a, b in pairs]
    if study == "energy":
        std, win = nested(takes, ENERGY_GRID, DualHMM, "standard")
        print(f"nested overall: standard {std} windowed {win}")
        return
    for markers in (0, 30):
        print(f"--- {'body points' if not markers else f'{markers} virtual markers'}")
        std, win = nested(takes, INITIAL_GRID, partial(DualHMM, markers=markers), "windowed")
        print(f"nested overall: standard {std} windowed {win}")


if __name__ == "__main__":
    main()

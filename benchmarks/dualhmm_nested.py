"""Nested leave-one-out of the dual HMM on the CMU 18/19 interaction takes (one pair of
people: one take at a time).

For each held-out take, settings are chosen by leave-one-out on the other takes alone
(:func:`markovmotion.evaluate.hmm.choose_settings`, as ``dualhmm crossval --choose``), then
the take is generated with the pick: the error of settings never chosen on the take they are
reported on (docs/hmm.md, "Settings chosen without the held-out pair"). Two studies:

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
import logging

import numpy as np

from markovmotion.data import MocapIndex
from markovmotion.evaluate.hmm import cross_validate
from markovmotion.evaluate.takes import take_names
from markovmotion.models.hmm.dual import DualHMM

ENERGY_GRID = [{"energy": e, "blend_window": b} for e, b in itertools.product((0.95, 0.99), (1, 9))]
INITIAL_GRID = [{"initial": i} for i in ("middle", "prior")]


def nested(takes: list, grid: list[dict], model: DualHMM, method: str) -> None:
    """Print each take's pick and inner errors, and the nested errors over all frames."""
    results, _ = cross_validate(takes, model, grid=grid, method=method)
    for r in results:
        print(r.name, "pick", r.chosen["settings"], r.chosen["inner_mm"],
              "standard", round(r.errors["standard"].mean(), 1),
              "windowed", round(r.errors["windowed"].mean(), 1), flush=True)  # fmt: skip
    std, win, mean = (
        np.concatenate([r.errors[k] for r in results])
        for k in ("standard", "windowed", "mean_pose")
    )
    print(
        f"nested overall: standard {std.mean():.1f} windowed {win.mean():.1f}, "
        f"beside the mean pose {mean.mean():.1f}"
    )


def main() -> None:
    # hmmlearn's "degenerate solution" warning, which the Gaussian HMM keeps, comes once per
    # inner EM (81 lines a run): the inner folds' small training sets are the point here
    logging.getLogger("markovmotion.models.hmm.gaussian").setLevel(logging.ERROR)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", nargs="?", default="energy", choices=("energy", "initial"))
    study = parser.parse_args().study
    idx = MocapIndex.load()
    pairs = [p for p in idx.pairs(kind="skeleton") if p[0].label in ("handshake", "pull")]
    names = take_names(pairs)
    takes = [(names[p], p[0].label, *idx.load_pair(*p)) for p in pairs]
    if study == "energy":
        nested(takes, ENERGY_GRID, DualHMM(), "standard")
        return
    for markers in (0, 30):
        print(f"--- {'body points' if not markers else f'{markers} virtual markers'}")
        nested(takes, INITIAL_GRID, DualHMM(markers=markers), "windowed")


if __name__ == "__main__":
    main()

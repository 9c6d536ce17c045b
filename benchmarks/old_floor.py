"""Run a command or a benchmark with the Gaussian HMM's variance floor as it was before issue 26,
for the before/after tables of docs/hmm.md, docs/chain.md and docs/video.md.

Before issue 26 every covariance eigenvalue of the Gaussian HMM (and of the dual HMM's B
Gaussians) was floored at 1e-3 of the training data's *mean* per-feature variance, the same
scalar for every feature. This script puts that rule in place of today's per-feature floor
(``covariance_floor``, ``max(min_covar, var_floor * Var(X[:, j]))``) and changes nothing else:
a scalar floor given to ``floor_covariances`` is the plain eigenvalue floor of before. So a
before/after pair differs only in the floor (the covariances' start, hmmlearn's since issue 26,
stays today's). ``--var-floor`` and ``min_covar`` are ignored under it. Only this process is
patched: keep ``--jobs 1`` (the default) so that EM does not run in other processes.

    python3 benchmarks/old_floor.py dualhmm crossval --labels handshake,pull --kind skeleton --json
    python3 benchmarks/old_floor.py benchmarks/tracked_partner.py
"""

from __future__ import annotations

import runpy
import sys

import numpy as np

import markovmotion.models.hmm.dual as dual
import markovmotion.models.hmm.gaussian as gaussian

OLD_FRACTION = 1e-3  # the old default var_floor, a fraction of the mean per-feature variance


def mean_variance_floor(x: np.ndarray, min_covar: float, var_floor: float) -> np.ndarray:
    """The floor before issue 26: ``1e-3 * mean_j Var(X[:, j])`` for every feature (D,)
    (absolute 1e-3 on constant input or one frame, as then)."""
    spread = float(np.var(x, axis=0).mean()) if len(x) > 1 else 0.0
    return np.full(x.shape[1], OLD_FRACTION * (spread if spread > 0 else 1.0))


def main(argv: list[str]) -> None:
    """Patch the floor where the Gaussian and dual HMMs look it up, then run ``argv``: a
    ``.py`` file as a script, else a ``markovmotion`` command line."""
    gaussian.covariance_floor = mean_variance_floor
    dual.covariance_floor = mean_variance_floor
    print(
        "variance floor: 1e-3 of the mean per-feature variance (before issue 26)", file=sys.stderr
    )
    if argv and argv[0].endswith(".py"):
        sys.argv = argv
        runpy.run_path(argv[0], run_name="__main__")
        return
    from markovmotion.cli import main as cli

    sys.argv = ["markovmotion", *argv]
    cli(argv)


if __name__ == "__main__":
    main(sys.argv[1:])

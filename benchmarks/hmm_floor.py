"""The variance floor against hmmlearn on the three cases of issue 26 (docs/hmm.md, "The
variance floor"): ours and hmmlearn 0.3.3's GaussianHMM fitted in one process on

1. hmmlearn's ``test_fit_with_priors`` data (three well-separated 3-D states, full
   covariances, 2000 frames): final log-likelihood, against the true parameters';
2. two features of standard deviation 1000 and 0.05, EM started at the true parameters:
   state accuracy;
3. hmmlearn's underflow data (N(0, 1) / N(5, 1) regimes and one frame of 10,000): regime
   accuracy.

    python3 benchmarks/hmm_floor.py [--var-floor F]
"""

from __future__ import annotations

import argparse
import logging

import numpy as np
from hmmlearn.hmm import GaussianHMM as Theirs
from sklearn.datasets import make_spd_matrix

from markovmotion.models.hmm.gaussian import GaussianHMM as Ours


def priors_case(var_floor: float) -> dict[str, float]:
    prng = np.random.RandomState(10)
    n = d = 3
    pi = prng.rand(n)
    pi /= pi.sum()
    trans = prng.rand(n, n)
    trans /= trans.sum(axis=1, keepdims=True)
    means = prng.randint(-20, 20, (n, d))
    covars = np.array([make_spd_matrix(d, random_state=prng) + 0.1 * np.eye(d) for _ in range(n)])
    truth = Theirs(n, "full", init_params="")
    truth.startprob_, truth.transmat_, truth.means_, truth.covars_ = pi, trans, 20 * means, covars
    x, _ = truth.sample(2000, random_state=prng)
    ours = Ours(n, "full", var_floor=var_floor, n_iter=20, random_state=0).fit(x)
    theirs = Theirs(n, "full", n_iter=20, random_state=0).fit(x)
    return {
        "truth": truth.score(x),
        "ours": ours.score(x),
        "hmmlearn": theirs.score(x),
        "floor_max": float(ours.covar_floor_.max()),
    }


def scales_case(var_floor: float) -> dict[str, float]:
    rng = np.random.default_rng(0)
    states = np.repeat(rng.integers(0, 2, 40), 25)
    scale = np.array([1000.0, 0.05])
    offsets = np.array([[0.0, 0.0], [-100.0, 0.3]])
    x = offsets[states] + rng.normal(size=(len(states), 2)) * scale
    out = {}
    for name, cls, extra in (("ours", Ours, {"var_floor": var_floor}), ("hmmlearn", Theirs, {})):
        m = cls(2, "full", init_params="", n_iter=20, **extra)
        m.startprob_, m.transmat_ = np.full(2, 0.5), np.array([[0.96, 0.04], [0.04, 0.96]])
        m.means_, m.covars_ = offsets, np.array([np.diag(scale**2)] * 2)
        out[name] = float((m.fit(x).predict(x) == states).mean())
    return out


def outlier_case(var_floor: float) -> dict[str, float]:
    prng = np.random.RandomState(10)
    regimes = np.repeat([0, 1, 0, 1], 100)
    x = np.concatenate([prng.normal(5.0 * r, 1, 100) for r in (0, 1, 0, 1)])
    x[40] = 10_000
    out = {}
    for name, cls, extra in (("ours", Ours, {"var_floor": var_floor}), ("hmmlearn", Theirs, {})):
        m = cls(2, "spherical", init_params="", n_iter=100, **extra)
        m.startprob_, m.transmat_ = np.array([0.0, 1.0]), np.array([[0.4, 0.6], [0.6, 0.4]])
        m.means_, m.covars_ = np.array([[0.0], [5.0]]), np.array([1.0, 1.0])
        states = m.fit(x[:, None]).predict(x[:, None])
        out[name] = float(max((states == regimes).mean(), (states != regimes).mean()))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--var-floor", type=float, default=0.0, help="ours' relative floor")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    p = priors_case(args.var_floor)
    print(
        f"1. test_fit_with_priors data, log-likelihood: ours {p['ours']:.1f}, hmmlearn "
        f"{p['hmmlearn']:.1f}, true parameters {p['truth']:.1f} (our floor <= {p['floor_max']:.3g})"
    )
    s = scales_case(args.var_floor)
    print(
        f"2. sd 1000 and 0.05, state accuracy: ours {s['ours']:.3f}, hmmlearn {s['hmmlearn']:.3f}"
    )
    o = outlier_case(args.var_floor)
    print(
        f"3. one outlier of 10,000, regime accuracy: ours {o['ours']:.3f}, hmmlearn {o['hmmlearn']:.3f}"
    )


if __name__ == "__main__":
    main()

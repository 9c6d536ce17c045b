"""Cross-validation of the VLMM's prediction settings on TRAINING takes only.

The takes ``vlmm train`` learns from (the exercise takes minus the last of each
label, :func:`~markovmotion.data.splits.held_out_last`, on one skeleton) are
split into folds (:func:`~markovmotion.data.splits.validation_folds`: fold f
validates on the f-th-from-last take of each label); for every setting a
behaviour model is trained on the rest and E_T (eq. 9, mm) measured on the
validation takes, for the VLMM, a first-order Markov model on the same
prototypes (with the same join) and zero velocity. The held-out test takes are
never read. The setting with the lowest mean E_T over 0.5, 1, 2 and 3 s (to 0.1 mm)
wins; a tie goes to the smaller lambda, then the shorter join (the nearer the paper).

    python3 benchmarks/vlmm_cv.py [--folds 3] [--samples 10] [--stride 10] \\
        [--configurations rotations,positions] [--lams 10,30,100] [--joins 0,1,2,3]
"""

from __future__ import annotations

import argparse
import copy

import numpy as np

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_last, validation_folds
from markovmotion.evaluate.vlmm import FIRST_ORDER, REPORT_SECONDS, ZeroVelocity, evaluate_horizon
from markovmotion.models.vlmm.behaviour import BehaviourModel, load_motions


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--category", default="exercise")
    ap.add_argument("--folds", type=int, default=3)
    ap.add_argument("--samples", type=int, default=10)
    ap.add_argument("--stride", type=int, default=10)
    ap.add_argument("--prototypes", type=int, default=100)
    ap.add_argument("--configurations", default="rotations,positions")
    ap.add_argument("--lams", default="10,30,100")
    ap.add_argument("--joins", default="0,1,2,3")
    args = ap.parse_args()
    index = MocapIndex.load(args.data)
    train, _ = held_out_last(index.query(category=args.category))
    fps = BehaviourModel().fps
    horizon = int(round(max(REPORT_SECONDS) * fps))
    at = np.array([int(round(s * fps)) - 1 for s in REPORT_SECONDS])
    joins = [float(v) for v in args.joins.split(",")]
    rows: dict[tuple, list[np.ndarray]] = {}
    for fold, (fit_on, validate) in enumerate(validation_folds(train, args.folds), 1):
        print(f"fold {fold}: validating on {', '.join(e.file for e in validate)}", flush=True)
        motions, other = load_motions(index, fit_on + validate, fps)
        kept = [e for e in fit_on + validate if e not in other]
        fit_motions = [m for m, e in zip(motions, kept, strict=True) if e in fit_on]
        val_motions = [m for m, e in zip(motions, kept, strict=True) if e in validate]
        for conf in args.configurations.split(","):
            for lam in (float(v) for v in args.lams.split(",")):
                model = BehaviourModel(args.prototypes, configuration=conf, lam=lam)
                model.fit(fit_motions)
                feats = model.observe(val_motions)
                first = model.with_vlmm(*FIRST_ORDER)
                zero = evaluate_horizon(ZeroVelocity(model), feats, horizon, fps, 1, args.stride)
                rows.setdefault((conf, lam, "zero velocity", 0.0), []).append(zero.mean[at])
                for join in joins:
                    for name, base in (("vlmm", model), ("first order", first)):
                        p = copy.copy(base)
                        p.join = join
                        c = evaluate_horizon(p, feats, horizon, fps, args.samples, args.stride)
                        rows.setdefault((conf, lam, name, join), []).append(c.mean[at])
    header = " ".join(f"{s:>6g}s" for s in REPORT_SECONDS)
    print(f"\n{'configuration':<13} {'lambda':>6} {'predictor':<13} {'join':>4} {header}   mean")
    best = None
    for (conf, lam, name, join), values in rows.items():
        e = np.mean(values, axis=0)
        cells = " ".join(f"{v:7.1f}" for v in e)
        print(f"{conf:<13} {lam:>6g} {name:<13} {join:>4g} {cells} {e.mean():6.1f}")
        if name == "vlmm":
            key = (round(float(e.mean()), 1), lam, join)
            if best is None or key < best[0]:
                best = (key, conf, lam, join)
    print(f"\nbest VLMM: --configuration {best[1]} --lam {best[2]:g} --join {best[3]:g}")


if __name__ == "__main__":
    main()

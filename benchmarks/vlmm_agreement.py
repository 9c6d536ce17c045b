"""How far apart the VLMM, first-order Markov and structured predictions are, and why.

For a model file from ``vlmm train`` (skeleton or markers; a structured model adds its
template predictions), on the takes the model held out: the most likely (not sampled)
continuation of every ``stride``-th frame by the prototype VLMM, a first-order Markov
model over the same prototypes and, for a structured model, the structured model, each
with the model's join and with no join (``join = 0``, the paper's). Reported per horizon:
the mean distance between two models' predictions (mm over the evaluated joints, as E_T)
and the share of frames where they differ at all (by more than 1 mm); and the share of
frames whose recognised VLMM state remembers only the current prototype (there the VLMM
and first order draw the next prototype from the same counts).

    python3 benchmarks/vlmm_agreement.py --model skel.npz [--stride 5]
"""

from __future__ import annotations

import argparse
import copy

import numpy as np

from markovmotion.data import MocapIndex
from markovmotion.evaluate.vlmm import FIRST_ORDER, REPORT_SECONDS, candidate_takes
from markovmotion.models.vlmm.structured import StructuredBehaviourModel, load_behaviour


def with_join(model, join: float):
    """A copy of ``model`` (or of a structured model with its prototype model) with ``join``."""
    if isinstance(model, StructuredBehaviourModel):
        other = copy.copy(model)
        other.prototype_model_ = with_join(model.prototype_model_, join)
        return other
    other = copy.copy(model)
    other.join = join
    return other


def predictions(predictor, base, feats: list[np.ndarray], stride: int, horizon: int):
    """(frames, horizon, J, 3) most likely predicted positions from every stride-th frame."""
    out = []
    for f in feats:
        d = f.shape[1] // 2
        frames = np.arange(0, len(f) - horizon, stride)
        pred = predictor.predict_configurations(f, predictor.prepare(f), frames, horizon, 1, None)
        pos = base.configuration_positions(pred.reshape(-1, d))
        out.append(pos.reshape(len(frames), horizon, *pos.shape[1:]))
    return np.concatenate(out)


def truths(base, feats: list[np.ndarray], stride: int, horizon: int) -> np.ndarray:
    """(frames, horizon, J, 3) the true positions after every stride-th frame."""
    out = []
    for f in feats:
        d = f.shape[1] // 2
        pos = base.configuration_positions(f[:, :d])
        frames = np.arange(0, len(f) - horizon, stride)
        out.append(np.stack([pos[t + 1 : t + 1 + horizon] for t in frames]))
    return np.concatenate(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--data", default=None)
    ap.add_argument("--stride", type=int, default=5)
    args = ap.parse_args()
    model = load_behaviour(args.model)
    base = model.prototype_model_ if isinstance(model, StructuredBehaviourModel) else model
    index = MocapIndex.load(args.data)
    entries, motions = [], []
    for e in candidate_takes(model, index, held_out=True):  # as vlmm evaluate: one skeleton
        motion = index.load_motion(e).resample(base.fps)
        if motion.skeleton.same_topology(base.skeleton_):
            entries.append(e)
            motions.append(motion)
    feats = base.observe(motions)
    horizon = int(round(max(REPORT_SECONDS) * base.fps))
    at = [int(round(s * base.fps)) - 1 for s in REPORT_SECONDS]
    states = np.concatenate([base.prepare(f) for f in feats])
    short = np.mean(base.vlmm_.memory_lengths_[states] <= 1)
    print(f"takes {', '.join(e.file for e in entries)}; join {base.join:g} s; stride {args.stride}")
    print(f"frames whose VLMM state remembers at most the current prototype: {short:.1%}")
    for join in sorted({base.join, 0.0}, reverse=True):
        b = with_join(base, join)
        preds = {
            "vlmm": predictions(b, b, feats, args.stride, horizon),
            "first_order": predictions(b.with_vlmm(*FIRST_ORDER), b, feats, args.stride, horizon),
        }
        if model is not base:
            preds["structured"] = predictions(
                with_join(model, join), b, feats, args.stride, horizon
            )
        truth = truths(b, feats, args.stride, horizon)
        errors = {k: np.linalg.norm(p - truth, axis=-1).mean(axis=-1) for k, p in preds.items()}
        print(f"\njoin {join:g} s ({len(preds['vlmm'])} predictions each)")
        print(
            "error of the most likely prediction (mm)".ljust(42)
            + "".join(f"{s:>8g} s" for s in REPORT_SECONDS)
        )
        for k, e in errors.items():
            print(f"  {k}".ljust(42) + "".join(f"{e[:, t].mean():10.1f}" for t in at))
        for k in [k for k in errors if k != "vlmm"]:
            cells = "".join(
                f"{np.mean(errors['vlmm'][:, t] < errors[k][:, t] - 1):5.0%}/"
                f"{np.mean(errors['vlmm'][:, t] > errors[k][:, t] + 1):4.0%}"
                for t in at
            )
            print(f"  vlmm closer / farther than {k} (by 1 mm)".ljust(42) + cells)
        print("pair".ljust(26) + "".join(f"{s:>8g} s mm  differ" for s in REPORT_SECONDS))
        pairs = [("vlmm", "first_order"), ("vlmm", "structured"), ("first_order", "structured")]
        for a, c in (p for p in pairs if p[1] in preds):
            dist = np.linalg.norm(preds[a] - preds[c], axis=-1).mean(axis=-1)  # (frames, T)
            cells = "".join(f"{dist[:, t].mean():12.1f} {np.mean(dist[:, t] > 1):7.0%}" for t in at)
            print(f"{a} - {c}".ljust(26) + cells)


if __name__ == "__main__":
    main()

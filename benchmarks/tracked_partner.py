"""The dual-HMM partner from tracked A against captured A (video issue, "Evaluation").

For the last take of each of the pull and handshake labels: render it by 3 cameras at 30 fps,
track A (annealed particle filter, 200 x 10), train a dual HMM on the other interaction takes
of the same people, and compare B's error (19 body points, mm) when A comes from the capture
and when it comes from the tracker. Numbers in docs/video.md.

    python3 benchmarks/tracked_partner.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from markovmotion.data import MocapIndex
from markovmotion.evaluate.vlmm import trial_errors
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.video.multiview import render_multiview, track_take, training_body_model


def main() -> None:
    """Print, per take, tracking MPJPE and B's errors from captured and from tracked A."""
    idx = MocapIndex.load()
    for label in ("pull", "handshake"):
        test = idx.pairs(label=[label], kind="skeleton")[-1]
        same = idx.pairs(kind="skeleton")
        train = [p for p in same if p[0].subject == test[0].subject and p != test]
        model = DualHMM().fit([idx.load_pair(*p) for p in train], [p[0].label for p in train])
        a, b = idx.load_pair(*test)
        a, b = a.resample(30.0), b.resample(30.0)
        with tempfile.TemporaryDirectory() as tmp:
            render_multiview(test[0].path, Path(tmp) / "v", views=3, fps=30.0)
            body = training_body_model(idx.root)
            tracked, _, summary = track_take(Path(tmp) / "v", body, truth=test[0].path)
        n = min(tracked.n_frames, a.n_frames)
        truth = model.body_positions(b.trim(0, n))
        res = {"mpjpe_mm": summary.get("mpjpe_mm"), "frames": n}
        for name, src in (("captured", a.trim(0, n)), ("tracked", tracked.trim(0, n))):
            for method in ("standard", "windowed"):
                g = model.respond(src, method)
                res[f"{name}_{method}_mm"] = round(
                    float(trial_errors(model.body_positions(g)[:n], truth).mean()), 1
                )
        print(test[0].name, res, flush=True)


if __name__ == "__main__":
    main()

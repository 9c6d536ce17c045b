"""``VirtualPartner(place_window=...)``, the chain partner's place averaged over its last
frames, measured by leaving one salsa training take out.

The eight salsa training takes of ``chain train`` (the last take of each label held out,
as ``chain train`` holds it out, never read here); each is left out in turn, a chain with
the defaults (``place_window`` 1) is trained on the other seven, and each person of the
left-out take is masked in turn. Every partner (200 hypotheses with each response, the
re-synchronised single hypothesis, the mean shape) is propagated once, and its placed
frames averaged over each window (:class:`~markovmotion.models.chain.partner.PlaceAverage`,
which is what ``respond`` does with that ``place_window``). Reported per window: the world
error (mm, the criterion), the body-centred error (unchanged by the window) and how much
the partner jumps (p90 of the median point's frame steps, the dual HMM's measure), beside
the real partner's.

    python3 benchmarks/chain_place_window.py [--data DIR] [--windows 1,5,10,20] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.evaluate.chain import jump_p90, point_error, pose_error_mm
from markovmotion.evaluate.takes import jump_sizes
from markovmotion.models.chain.partner import PlaceAverage, VirtualPartner

PARTNERS = {
    "multiple_hypotheses_ml": {"n_hypotheses": 200, "response": "ml"},
    "multiple_hypotheses_map": {"n_hypotheses": 200, "response": "map"},
    "multiple_hypotheses_mean": {"n_hypotheses": 200, "response": "mean"},
    "single_hypothesis": {"n_hypotheses": 1},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="folder with INDEX.csv")
    parser.add_argument("--windows", default="1,5,10,15,20,25,30,40")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    windows = [int(w) for w in args.windows.split(",")]
    index = MocapIndex.load(args.data)
    train, _ = held_out_pairs(index.pairs(label="salsa"))
    motions = [index.load_pair(a, b) for a, b in train]
    names = [*PARTNERS, "mean_shape"]
    world = {(k, w): 0.0 for k in names for w in windows}
    body = {(k, w): 0.0 for k in names for w in windows}
    steps: dict = {(k, w): [] for k in names for w in windows}
    real, frames = [], 0
    with threadpool_limits(1):
        for i in range(len(train)):
            model = VirtualPartner(place_window=1)
            model.fit([m for j, m in enumerate(motions) if j != i])
            take = model.two_people(*motions[i])
            for person in (0, 1):
                seen, truth = take.person(person), take.person(1 - person)
                real.append(jump_sizes(truth.points))
                frames += take.n_frames
                placed = {
                    k: model.respond_shapes(seen, person, rng=args.seed, **o).partner
                    for k, o in PARTNERS.items()
                }
                placed["mean_shape"] = model.mean_partner(seen, np.full(take.n_frames, person))
                for k, partner in placed.items():
                    for w in windows:
                        pred = PlaceAverage(w)(partner)
                        world[k, w] += point_error(pred, truth, False) * take.n_frames
                        body[k, w] += pose_error_mm(model, pred, truth) * take.n_frames
                        steps[k, w].append(jump_sizes(pred.points))
            Console(stderr=True).print(f"take {train[i][0].trial} left out", highlight=False)
    rows = {
        f"{k}, window {w}": {
            "world_mm": round(world[k, w] / frames, 1),
            "body_centred_mm": round(body[k, w] / frames, 1),
            "jump_p90_mm": jump_p90(steps[k, w]),
        }
        for k in names
        for w in windows
    }
    report = {"takes": [a.trial for a, _ in train], "frames": frames, "partners": rows,
              "real_jump_p90_mm": jump_p90(real)}  # fmt: skip
    if args.json:
        print(json.dumps(report, indent=2))
        return
    table = Table(
        title="place_window by leaving one salsa training take out (mm)",
        caption=f"{frames} partner frames; the real partner's jump p90: {report['real_jump_p90_mm']}",
    )
    for col in ("partner", "world", "body-centred", "jump p90"):
        table.add_column(col)
    for name, r in rows.items():
        table.add_row(
            name, *(f"{r[c]:.1f}" for c in ("world_mm", "body_centred_mm", "jump_p90_mm"))
        )
    Console().print(table)


if __name__ == "__main__":
    main()

"""Where a tracked frame's time goes: the stages of the annealed particle filter, one at a time.

On the held-out take of ``benchmarks/tracker_bench.py`` (3 cameras, 320x240; rendered into
``--cache`` if missing) times, in CPU milliseconds (best of ``--repeat``, so other jobs on the
shared machine inflate them less than wall time):

* ``decode``: one frame of every camera read from the videos;
* ``features``: their foreground and edge maps and the sampled foreground pixels
  (:func:`~markovmotion.video.annealed_particle_filter.view_features`);
* per weighting of ``--particles`` particles: ``kinematics`` (body points of the states),
  ``projection`` (into every camera), ``projection + costs`` (the weighting function of
  given body points), and ``score`` (all of them, as a layer calls it); ``survival beta``;
* ``frame``: a whole tracked frame (features included, the limb search too), the mean over
  the take's frames after the first.

Only public functions are called, so an older checkout runs it too (``PYTHONPATH=OLD/src``).

    python3 benchmarks/tracker_stages.py [--data DIR] [--particles 200] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.video.annealed_particle_filter import (
    AnnealedParticleFilter,
    joint_costs,
    open_video,
    project_model,
    survival_beta,
)
from markovmotion.video.multiview import BODY_LABELS, render_multiview, training_body_model


def best_ms(fn, repeat: int, number: int = 10) -> float:
    """Best CPU time of ``fn`` in ms over ``repeat`` rounds of ``number`` calls."""
    fn()
    return (
        1e3 * min(timeit.repeat(fn, number=number, repeat=repeat, timer=time.process_time)) / number
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    parser.add_argument("--particles", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "mm-tracker")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()

    index = MocapIndex.load(args.data)
    _, test = held_out_pairs(index.pairs(label=list(BODY_LABELS), kind="skeleton"))
    take = test[0][0]
    folder = args.cache / f"{Path(take.file).name.split('.')[0]}-3s"
    if not (folder / "cameras.json").is_file():
        render_multiview(take.path, folder, views=3, seconds=3.0, fps=30.0)
    body = training_body_model(args.data)

    mv = open_video(folder, views=3)
    frames = list(mv.frames)
    mid = len(frames) // 2
    t0 = time.process_time()
    list(open_video(folder, views=3).frames)
    rows = {"decode": 1e3 * (time.process_time() - t0) / len(frames)}
    rows["features"] = best_ms(lambda: mv.features_of(frames[mid], mid), args.repeat)
    feats = [mv.features_of(f, i) for i, f in enumerate(frames)]

    apf = AnnealedParticleFilter(body, mv.cameras, args.particles, 10, fps=mv.fps, seed=0)
    est, _ = apf.initialise(feats[0])
    rng = np.random.default_rng(0)
    x = body.clip(est + rng.normal(size=(args.particles, body.n_dof)) * apf.step_std)
    joints = body.joint_positions(x)
    f = feats[mid]
    rows["kinematics"] = best_ms(lambda: body.joint_positions(x), args.repeat)
    rows["projection"] = best_ms(lambda: project_model(joints, mv.cameras), args.repeat)
    rows["projection + costs"] = best_ms(lambda: joint_costs(joints, mv.cameras, f), args.repeat)
    rows["score"] = best_ms(
        lambda: joint_costs(body.joint_positions(x), mv.cameras, f), args.repeat
    )
    e = joint_costs(joints, mv.cameras, f)
    rows["survival beta"] = best_ms(lambda: survival_beta(e, 0.5), args.repeat)

    tracker = AnnealedParticleFilter(body, mv.cameras, args.particles, 10, fps=mv.fps, seed=0)
    tracker.step(feats[0])
    t0 = time.process_time()
    for i, frame in enumerate(frames[1:], 1):
        tracker.step(mv.features_of(frame, i))
    rows["frame"] = 1e3 * (time.process_time() - t0) / (len(frames) - 1)
    rows = {k: round(v, 3) for k, v in rows.items()}
    load = os.getloadavg()
    if args.json:
        print(json.dumps({"ms": rows, "particles": args.particles, "load": load}))
        return
    for k, v in rows.items():
        print(f"{k:20s} {v:8.3f} ms CPU")
    print(f"load average {load[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()

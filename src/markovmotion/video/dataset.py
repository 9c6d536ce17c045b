"""Silhouette videos of the two-person takes, and the tracked takes for the behaviour chain.

:func:`render_takes` writes, for every take, a video of both people from a
fixed side camera, and for each held-out take also one video per person with
the other masked out (the paper's test sequences: one individual masked
before tracking, §5). ``index.json`` lists them with the split and cameras.

:func:`silhouette_takes` reads them back as tracked people: the training
takes as left-hand and right-hand individuals of two-person tracks, the
held-out takes as the two identities tracked from their own videos. A video
with a ``.track.npz`` beside it (from ``silhouette track``) is not tracked
again.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from markovmotion.data.index import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.errors import DataNotFoundError
from markovmotion.evaluate.chain import mocap_takes
from markovmotion.features.joint_shape import TwoPeople
from markovmotion.io.files import atomic_write
from markovmotion.progress import track
from markovmotion.video.render import PEOPLE_COLOURS, render_frames, side_camera, write_video
from markovmotion.video.tracker import SilhouetteTrack, track_video

INDEX = "index.json"
FPS = 25.0


def render_takes(
    data: str | os.PathLike[str] | None,
    out: str | os.PathLike[str],
    label: str = "salsa",
    suffix: str = ".mp4",
    noise: float = 4.0,
    max_frames: int | None = None,
) -> Path:
    """Render every two-person take of ``label`` into ``out`` (``.mp4`` files, or PNG folders
    with ``suffix`` ""); returns the path of ``index.json``."""
    index = MocapIndex.load(data)
    train, test = held_out_pairs(index.pairs(label=label, kind="skeleton"))
    out = Path(out)
    entries = []
    for pair, split in track(
        [(p, "train") for p in train] + [(p, "test") for p in test], "rendering"
    ):
        take = mocap_takes(index, [pair], fps=FPS)[0].trim(0, max_frames)
        people = [take.person(0), take.person(1)]
        camera = side_camera(people)
        name = pair[0].name
        entry = {
            "name": name,
            "split": split,
            "files": [pair[0].file, pair[1].file],
            "frames": take.n_frames,
            "camera": camera.to_dict(),
            "video": write_video(
                render_frames(people, camera, noise), out / f"{name}{suffix}", FPS
            ).name,
        }
        if split == "test":
            entry["alone"] = [
                write_video(
                    render_frames([p], camera, noise, colours=[PEOPLE_COLOURS[i]]),
                    out / f"{name}.{'AB'[i]}{suffix}",
                    FPS,
                ).name
                for i, p in enumerate(people)
            ]
        entries.append(entry)
    path = out / INDEX
    with atomic_write(path) as fh:
        fh.write(json.dumps({"fps": FPS, "label": label, "takes": entries}, indent=2))
    return path


def tracked(video: Path, n_people: int) -> SilhouetteTrack:
    """The track of ``video``: its ``.track.npz`` if there is one, else tracked now."""
    cached = video.parent / f"{video.name}.track.npz"
    if cached.is_file():
        return SilhouetteTrack.load(cached)
    return track_video(video, n_people)


def silhouette_takes(folder: str | os.PathLike[str] | None, split: str) -> list[TwoPeople]:
    """Tracked takes of ``split`` ("train": left/right individuals; "test": identities A, B)."""
    if folder is None:
        raise DataNotFoundError("silhouette data: give the folder written by 'silhouette render'")
    folder = Path(folder)
    if folder.is_file():
        folder = folder.parent
    if not (folder / INDEX).is_file():
        raise DataNotFoundError(f"{folder}: no {INDEX} (write one with 'silhouette render')")
    entries = [e for e in json.loads((folder / INDEX).read_text())["takes"] if e["split"] == split]
    takes = []
    for e in entries:
        # named by the video and the captured files it shows (what a model records of it)
        name = f"{e['video']} ({' + '.join(e.get('files', []))})"
        if split == "train":
            take = tracked(folder / e["video"], 2).two_people()
            takes.append(dataclasses.replace(take, name=name))
            continue
        a, b = (tracked(folder / v, 1).person(0) for v in e["alone"])
        takes.append(TwoPeople.from_people(a, b, FPS, name))
    return takes

"""Walks of a collection for the gait family: which takes, and reading them.

A walk is a take of category ``walk`` (neutral) or ``style_walk``; by
default those whose file lies under Bandai Namco's dataset-2 (about 20 takes
of each of 7 styles, one skeleton), overridable by ``subset`` (any prefix of
the index's file names; "" for every walk).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from markovmotion.core.motion import Motion
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.splits import held_out_every
from markovmotion.errors import DataNotFoundError
from markovmotion.io import read_motion
from markovmotion.progress import track

#: The walks of the shared collection used by default.
DEFAULT_SUBSET = "bandai/dataset-2/"
#: Which takes of an index :func:`load_walks` reads: the training split, the held-out one, all.
SPLITS = ("train", "test", "all")


def gait_entries(
    index: MocapIndex, labels: str | Sequence[str] | None = None, subset: str = DEFAULT_SUBSET
) -> list[Entry]:
    """Walk entries (neutral and styled) whose file starts with ``subset``, optionally of some labels."""
    rows = index.query(category=["walk", "style_walk"], label=labels)
    return sorted((e for e in rows if e.file.startswith(subset)), key=lambda e: e.file)


def _is_index(paths: Sequence[Path]) -> bool:
    return len(paths) == 1 and (paths[0].is_dir() or paths[0].name.lower().endswith(".csv"))


def load_walks(
    paths: Sequence[str | os.PathLike[str]] | None,
    labels: Sequence[str] | str | None,
    split: str = "train",
    subset: str = "",
    folders: list[str] | None = None,
) -> list[Motion]:
    """Walks from motion files, or from an INDEX.csv (or its folder) by label and split.

    From an index, the walks are those of ``subset`` (:data:`DEFAULT_SUBSET`
    if empty) with the labels asked for; ``split`` keeps the training takes,
    the held-out takes (:func:`~markovmotion.data.splits.held_out_every`) or
    all. The folder of each walk (its dataset) is appended to ``folders`` if
    given.
    """
    paths = [Path(p) for p in paths or []]
    if paths and not _is_index(paths):
        if folders is not None:
            folders.extend(p.resolve().parent.name for p in paths)
        return [read_motion(p) for p in track(paths, "reading walks")]
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    index = MocapIndex.load(paths[0] if paths else None)
    entries = gait_entries(index, labels, subset or DEFAULT_SUBSET)
    train, test = held_out_every(entries)
    chosen = {"train": train, "test": test, "all": entries}[split]
    if not chosen:
        raise DataNotFoundError(
            f"no walks labelled {labels} under {subset or DEFAULT_SUBSET} in {index.root}"
        )
    if folders is not None:
        folders.extend(Path(e.file).parent.name for e in chosen)
    return [index.load_motion(e) for e in track(chosen, "reading walks")]

"""Walks of a collection for the gait family: which takes, and reading them.

A walk is a take of category ``walk`` (neutral) or ``style_walk``; by
default those whose file lies under Bandai Namco's dataset-2 (about 20 takes
of each of 7 styles, one skeleton) in an index that has it (the shared
collection), every walk in one that does not (a user's own), overridable by
``subset`` (any prefix of the index's file names; "" for every walk).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from markovmotion.core.motion import Motion
from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.kinds import largest_group
from markovmotion.data.splits import held_out_every
from markovmotion.errors import DataNotFoundError
from markovmotion.io import read_motion
from markovmotion.progress import track

#: The walks of the shared collection used by default.
DEFAULT_SUBSET = "bandai/dataset-2/"
#: Which takes of an index :func:`load_walks` reads: the training split, the held-out one, all.
SPLITS = ("train", "test", "all")


def gait_entries(
    index: MocapIndex, labels: str | Sequence[str] | None = None, subset: str | None = None
) -> list[Entry]:
    """Walk entries (neutral and styled) whose file starts with ``subset``, optionally of
    some labels; ``subset`` None: :data:`DEFAULT_SUBSET` if any walk of the index is there,
    else every walk."""
    rows = index.query(category=["walk", "style_walk"], label=labels)
    if subset is None:
        subset = default_subset(index)
    return sorted((e for e in rows if e.file.startswith(subset)), key=lambda e: e.file)


def default_subset(index: MocapIndex) -> str:
    """:data:`DEFAULT_SUBSET` where ``index`` has walks there (the shared collection, whose
    other walks are of many skeletons), else "" (every walk: a user's own collection)."""
    walks = index.query(category=["walk", "style_walk"])
    return DEFAULT_SUBSET if any(e.file.startswith(DEFAULT_SUBSET) for e in walks) else ""


def _is_index(paths: Sequence[Path]) -> bool:
    return len(paths) == 1 and (paths[0].is_dir() or paths[0].name.lower().endswith(".csv"))


def walks_index(paths: Sequence[str | os.PathLike[str]] | None) -> MocapIndex | None:
    """The index :func:`load_walks` reads ``paths`` from (the default collection for none),
    or None when they are motion files."""
    given = [Path(p) for p in paths or []]
    if given and not _is_index(given):
        return None
    return MocapIndex.load(given[0] if given else None)


def load_walks(
    paths: Sequence[str | os.PathLike[str]] | None,
    labels: Sequence[str] | str | None,
    split: str = "train",
    subset: str | None = None,
    folders: list[str] | None = None,
) -> list[Motion]:
    """Walks from motion files, or from an INDEX.csv (or its folder) by label and split.

    From an index, the walks are those of ``subset`` (None: :func:`default_subset`; "":
    every walk) with the labels asked for; ``split`` keeps the training takes,
    the held-out takes (:func:`~markovmotion.data.splits.held_out_every`) or
    all. The folder of each walk (its dataset) is appended to ``folders`` if
    given.
    """
    paths = [Path(p) for p in paths or []]
    if paths and not _is_index(paths):
        walks = [read_motion(p) for p in track(paths, "reading walks")]
        return _one_skeleton(
            walks, [str(p) for p in paths], [p.resolve().parent.name for p in paths], folders
        )
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    index = MocapIndex.load(paths[0] if paths else None)
    if subset is None:
        subset = default_subset(index)
    entries = gait_entries(index, labels, subset)
    train, test = held_out_every(entries)
    chosen = {"train": train, "test": test, "all": entries}[split]
    if not chosen:
        which = (
            f" labelled {labels if isinstance(labels, str) else ', '.join(labels)}"
            if labels
            else ""
        )
        under = f" under {subset}" if subset else ""
        split_words = "" if split == "all" else f" in the {split} split"
        raise DataNotFoundError(f"no walks{which}{under}{split_words} in {index.root}")
    walks = [index.load_motion(e) for e in track(chosen, "reading walks")]
    files = [e.file for e in chosen]
    return _one_skeleton(walks, files, [Path(f).parent.name for f in files], folders)


def _one_skeleton(
    walks: list[Motion], files: list[str], datasets: list[str], folders: list[str] | None
) -> list[Motion]:
    """The walks of the largest group sharing one skeleton (a gait model learns one; the
    others are named in a note, :func:`~markovmotion.data.kinds.largest_group`), each
    one's dataset (its folder) appended to ``folders`` if given."""
    best, _ = largest_group(walks, files, "walks")
    if folders is not None:
        folders.extend(datasets[i] for i in best)
    return [walks[i] for i in best]

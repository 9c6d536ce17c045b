"""Stimuli of the perceptual evaluation (gait paper §6.1): a folder of BVH files and a manifest.

``manifest.csv`` in the folder has the columns ``file, style, kind,
displacement``: ``file`` a path relative to the folder, ``style`` the walk
style (``average`` for the average-walk model), ``kind`` ``real`` or
``synthetic``, ``displacement`` ``yes`` when the root travels and ``no`` when
its displacement was removed ("static" in the paper).
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markovmotion.core.motion import GROUND, Motion
from markovmotion.errors import DataNotFoundError, MarkovMotionError, MotionFormatError
from markovmotion.io import read_motion, write_motion
from markovmotion.io.files import atomic_write, read_text

MANIFEST = "manifest.csv"
COLUMNS = ("file", "style", "kind", "displacement")
KINDS = ("real", "synthetic")
AVERAGE = "average"
_TRUE = ("yes", "true", "1")
_FALSE = ("no", "false", "0")


@dataclass(frozen=True)
class Stimulus:
    """One motion shown to evaluators."""

    file: str
    style: str
    kind: str
    displacement: bool


def read_manifest(folder: str | os.PathLike[str]) -> list[Stimulus]:
    """The stimuli listed in ``folder/manifest.csv``, each checked to be a file inside ``folder``."""
    root = Path(folder).resolve()
    path = root / MANIFEST
    if not path.is_file():
        raise DataNotFoundError(f"{path}: no stimuli manifest (columns {', '.join(COLUMNS)})")
    reader = csv.DictReader(io.StringIO(read_text(path)))
    missing = [c for c in COLUMNS if c not in (reader.fieldnames or ())]
    if missing:
        raise MotionFormatError(path, f"missing column(s) {', '.join(missing)}", 1)
    out: list[Stimulus] = []
    for line, row in enumerate(reader, start=2):
        file, style = row["file"].strip(), row["style"].strip().lower()
        kind, disp = row["kind"].strip().lower(), row["displacement"].strip().lower()
        if kind not in KINDS:
            raise MotionFormatError(path, f"kind {kind!r} is not one of {KINDS}", line)
        if disp not in _TRUE + _FALSE:
            raise MotionFormatError(path, f"displacement {disp!r} is not yes or no", line)
        if not style:
            raise MotionFormatError(path, "empty style", line)
        target = (root / file).resolve()
        if not target.is_relative_to(root) or not target.is_file():
            raise MotionFormatError(path, f"{file!r} is not a file inside {root}", line)
        out.append(Stimulus(file, style, kind, disp in _TRUE))
    if not out:
        raise MotionFormatError(path, "the manifest lists no stimuli")
    return out


def without_displacement(motion: Motion) -> Motion:
    """The motion on the spot: the pelvis's horizontal travel removed (paper §6.1 "static")."""
    pelvis = motion.positions()[:, motion.skeleton.body_root]
    out = motion.copy()
    out.translations[:, 0, GROUND] -= pelvis[:, GROUND] - pelvis[0, GROUND]
    return out


def write_stimuli(
    folder: str | os.PathLike[str],
    real: dict[str, str | os.PathLike[str]],
    synthetic: dict[str, str | os.PathLike[str]],
) -> list[Stimulus]:
    """Build a stimuli folder as in paper §6.1: each motion with and without root displacement.

    ``real`` and ``synthetic`` map a style to a motion file (``synthetic`` may
    hold ``average`` for the average-walk model). Files are numbered in a
    random order so their names tell nothing. Every input is read before
    anything is written, and the manifest is written last.
    """
    entries = [(s, "real", f) for s, f in real.items()]
    entries += [(s, "synthetic", f) for s, f in synthetic.items()]
    if not entries:
        raise MarkovMotionError(
            f"{folder}: no stimuli to write: give walks with --real STYLE=FILE "
            "and/or --synthetic STYLE=FILE"
        )
    motions = [read_motion(file) for _, _, file in entries]
    order = np.random.default_rng().permutation(2 * len(entries))
    root = Path(folder)
    stimuli: list[Stimulus] = []
    for i, ((style, kind, _), moving) in enumerate(zip(entries, motions, strict=True)):
        for k, (motion, disp) in enumerate(((moving, True), (without_displacement(moving), False))):
            name = f"stimulus_{order[2 * i + k] + 1:03d}.bvh"
            write_motion(motion, root / name)
            stimuli.append(Stimulus(name, style.lower(), kind, disp))
    stimuli.sort(key=lambda s: s.file)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for s in stimuli:
        writer.writerow((s.file, s.style, s.kind, "yes" if s.displacement else "no"))
    with atomic_write(root / MANIFEST) as fh:
        fh.write(text.getvalue())
    return stimuli

"""Every file of the shared INDEX.csv reads, with the frame count INDEX.csv gives, and converts.

Each file is read once with the library (what ``markovmotion info`` does), and
its first frames go through ``convert``'s path (write BVH, read it back). The
command line itself runs ``info`` and ``convert`` on the shortest file of each
kind (source and format), whole.
"""

from __future__ import annotations

import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.data import MocapIndex
from markovmotion.io import read_motion, write_motion
from markovmotion.io.files import base_suffix

ENTRIES = MocapIndex.load().entries
HEAD = 20  # frames of each file sent through convert's path


def _kind(entry) -> str:
    return f"{entry.source}{base_suffix(entry.file)}"


@pytest.mark.parametrize("entry", ENTRIES, ids=[e.file for e in ENTRIES])
def test_file_reads_and_converts(entry, tmp_path):
    motion = read_motion(entry.path)  # the raw file, as `info` reads it
    assert motion.n_frames == entry.frames
    assert np.isfinite(motion.positions()).all()
    head = motion.trim(0, HEAD)
    write_motion(head, tmp_path / "head.bvh")
    back = read_motion(tmp_path / "head.bvh", fps=head.fps)
    assert back.n_frames == head.n_frames
    assert back.skeleton.names == head.skeleton.names
    np.testing.assert_allclose(back.positions(), head.positions(), atol=1e-3)


SHORTEST = {}
for _e in sorted(ENTRIES, key=lambda e: e.frames):
    SHORTEST.setdefault(_kind(_e), _e)


@pytest.mark.parametrize("kind", sorted(SHORTEST))
def test_cli_info_and_convert(kind, tmp_path, capsys):
    entry = SHORTEST[kind]
    main(["info", str(entry.path)])
    shown = capsys.readouterr().out
    # a file of the collection is read as INDEX.csv says: true rate, CMU's reference frame dropped
    frames = entry.frames - int(entry.has_reference_frame)
    assert "frames" in shown and f" {frames} " in shown and f" {entry.fps:g} fps" in shown
    out = tmp_path / "out.bvh.gz"
    main(["convert", str(entry.path), str(out), "--fps", str(entry.fps)])
    back = read_motion(out)
    assert back.n_frames == entry.frames
    assert back.fps == pytest.approx(entry.fps, rel=1e-6)

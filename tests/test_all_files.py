"""Every file of the shared INDEX.csv reads, with the frame count INDEX.csv gives, and converts.

Each file is read once with the library (what ``markovmotion info`` does), through the
reader of its kind: a skeleton's motion (BVH, ASF/AMC), whose first frames go through
``convert``'s path (write BVH, read it back), or markers (C3D), whose first frames are
written as C3D and read back. The command line itself runs ``info`` (and for skeletons
``convert``) on the shortest file of each kind (source and format), whole.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.data import MocapIndex
from markovmotion.io import describe_take, read_c3d, read_motion, write_c3d, write_motion
from markovmotion.io.files import base_suffix

ENTRIES = MocapIndex.load().entries
HEAD = 20  # frames of each file sent through convert's path


def _kind(entry) -> str:
    return f"{entry.source}{base_suffix(entry.file)}"


SKELETONS = [e for e in ENTRIES if e.kind == "skeleton"]
MARKERS = [e for e in ENTRIES if e.kind == "markers"]


def test_the_collection_holds_both_kinds():
    assert SKELETONS and MARKERS
    assert {describe_take(e.path)[0] for e in (SKELETONS[0], MARKERS[0])} == {
        "skeleton",
        "markers",
    }


@pytest.mark.parametrize("entry", MARKERS, ids=[e.file for e in MARKERS])
def test_markers_file_reads_and_round_trips(entry, tmp_path):
    markers = read_c3d(entry.path)  # the markers reader, as `info` reads a C3D file
    assert markers.n_frames == entry.frames
    assert markers.fps == pytest.approx(entry.fps, rel=1e-3)
    assert markers.names and all(n.strip() for n in markers.names)
    assert len(set(markers.names)) == len(markers.names)
    seen = markers.visible()
    assert seen.any(axis=1).all()  # every frame shows some marker
    assert np.isfinite(markers.positions[seen]).all()
    assert describe_take(entry.path) == ("markers", len(markers.names))
    head = markers.trim(0, HEAD)
    write_c3d(head, tmp_path / "head.c3d")
    back = read_c3d(tmp_path / "head.c3d")
    assert back.names == head.names and back.n_frames == head.n_frames
    np.testing.assert_allclose(back.positions, head.positions, atol=0.01)


@pytest.mark.parametrize("entry", SKELETONS, ids=[e.file for e in SKELETONS])
def test_file_reads_and_converts(entry, tmp_path):
    motion = read_motion(entry.path)  # the raw file, as `info` reads it
    assert describe_take(entry.path) == ("skeleton", int((~motion.skeleton.end_site).sum()))
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
    assert re.search(rf"\bframes\W+{frames}\b", shown), shown
    assert f" {entry.fps:g} fps" in shown
    if entry.kind == "markers":
        assert re.search(rf"\bmarkers\W+{describe_take(entry.path)[1]} ", shown), shown
        return
    out = tmp_path / "out.bvh.gz"
    main(["convert", str(entry.path), str(out), "--fps", str(entry.fps)])
    back = read_motion(out)
    assert back.n_frames == entry.frames
    assert back.fps == pytest.approx(entry.fps, rel=1e-6)

"""C3D reading: files written with c3d.Writer read back in mm, Y up, occlusions as NaN."""

from __future__ import annotations

import warnings

import c3d
import numpy as np
import pytest

from markovmotion import MotionFormatError
from markovmotion.core.markers import Markers
from markovmotion.io import read_c3d

LABELS = ["LFHD", "RFHD", "C7", "LTOE"]


def write_c3d(
    path,
    positions_mm: np.ndarray,
    units: str = "mm",
    scale: float = -1.0,
    screen: tuple[str, str] | None = None,
    occluded: tuple[int, int] | None = None,
    rate: float = 100.0,
    labels: list[str] | None = None,
) -> None:
    """A C3D of lab positions (F, M, 3) given in mm, stored in ``units``."""
    per_mm = {"mm": 1.0, "cm": 0.1, "m": 0.001}.get(units.strip(), 1.0)
    writer = c3d.Writer(point_rate=rate, point_scale=scale, point_units=units)
    for f, frame in enumerate(positions_mm):
        points = np.zeros((len(frame), 5), np.float32)
        points[:, :3] = frame * per_mm
        if occluded is not None and f == occluded[0]:
            points[occluded[1], 3] = -1
        writer.add_frames((points, np.zeros((0, 0))))
    writer.set_point_labels(labels or LABELS[: positions_mm.shape[1]])
    if screen is not None:
        writer.set_screen_axis(*screen)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no analog data"
        with open(path, "wb") as fh:
            writer.write(fh)


def lab_positions(n_frames: int = 30, seed: int = 0) -> np.ndarray:
    """Markers wandering around a Z-up lab, 0.5-1.8 m high (mm)."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1000, 1000, (n_frames, len(LABELS), 3))
    pos[..., 2] = rng.uniform(500, 1800, (n_frames, len(LABELS)))
    return pos


@pytest.mark.parametrize("units", ["mm", "cm", "m"])
def test_units_and_z_up_to_y_up(tmp_path, units):
    lab = lab_positions()
    path = tmp_path / f"walk_{units}.c3d"
    write_c3d(path, lab, units=units.ljust(4), occluded=(5, 2))
    markers = read_c3d(path)
    assert isinstance(markers, Markers)
    assert markers.names == tuple(LABELS)
    assert markers.fps == 100 and markers.n_frames == 30 and markers.name == path.name
    # lab (x, y, z) with Z up is (x, z, -y) with Y up
    expected = np.stack([lab[..., 0], lab[..., 2], -lab[..., 1]], axis=-1)
    expected[5, 2] = np.nan
    np.testing.assert_allclose(markers.positions, expected, atol=1e-3)  # float32
    assert markers.visible().sum() == markers.positions.shape[0] * 4 - 1
    assert (markers.positions[..., 1][markers.visible()] >= 500 - 1e-3).all()  # up is +Y


def test_integer_storage_and_screen_axes(tmp_path):
    lab = np.round(lab_positions(n_frames=10, seed=1))
    path = tmp_path / "y_up.c3d"
    # stored as int16 * 0.1 mm, already Y up (X right, Y up on screen)
    write_c3d(path, lab / 2, scale=0.1, screen=("+X", "+Y"))
    np.testing.assert_allclose(read_c3d(path).positions, lab / 2, atol=0.051)


def test_summary_names_the_essentials(tmp_path):
    path = tmp_path / "s.c3d"
    write_c3d(path, lab_positions(), occluded=(0, 0))
    text = read_c3d(path).summary()
    for expected in ("s.c3d", "30", "100 fps", "LFHD", "occluded"):
        assert expected in text


def _damaged(tmp_path, name: str, edit) -> str:
    good = tmp_path / "good.c3d"
    write_c3d(good, lab_positions(n_frames=200))
    bad = tmp_path / name
    bad.write_bytes(edit(good.read_bytes()))
    return str(bad)


BAD = {
    "not a c3d": lambda b: b"hello, world\n" * 10,
    "empty": lambda b: b"",
    "truncated data": lambda b: b[: len(b) - 3000],
    "truncated parameters": lambda b: b[:700],
}


@pytest.mark.parametrize("problem", sorted(BAD))
def test_malformed_c3d(tmp_path, problem):
    path = _damaged(tmp_path, "bad.c3d", BAD[problem])
    with pytest.raises(MotionFormatError) as info:
        read_c3d(path)
    assert info.value.path == path


def test_unknown_units(tmp_path):
    write_c3d(tmp_path / "ft.c3d", lab_positions(), units="ft")
    with pytest.raises(MotionFormatError, match="unknown POINT:UNITS 'ft'"):
        read_c3d(tmp_path / "ft.c3d")


def test_missing_c3d(tmp_path):
    with pytest.raises(MotionFormatError, match="no such file"):
        read_c3d(tmp_path / "none.c3d")


def test_markers_validate_shapes():
    with pytest.raises(ValueError):
        Markers(("a",), np.zeros((3, 2, 3)), 100.0)
    with pytest.raises(ValueError):
        Markers(("a",), np.full((3, 1, 3), np.inf), 100.0)


def test_a_capture_longer_than_a_uint16_reads_back_and_the_value_limit_holds(tmp_path, monkeypatch):
    """The header's counts are NumPy uint16: 70,000 frames overflowed ("Python integer out
    of bounds for uint16"), and below 65,536 frames x points x 3 wrapped round and passed the
    value limit (60,000 x 200 x 3 read as 20,736). The project's own writer and reader."""
    from markovmotion.io.c3d import write_c3d as write_markers

    n = 70_000
    pos = np.zeros((n, 2, 3))
    pos[:, :, 0] = np.arange(n)[:, None] % 1000
    write_markers(Markers(("A", "B"), pos, 30.0, "long"), tmp_path / "long.c3d")
    back = read_c3d(tmp_path / "long.c3d")
    assert back.n_frames == n
    np.testing.assert_allclose(back.positions[-1, :, 0], pos[-1, :, 0], atol=0.1)
    monkeypatch.setenv("MARKOVMOTION_MAX_VALUES", str(n * 2 * 3 - 1))
    with pytest.raises(MotionFormatError, match="70000 frames x 2 points"):
        read_c3d(tmp_path / "long.c3d")


def _standing(n_frames: int = 40, seed: int = 1) -> np.ndarray:
    """A person's four markers in a Y-up lab (mm): the head's two 1.7 m high, C7 1.45 m, a toe
    on the floor, swaying a little."""
    rng = np.random.default_rng(seed)
    body = np.array([[-60, 1700, 80], [60, 1700, 80], [0, 1450, -50], [-100, 30, 100]], float)
    return body + rng.normal(0, 15, (n_frames, 4, 3))


def test_a_y_up_file_without_screen_axes_is_read_upright(tmp_path, capsys):
    """Without POINT:X_SCREEN/Y_SCREEN a lab is taken as Z up; a Y-up capture that left them
    out (its head level with the body read so, above it read Y up) is read with Y up, said
    in a note; with its screen axes given, a file is read as they say, whatever its head."""
    lab = _standing()
    write_c3d(tmp_path / "yup.c3d", lab)  # no screen axes
    markers = read_c3d(tmp_path / "yup.c3d")
    np.testing.assert_allclose(markers.positions, lab, atol=1e-3)  # Y up: our axes
    assert "read with Y up" in " ".join(capsys.readouterr().err.split())
    write_c3d(tmp_path / "zup.c3d", lab, screen=("+X", "+Z"))  # said to be Z up: so read
    turned = read_c3d(tmp_path / "zup.c3d").positions
    np.testing.assert_allclose(turned[..., 1], lab[..., 2], atol=1e-3)
    zup = np.stack([lab[..., 0], -lab[..., 2], lab[..., 1]], axis=-1)  # the same person, Z up
    write_c3d(tmp_path / "lab.c3d", zup)
    np.testing.assert_allclose(read_c3d(tmp_path / "lab.c3d").positions, lab, atol=1e-3)
    assert "read with Y up" not in capsys.readouterr().err


def test_samples_at_the_origin_are_gaps(tmp_path, capsys):
    """A sample at exactly (0, 0, 0), how some software writes a gap, is unseen (NaN) like a
    sample with a negative residual, and counted in a note."""
    lab = lab_positions()
    lab[3:6, 1] = 0.0
    write_c3d(tmp_path / "gaps.c3d", lab, occluded=(10, 2))
    markers = read_c3d(tmp_path / "gaps.c3d")
    assert np.isnan(markers.positions[3:6, 1]).all() and np.isnan(markers.positions[10, 2]).all()
    assert markers.visible().sum() == lab.shape[0] * lab.shape[1] - 4
    assert "3 samples at exactly (0, 0, 0) read as unseen" in capsys.readouterr().err


def test_a_body_in_another_unit_than_its_file_says_is_noted(tmp_path, capsys):
    """A file whose values are metres but whose POINT:UNITS says mm is a body 2 mm across:
    read as the file says, with a note naming the unit that would make a person of it; a
    person in the unit the file gives is not noted, in any unit."""
    lab = _standing()
    write_c3d(tmp_path / "ok.c3d", lab, units="m   ", screen=("+X", "+Y"))
    read_c3d(tmp_path / "ok.c3d")
    assert "POINT:UNITS" not in capsys.readouterr().err
    # the metres' numbers, but the file says mm: stored as lab / 1000 "mm"
    write_c3d(tmp_path / "wrong.c3d", lab / 1000.0, units="mm  ", screen=("+X", "+Y"))
    markers = read_c3d(tmp_path / "wrong.c3d")
    np.testing.assert_allclose(markers.positions, lab / 1000.0, atol=1e-5)  # as it says
    said = " ".join(capsys.readouterr().err.split())
    assert "wrong.c3d: its markers span 1.68 mm read in mm (POINT:UNITS)" in said
    assert "in m they would span 1676 mm: is its POINT:UNITS wrong?" in said


def _two_dimensional_trial_fields(data: bytes) -> bytes:
    """``data`` (a C3D file) with TRIAL:ACTUAL_START_FIELD and ACTUAL_END_FIELD given two
    dimensions (2, 1) instead of one (2), as ezc3d's example files give them: each
    parameter record grows by a dimension byte, taken from the parameter section's
    padding so that the data stay where the header says."""
    import struct

    out = bytearray(data)
    data_start = (struct.unpack_from("<H", out, 16)[0] - 1) * 512
    for name in (b"ACTUAL_START_FIELD", b"ACTUAL_END_FIELD"):
        at = out.index(name) + len(name)  # the offset to the next parameter, then the type
        assert out[at + 3] == 1 and out[at + 4] == 2  # one dimension, of 2
        out[at + 3] = 2
        out.insert(at + 5, 1)
        struct.pack_into("<h", out, at, struct.unpack_from("<h", out, at)[0] + 1)
        assert out[data_start] == 0  # padding
        del out[data_start]
    return bytes(out)


def test_trial_fields_of_two_dimensions_are_read(tmp_path):
    """A C3D whose TRIAL:ACTUAL_*_FIELD have two dimensions (ezc3d's C3DRotationExample.c3d)
    had the c3d package fail on its frame count: "not a readable C3D file (TypeError: only
    0-dimensional arrays can be converted to Python scalars)". It reads as the file with one."""
    write_c3d(tmp_path / "plain.c3d", lab_positions())
    patched = tmp_path / "trial2d.c3d"
    patched.write_bytes(_two_dimensional_trial_fields((tmp_path / "plain.c3d").read_bytes()))
    assert patched.stat().st_size == (tmp_path / "plain.c3d").stat().st_size
    plain, read = read_c3d(tmp_path / "plain.c3d"), read_c3d(patched)
    assert read.names == plain.names and read.fps == plain.fps
    np.testing.assert_array_equal(read.positions, plain.positions)


def test_screen_axes_that_put_the_head_below_the_body_are_read_upright(tmp_path, capsys):
    """Qualisys writes ``POINT:X_SCREEN -X``, ``Y_SCREEN -Z`` for a Z-up lab (the screen's Y
    running down, as image rows do): read as stated every person stood on their head,
    silently (ezc3d's Qualisys.c3d). When the head markers (``L_HDF``...) stand below the
    body and the screen's Y taken downwards puts them above, that is how it is read, said
    in a note; a file whose stated axes put the head up, or that states a positive screen Y
    (ours, ``+Y``), is read as stated."""
    body = np.array([[0, 0, 1700], [0, 50, 1650], [0, 0, 1000], [0, 0, 80]], float)  # Z up
    pos = np.repeat(body[None], 20, axis=0) + np.arange(20)[:, None, None] * [5.0, 0, 0]
    labels = ["L_HDF", "R_HDB", "SACR", "L_FCC"]
    write_c3d(tmp_path / "q.c3d", pos, screen=("-X", "-Z"), labels=labels)
    write_c3d(tmp_path / "v.c3d", pos, screen=("+X", "+Z"), labels=labels)
    read = read_c3d(tmp_path / "q.c3d")
    assert "POINT:Y_SCREEN -Z puts the head below the body: read with +Z up" in (
        capsys.readouterr().err
    )
    np.testing.assert_allclose(read.positions[..., 1], pos[..., 2], atol=1e-3)  # height
    stated = read_c3d(tmp_path / "v.c3d")
    assert "note" not in capsys.readouterr().err
    np.testing.assert_allclose(stated.positions[..., 1], pos[..., 2], atol=1e-3)
    write_c3d(tmp_path / "down.c3d", pos, screen=("+X", "-Z"), labels=labels[::-1])  # feet up
    assert read_c3d(tmp_path / "down.c3d").positions[0, 0, 1] < 0  # a head stated up: as is
    assert "note" not in capsys.readouterr().err


def test_data_check_lists_what_reading_a_c3d_notes_as_findings(tmp_path, capsys):
    """``data check`` lists a C3D's notes (its axes read Y up) among its findings, one per
    file, and counts them, rather than printing them beside its table as notes it then
    counted as none."""
    from markovmotion.cli import main

    lab = _standing()
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for me, partner in (("a", "b"), ("b", "a")):
        write_c3d(tmp_path / f"{me}.c3d", lab)  # no screen axes: read Y up, with a note
        rows.append(f"{me}.c3d,lab,p,1,interaction,meet,{partner}.c3d,100,,")
    (tmp_path / "INDEX.csv").write_text("\n".join(rows) + "\n")
    main(["data", "check", "--data", str(tmp_path)])
    out, err = capsys.readouterr()
    found = [line for line in out.splitlines() if "read with Y up" in line]
    assert [line.split(",")[:2] for line in found] == [["a.c3d", "note"], ["b.c3d", "note"]]
    assert "read with Y up" not in err and "2 notes" in err

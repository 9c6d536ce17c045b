"""BVH reading and writing: round trips, real files, malformed input."""

from __future__ import annotations

import gzip
import re

import numpy as np
import pytest
from conftest import make_motion

from markovmotion import MotionFormatError, read_motion, write_motion
from markovmotion.io.bvh import bvh_text


def same_rotations(a: np.ndarray, b: np.ndarray) -> float:
    """Largest angle (rad) between quaternion arrays, sign-insensitive."""
    dot = np.abs(np.sum(a * b, axis=-1)).clip(0, 1)
    return float(np.max(2 * np.arccos(dot)))


@pytest.mark.parametrize("suffix", [".bvh", ".bvh.gz"])
def test_round_trip_synthetic(tmp_path, suffix):
    m = make_motion()
    path = tmp_path / f"m{suffix}"
    write_motion(m, path)
    back = read_motion(path)
    assert back.skeleton.names == m.skeleton.names
    assert back.skeleton.channels == m.skeleton.channels
    np.testing.assert_allclose(back.skeleton.offsets, m.skeleton.offsets, atol=1e-6)
    np.testing.assert_allclose(back.translations, m.translations, atol=1e-6)
    assert same_rotations(back.rotations, m.rotations) < 1e-6
    assert back.fps == pytest.approx(m.fps)
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)


def test_round_trip_real_files(mocap, tmp_path):
    for entry in (mocap.query(label="salsa")[0], mocap.query(source="bandai")[0]):
        m = read_motion(entry.path, fps=entry.fps)
        write_motion(m, tmp_path / "x.bvh")
        back = read_motion(tmp_path / "x.bvh")
        assert back.n_frames == m.n_frames
        assert same_rotations(back.rotations, m.rotations) < 1e-6
        np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)


@pytest.mark.parametrize("runs", [("CONVERT_FRAMES", 7), ("LOADTXT_LINES", 5)])
def test_frames_read_and_converted_in_runs_give_the_same_motion(mocap, monkeypatch, runs):
    """Euler angles are converted to quaternions in runs of frames (bounded memory: reading
    took 9-12 times a file's size), and frame lines are read in runs (one np.loadtxt call
    holds the interpreter, and the web reads uploads in a worker thread); the runs' seams
    change nothing."""
    import markovmotion.io.bvh as bvh

    path = mocap.find("cmu/bvh/salsa_01.bvh.gz").path
    whole = read_motion(path)
    monkeypatch.setattr(bvh, *runs)
    in_runs = read_motion(path)
    np.testing.assert_array_equal(in_runs.rotations, whole.rotations)
    np.testing.assert_array_equal(in_runs.translations, whole.translations)


def test_a_blank_frame_line_is_an_error_naming_it(tmp_path):
    """A blank line among the frames is a frame of no values, not skipped (the frames
    after it would shift by one and the file would silently lose a frame)."""
    lines = _valid_text().rstrip("\n").split("\n")
    first = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 1
    lines[first + 1] = ""
    path = tmp_path / "blank.bvh"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionFormatError, match=f"blank.bvh:{first + 2}: frame 1 has 0 values"):
        read_motion(path)


def test_header_fps_overridden_by_index(mocap):
    entry = mocap.query(label="salsa")[0]
    assert read_motion(entry.path).fps == pytest.approx(120, rel=1e-4)  # the header is wrong
    assert mocap.load_motion(entry).fps == 60


def test_forward_kinematics_hand_computed():
    m = make_motion(n_frames=3)
    m.rotations[:] = [0, 0, 0, 1]
    # rotate the hips 90 degrees about +Y: the left leg offset (100, -50, 0) goes to (0, -50, -100)
    m.rotations[:, 0] = [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]
    pos = m.positions()
    np.testing.assert_allclose(pos[:, 1] - pos[:, 0], [[0, -50, -100]] * 3, atol=1e-9)
    np.testing.assert_allclose(pos[:, 4] - pos[:, 0], [[0, 350, 0]] * 3, atol=1e-9)


def _valid_text() -> str:
    return bvh_text(make_motion(n_frames=4))


def _last_line(text: str, edit) -> str:
    lines = text.rstrip("\n").split("\n")
    lines[-1] = edit(lines[-1])
    return "\n".join(lines) + "\n"


BROKEN = {
    "truncated": lambda t: t[: len(t) - 40],
    "extra value in a frame": lambda t: _last_line(t, lambda ln: ln + " 3.5"),
    "missing value in a frame": lambda t: _last_line(t, lambda ln: ln.rsplit(" ", 1)[0]),
    "non-numeric": lambda t: _last_line(t, lambda ln: ln.rsplit(" ", 1)[0] + " abc"),
    "nan": lambda t: _last_line(t, lambda ln: ln.rsplit(" ", 1)[0] + " nan"),
    "inf": lambda t: _last_line(t, lambda ln: ln.rsplit(" ", 1)[0] + " inf"),
    "unknown channel": lambda t: t.replace("Zrotation", "Qrotation", 1),
    "zero frames": lambda t: t.split("MOTION")[0] + "MOTION\nFrames: 0\nFrame Time: 0.03\n",
    "missing hierarchy": lambda t: "MOTION" + t.split("MOTION")[1],
    "unbalanced braces": lambda t: t.replace("}", "", 1),
    "empty": lambda t: "",
}


@pytest.mark.parametrize("problem", sorted(BROKEN))
def test_malformed_files_raise_one_error(tmp_path, problem):
    path = tmp_path / "bad.bvh"
    path.write_text(BROKEN[problem](_valid_text()))
    with pytest.raises(MotionFormatError) as info:
        read_motion(path)
    assert str(path) in str(info.value)


def test_error_names_line(tmp_path):
    path = tmp_path / "bad.bvh"
    text = _valid_text().replace("Zrotation", "Qrotation", 1)
    path.write_text(text)
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if "Qrotation" in ln)
    with pytest.raises(MotionFormatError, match=f"bad.bvh:{line}: unknown channel"):
        read_motion(path)


def test_corrupt_gzip(tmp_path):
    path = tmp_path / "bad.bvh.gz"
    path.write_bytes(gzip.compress(_valid_text().encode())[:-30])
    with pytest.raises(MotionFormatError, match="bad.bvh.gz"):
        read_motion(path)


def test_huge_values_that_overflow_in_mm(tmp_path):
    path = tmp_path / "huge.bvh"
    path.write_text(_valid_text().replace("OFFSET 0 0 0", "OFFSET 1e308 0 0", 1))
    with pytest.raises(MotionFormatError, match="too large"):
        read_motion(path)


@pytest.mark.parametrize("unit", ["m", "inch", "mm"])
def test_a_body_in_another_unit_is_named_and_read_in_it_by_auto(
    mocap, tmp_path, unit, caplog, monkeypatch
):
    """A CMU take written in metres, inches or mm (Blender writes metres): read as cm (the
    default) it is not a person's size and a warning names the unit that makes it one;
    ``auto``, given or from the environment, reads it in that unit, the same motion."""
    from markovmotion.io.bvh import (
        BODY_SPAN_MM,
        UNIT_ENV,
        read_bvh,
        read_bvh_skeleton,
        rest_span,
        write_bvh,
    )

    take = next(e for e in mocap.query(source="cmu") if e.file.endswith(".bvh.gz"))
    motion = read_bvh(take.path, length_unit="cm")
    path = tmp_path / f"in_{unit}.bvh"
    write_bvh(motion, path, length_unit=unit)
    monkeypatch.delenv(UNIT_ENV, raising=False)
    with caplog.at_level("WARNING", logger="markovmotion"):
        as_cm = read_bvh(path)
    assert f"in {unit} it spans" in caplog.text and f"{UNIT_ENV}={unit}" in caplog.text
    low, high = BODY_SPAN_MM
    assert not low <= rest_span(as_cm.skeleton) <= high
    for auto in (read_bvh(path, length_unit="auto"), read_bvh(path, length_unit=unit)):
        assert np.allclose(auto.positions(), motion.positions(), atol=1e-3)
    monkeypatch.setenv(UNIT_ENV, "auto")
    assert np.allclose(read_bvh(path).positions(), motion.positions(), atol=1e-3)
    assert np.allclose(read_bvh_skeleton(path).offsets, motion.skeleton.offsets, atol=1e-3)
    monkeypatch.setenv(UNIT_ENV, "furlong")
    with pytest.raises(ValueError, match=f"{UNIT_ENV}='furlong' is not a length unit"):
        read_bvh(path)


def test_a_walker_with_the_arms_out_in_inches_is_not_taken_for_a_person_in_cm(
    mocap, tmp_path, caplog
):
    """A Bandai walker (rest pose arms out, 1.84 m across) written in inches spans 723 mm read
    in cm: it had passed for a person (the walker learnt 553 mm tall); now the warning names
    inches, and ``auto`` reads the same motion."""
    from markovmotion.io.bvh import read_bvh, write_bvh

    take = next(e for e in mocap.query(source="bandai"))
    motion = read_bvh(take.path, length_unit="cm")
    write_bvh(motion, tmp_path / "walk.bvh", length_unit="inch")
    with caplog.at_level("WARNING", logger="markovmotion"):
        read_bvh(tmp_path / "walk.bvh", length_unit="cm")
    assert "in inch it spans" in caplog.text
    auto = read_bvh(tmp_path / "walk.bvh", length_unit="auto")
    assert np.allclose(auto.positions(), motion.positions(), atol=1e-3)


def test_no_take_of_the_collection_and_no_small_tree_is_taken_for_another_unit(mocap):
    """Every BVH take of the collection is a person's size in cm (so the default and
    ``auto`` read it alike); a tree of a few joints is not judged at all."""
    from markovmotion.core.skeleton import Skeleton
    from markovmotion.io.bvh import likely_unit, read_bvh_skeleton

    takes = [e for e in mocap.entries if e.file.endswith((".bvh", ".bvh.gz"))]
    assert takes
    assert [e.file for e in takes if likely_unit(read_bvh_skeleton(e.path, "cm"), "cm")] == []
    toy = Skeleton(("a", "b", "c"), [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]], [()] * 3)
    assert likely_unit(toy, "cm") is None  # 2 mm, or 2 m in metres: not a body either way


def test_joint_names_with_spaces_are_read_whole(tmp_path):
    """3ds Max's Biped writes 'JOINT Bip01 L Thigh': the name is the rest of its line, as
    Blender reads it (a name's first word alone had made 'Bip01' a joint named twice)."""
    m = make_motion(n_frames=4)
    names = tuple(f"Bip01 {n}" for n in m.skeleton.names)
    sk = m.skeleton
    biped = type(sk)(names, sk.parents, sk.offsets, sk.channels, sk.end_site)
    m = type(m)(biped, m.rotations, m.translations, m.fps)
    path = tmp_path / "biped.bvh"
    write_motion(m, path)
    assert "JOINT Bip01 " in path.read_text()
    back = read_motion(path)
    assert back.skeleton.names == ("Bip01 hips", "Bip01 lleg", "Bip01 rleg", "Bip01 spine",
                                   "Bip01 spine_end")  # fmt: skip
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)
    # the brace may follow the name on its line
    path.write_text(path.read_text().replace("Bip01 ", "Bip01  L\t").replace("\n\t{", " {", 1))
    assert read_motion(path).skeleton.names[1].startswith("Bip01 L ")


def test_a_zero_frame_time_is_read_when_the_true_rate_is_given(tmp_path, capsys):
    """Some exporters write ``Frame Time: 0``: with the true rate (``fps``, an index's, the
    command line's ``--fps``) the file is read at it (the header's 0 had refused it whatever
    rate was given); without one it is one line naming the line and asking for the rate."""
    from markovmotion.cli import main

    text = _valid_text()
    path = tmp_path / "zero.bvh"
    path.write_text(re.sub(r"Frame Time: .*", "Frame Time: 0.0", text))
    assert read_motion(path, fps=25.0).fps == 25.0
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if ln.startswith("Frame Time"))
    with pytest.raises(MotionFormatError, match=f"zero.bvh:{line}: frame time must be positive"):
        read_motion(path)
    with pytest.raises(SystemExit) as exc:
        main(["info", str(path)])
    assert exc.value.code == 2 and "give the true frame rate: --fps" in capsys.readouterr().err
    main(["info", str(path), "--fps", "25"])
    assert "25 fps" in capsys.readouterr().out


@pytest.mark.parametrize("frame_time", ["1e9", "1e-300"])
def test_an_unusable_frame_time_asks_for_the_rate_the_command_line_way(
    tmp_path, capsys, frame_time
):
    """A header's Frame Time that gives no usable rate (far too large or too small) is one
    line asking for the true rate as a user gives it (``--fps``, not the Python argument
    alone), and the file is read at a rate given."""
    from markovmotion.cli import main

    path = tmp_path / "odd.bvh"
    path.write_text(re.sub(r"Frame Time: .*", f"Frame Time: {frame_time}", _valid_text()))
    with pytest.raises(SystemExit) as exc:
        main(["info", str(path)])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and "not a usable frame rate (give the true frame rate: --fps" in err
    assert len(err.splitlines()) == 1
    assert read_motion(path, fps=30.0).fps == 30.0


def test_an_end_site_written_with_a_name_is_read_as_end_site(tmp_path):
    """Some exporters write ``End LeftToeBase_End`` for ``End Site`` (Mixamo characters
    re-exported: such a file had been refused at its first end site, "expected 'Site'"):
    it is the same motion; an end site is still named after its joint."""
    m = make_motion(n_frames=4)
    text = bvh_text(m)
    path = tmp_path / "named.bvh"
    for written in ("End spine_End", "END x"):
        path.write_text(text.replace("End Site", written))
        back = read_motion(path)
        assert back.skeleton.names == m.skeleton.names
        np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)
    # 'End' with nothing after it on its line, or two words, is still one error naming it
    for broken, found in (("End\n", "'{'"), ("End a b", "'b'")):
        path.write_text(text.replace("End Site", broken, 1))
        with pytest.raises(MotionFormatError, match=f"expected .*, found {found}"):
            read_motion(path)


def test_a_body_of_no_unit_is_noted_and_read_in_the_millimetres_given(
    mocap, tmp_path, caplog, monkeypatch
):
    """A take written in a unit of no name (CMU's ASF unit, 56.44 mm: Xia's style walks as
    deep-motion-editing gives them are a person 25 cm tall read in cm) is a person's size in
    none of mm, cm, m, inch: a warning says its lengths are off (it was read without a word);
    ``MARKOVMOTION_BVH_UNIT`` (or ``length_unit``) as the millimetres of one unit reads it."""
    from markovmotion.io.bvh import UNIT_ENV, read_bvh, write_bvh

    take = next(e for e in mocap.query(source="cmu") if e.file.endswith(".bvh.gz"))
    motion = read_bvh(take.path, length_unit="cm")
    path = tmp_path / "asf_units.bvh"
    write_bvh(motion, path, length_unit="56.44")
    monkeypatch.delenv(UNIT_ENV, raising=False)
    with caplog.at_level("WARNING", logger="markovmotion"):
        read_bvh(path)
        read_bvh(path, length_unit="auto")  # no unit to choose: read in cm, said
    assert caplog.text.count("in none of mm, cm, m, inch is it a person's size") == 2
    caplog.clear()
    monkeypatch.setenv(UNIT_ENV, "56.44")
    with caplog.at_level("WARNING", logger="markovmotion"):
        back = read_bvh(path)
    assert not caplog.text
    assert np.allclose(back.positions(), motion.positions(), atol=1e-2)
    assert np.allclose(read_bvh(path, length_unit="56.44").positions(), back.positions())
    for bad in ("0", "-3", "nan", "furlong"):
        monkeypatch.setenv(UNIT_ENV, bad)
        with pytest.raises(ValueError, match=f"{UNIT_ENV}='{bad}' is not a length unit; use"):
            read_bvh(path)

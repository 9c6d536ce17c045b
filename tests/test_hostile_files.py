"""Hostile motion files (BVH, .bvh.gz, ASF/AMC, C3D, INDEX.csv): one clear line and exit 2,
in bounded time and memory, never a traceback (issue 14).

The inputs are generated here (see ``hostile_corpus``); heavy cases run the real
command line in a child process whose CPU time and peak memory are measured.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hostile_corpus import (
    COUNTS,
    SMALL_CHANNELS,
    SMALL_HIERARCHY,
    amc_pair,
    check_clean,
    gzip_bomb,
    nested_bvh,
    run_cli,
    sibling_bvh,
    small_bvh,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markovmotion.cli import main
from markovmotion.data.index import data_root
from markovmotion.io.bvh import read_bvh, read_bvh_stream

# ------------------------------------------------------------- the real process


def _symlink_loop(tmp: Path) -> Path:
    os.symlink(tmp / "b.bvh", tmp / "a.bvh")
    os.symlink(tmp / "a.bvh", tmp / "b.bvh")
    return tmp / "a.bvh"


def _fifo(tmp: Path) -> Path:
    os.mkfifo(tmp / "pipe.bvh")
    return tmp / "pipe.bvh"


def _link(target: str):
    def make(tmp: Path) -> Path:
        os.symlink(target, tmp / "dev.bvh")
        return tmp / "dev.bvh"

    return make


def _text(name: str, text):
    def make(tmp: Path) -> Path:
        (tmp / name).write_text(text())
        return tmp / name

    return make


HEAVY = {
    "fifo": (_fifo, "FIFO", {}),
    "link to /dev/zero": (_link("/dev/zero"), "device", {}),
    "5,000 nested joints": (_text("deep.bvh", lambda: nested_bvh(5000)), None, {}),
    "100k sibling joints": (_text("wide.bvh", lambda: sibling_bvh(100_000)), "joints", {}),
    "Frame Time 1e300": (
        _text("slow.bvh", lambda: small_bvh(3, frame_time="1e300")),
        "Frame Time",
        {},
    ),
    "gzip bomb": (
        lambda tmp: gzip_bomb(tmp / "bomb.bvh.gz", 48, SMALL_HIERARCHY.encode()),
        "decompresses to more than",
        {"MARKOVMOTION_MAX_BYTES": "16000000"},
    ),
}


@pytest.mark.parametrize("case", sorted(HEAVY))
def test_hostile_file_in_a_real_process(tmp_path, case):
    make, problem, env = HEAVY[case]
    path = make(tmp_path)
    run = run_cli(["info", str(path)], env=env)
    if problem is None:  # a legal if odd file: read, in bounded time and memory
        COUNTS["tried"] += 1
        assert run.code == 0 and "Traceback" not in run.stderr, run.stderr[-2000:]
        assert run.cpu_s < 10 and run.max_rss_bytes < 1 << 30
        COUNTS["clean"] += 1
        return
    check_clean(run, path.name, problem)


# ------------------------------------------------------------- in-process

LIGHT = {
    "symlink loop": (_symlink_loop, "symbolic link loop"),
    "link to /dev/urandom": (_link("/dev/urandom"), "device"),
    "values 1e308": (_text("huge.bvh", lambda: small_bvh(3, value="1e308")), "too large"),
    "a folder": (lambda tmp: tmp, "folder"),
}


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("case", sorted(LIGHT))
def test_hostile_file_in_process(tmp_path, capsys, case):
    make, problem = LIGHT[case]
    path = make(tmp_path)
    COUNTS["tried"] += 1
    with pytest.raises(SystemExit) as exc:
        main(["info", str(path)])
    assert exc.value.code == 2
    assert problem in _one_line(capsys, path)
    COUNTS["clean"] += 1


HOSTILE_TOKENS = [
    "nan", "inf", "-inf", "1e308", "-1e308", "1e999", "{", "}", "", "JOINT", "ROOT", "End",
    "CHANNELS", "7", "-1", "0", "1e300", "Xposition", "\x00", "é", "MOTION", "Frames:",
]  # fmt: skip


def _one_line(capsys, path: Path) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and path.name in lines[0], err
    assert "Traceback" not in err and "Warning" not in err, err
    return lines[0]


def _info(path: Path, capsys, *extra: str) -> None:
    """``info`` either succeeds or exits 2 with one line naming the file, within 10 s."""
    COUNTS["tried"] += 1
    start = time.process_time()
    try:
        main(["info", str(path), *extra])
        capsys.readouterr()
    except SystemExit as exc:
        try:
            assert exc.code == 2
            _one_line(capsys, path)
        except AssertionError:
            COUNTS["failed"] += 1
            raise
    assert time.process_time() - start < 10
    COUNTS["clean"] += 1


@settings(max_examples=20, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_mutated_bvh_gives_one_line_or_a_motion(tmp_path_factory, capsys, data):
    lines = small_bvh(4).splitlines()
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(lines) - 1))
        words = lines[i].split() or [""]
        j = data.draw(st.integers(0, len(words) - 1))
        words[j] = data.draw(st.sampled_from(HOSTILE_TOKENS))
        lines[i] = " ".join(words)
    if data.draw(st.booleans()):
        lines = lines[: data.draw(st.integers(0, len(lines)))]
    path = tmp_path_factory.mktemp("bvh") / data.draw(st.sampled_from(["m.bvh", "m.bvh.gz"]))
    text = "\n".join(lines) + "\n"
    if path.suffix == ".gz":
        import gzip

        path.write_bytes(gzip.compress(text.encode("utf-8", "replace")))
    else:
        path.write_text(text, encoding="utf-8", errors="replace")
    _info(path, capsys)


@settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    value=st.sampled_from(["nan", "1e308", "-1e308", "x", "", "1e999", "0 0"]),
    at=st.integers(0, 2),
)
def test_mutated_amc_gives_one_line_or_a_motion(tmp_path_factory, capsys, value, at):
    frames = [f"{k}\nroot 0 0 0 0 0 0\nlfemur 1 2 3\n" for k in (1, 2, 3)]
    frames[at] = frames[at].replace("2 3", f"2 {value}")
    _info(amc_pair(tmp_path_factory.mktemp("amc"), frames), capsys)


@settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck))
@given(blob=st.binary(min_size=0, max_size=600))
def test_random_c3d_gives_one_line(tmp_path_factory, capsys, blob):
    path = tmp_path_factory.mktemp("c3d") / "m.c3d"
    path.write_bytes(blob)
    _info(path, capsys)


@settings(max_examples=6, deadline=None, suppress_health_check=list(HealthCheck))
@given(fps=st.sampled_from(["nan", "-30", "0", "1e300", "1e-300", "inf", "x", ""]))
def test_bad_index_csv_gives_one_line(tmp_path_factory, capsys, fps):
    root = tmp_path_factory.mktemp("index")
    (root / "INDEX.csv").write_text(f"file,category,label,fps\nm.bvh,walk,walk,{fps}\n")
    COUNTS["tried"] += 1
    with pytest.raises(SystemExit) as exc:
        main(["data", "list", "--data", str(root)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len([ln for ln in err.splitlines() if ln.strip()]) == 1 and "INDEX.csv" in err, err
    COUNTS["clean"] += 1


def test_index_csv_beyond_the_size_limit_is_refused(tmp_path, monkeypatch, capsys):
    (tmp_path / "INDEX.csv").write_text("file,category,label,fps\n" + "m.bvh,a,b,30\n" * 2000)
    monkeypatch.setenv("MARKOVMOTION_MAX_BYTES", "1000")
    with pytest.raises(SystemExit) as exc:
        main(["data", "list", "--data", str(tmp_path)])
    assert exc.value.code == 2
    assert "INDEX.csv: the file is more than 1000 bytes" in capsys.readouterr().err


# ------------------------------------------------------------- library behaviour


def test_bad_frames_kept_as_missing_or_refused(tmp_path):
    frames = [" ".join(["0"] * SMALL_CHANNELS)] * 5
    frames[2] = " ".join(["nan"] * SMALL_CHANNELS)
    frames[3] = "0 0"
    from hostile_corpus import bvh

    path = tmp_path / "s.bvh"
    path.write_text(bvh(SMALL_HIERARCHY, frames))
    motion, broken = read_bvh_stream(path)
    assert broken.tolist() == [False, False, True, True, False]
    assert motion.n_frames == 5 and (motion.rotations[broken] != motion.rotations[broken]).all()
    with pytest.raises(Exception, match="s.bvh:"):
        read_bvh(path)


def test_limits_are_read_from_the_environment(tmp_path, monkeypatch):
    path = tmp_path / "m.bvh"
    path.write_text(small_bvh(50))
    monkeypatch.setenv("MARKOVMOTION_MAX_FRAMES", "10")
    with pytest.raises(Exception, match="more than 10 frames.*MARKOVMOTION_MAX_FRAMES"):
        read_bvh(path)
    monkeypatch.setenv("MARKOVMOTION_MAX_JOINTS", "2")
    with pytest.raises(Exception, match="MARKOVMOTION_MAX_JOINTS"):
        read_bvh(path)


def test_resample_refuses_absurd_sizes():
    from conftest import make_motion

    from markovmotion.errors import LimitError

    motion = make_motion(n_frames=10, fps=0.001)
    with pytest.raises(LimitError, match="MARKOVMOTION_MAX_FRAMES"):
        motion.resample(1000)
    for bad in (0, -5, float("nan"), float("inf"), 1e9):
        with pytest.raises(ValueError):
            motion.resample(bad)


# ------------------------------------------------------------- outputs

# The child restores Ctrl-C's handler: a shell starts background jobs with SIGINT ignored,
# which the child would inherit (then no KeyboardInterrupt, and the test would wait 30 s).
WRITER = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
from markovmotion.io.files import atomic_write
with atomic_write(sys.argv[1], "wb") as fh:
    fh.write(b"x" * 1000)
    fh.flush()
    print("writing", flush=True)
    time.sleep(60)
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_temporary_output_removed_when_killed(tmp_path, sig):
    out = tmp_path / "out.bin"
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert proc.stdout.readline().strip() == "writing"
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    proc.send_signal(sig)
    proc.wait(timeout=30)
    proc.stdout.close()
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


def test_a_broken_video_is_one_line_in_a_real_process(tmp_path, monkeypatch):
    """A video cut short (no index: FFmpeg says "moov atom not found" on its own) gives one
    line of ours; FFmpeg's own log is held back (``OPENCV_FFMPEG_LOGLEVEL``)."""
    real = data_root().parent / "video" / "pose2sim_balancing" / "cam0.mp4"
    broken = tmp_path / "cam0.mp4"
    broken.write_bytes(real.read_bytes()[: len(real.read_bytes()) // 2])
    monkeypatch.delenv("OPENCV_FFMPEG_LOGLEVEL", raising=False)  # set by this process's imports
    run = run_cli(["video", "cameras", str(tmp_path / "no.toml"), str(broken)])
    assert "no such calibration file" in run.stderr  # the calibration is checked first
    (tmp_path / "Calib.toml").write_text(
        '[cam_1]\nname = "cam0"\nsize = [272.0, 480.0]\nmatrix = [[420.0, 0.0, 136.0], '
        "[0.0, 420.0, 240.0], [0.0, 0.0, 1.0]]\ndistortions = [0.0, 0.0, 0.0, 0.0]\n"
        "rotation = [0.0, 0.0, 0.0]\ntranslation = [0.0, 0.0, 3.0]\nfisheye = false\n"
    )
    run = run_cli(["video", "cameras", str(tmp_path / "Calib.toml"), str(broken)])
    check_clean(run, "cam0.mp4", "cannot read")

"""The command line on bad input: exit code 2, one line on stderr naming the file, no traceback."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import make_motion

from markovmotion.cli import main
from markovmotion.io.bvh import bvh_text

BAD_FILES = {
    "missing.bvh": None,
    "truncated.bvh": lambda: bvh_text(make_motion(n_frames=5))[:-60],
    "garbage.bvh.gz": lambda: "not gzip at all",
    "empty.bvh": lambda: "",
    "07_01.amc": lambda: ":FULLY-SPECIFIED\n1\nroot 0 0 0 0 0 0\n",  # no 07.asf beside it
    "damaged.c3d": lambda: "C3D? no.\n" * 20,
    "walk.fbx": lambda: "Kaydara FBX Binary",
}


def _make(tmp_path, name: str):
    path = tmp_path / name
    text = BAD_FILES[name]
    if text is not None:
        path.write_bytes(text().encode())
    return path


def _one_error_line(stderr: str, path) -> None:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert str(path) in lines[0]
    assert "Traceback" not in stderr


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_info_on_bad_file_exits_2_with_one_line(tmp_path, capsys, name):
    path = _make(tmp_path, name)
    with pytest.raises(SystemExit) as info:
        main(["info", str(path)])
    assert info.value.code == 2
    captured = capsys.readouterr()
    _one_error_line(captured.err, path)
    assert captured.out == ""


@pytest.mark.parametrize("command", ["info", "convert"])
def test_console_script_on_bad_file(tmp_path, command):
    """The real process: exit status and stderr as a user sees them."""
    path = _make(tmp_path, "truncated.bvh")
    args = [str(path)] + ([str(tmp_path / "out.bvh")] if command == "convert" else [])
    run = subprocess.run(
        [sys.executable, "-m", "markovmotion", command, *args],  # as python3 -m markovmotion
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 2
    _one_error_line(run.stderr, path)
    assert not (tmp_path / "out.bvh").exists()


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (["dualhmm", "train", "--out", "{tmp}/partner.txt"], "models are written as .npz"),
        (["vlmm", "train", "--out", "{tmp}/vlmm.bvh"], "models are written as .npz"),
        (["gait", "train", "--out", "{tmp}/average.npz.gz"], "models are written as .npz"),
        (
            ["dualhmm", "respond", "--model", "m.npz", "--input", "a.bvh", "--out", "{tmp}/b.txt"],
            "motions are written as BVH",
        ),
        (
            ["vlmm", "predict", "--model", "m.npz", "--input", "a.bvh", "--out", "{tmp}/p.txt"],
            "motions are written as BVH",
        ),
        (["vlmm", "evaluate", "--model", "m.npz", "--plot", "{tmp}/et.txt"], "unknown image"),
    ],
)
def test_wrong_output_suffix_is_refused_before_any_work(tmp_path, capsys, args, problem):
    args = [a.format(tmp=tmp_path) for a in args]
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    _one_error_line(err, args[args.index("--out" if "--out" in args else "--plot") + 1])
    assert problem in err
    assert list(tmp_path.iterdir()) == []


def test_output_below_a_file_names_the_output(tmp_path, capsys):
    source = tmp_path / "walk.bvh"
    source.write_text(bvh_text(make_motion(n_frames=3)))
    out = source / "copy.bvh"
    with pytest.raises(SystemExit) as info:
        main(["convert", str(source), str(out)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    _one_error_line(err, out)
    assert "is a file, not a folder" in err
    assert ".tmp" not in err


def test_stream_reader_names_the_users_file(tmp_path):
    """A damaged stream (a NaN frame, the last frame missing) is reported under the user's
    path."""
    from markovmotion.cli.hmm import read_stream
    from markovmotion.errors import MotionFormatError

    lines = bvh_text(make_motion(n_frames=6)).splitlines()
    lines[-3] = "nan " + lines[-3].split(maxsplit=1)[1]  # one bad frame
    path = tmp_path / "take.bvh"
    path.write_text("\n".join(lines[:-1]) + "\n")  # and the last frame missing
    with pytest.raises(MotionFormatError) as info:
        read_stream(path)
    assert info.value.path == str(path)


def test_unknown_test_trial_is_refused(mocap, capsys):
    """A mistyped held-out trial must not silently put every take into training."""
    with pytest.raises(SystemExit) as info:
        main(["dualhmm", "train", "--test-trials", "99", "--out", "never.npz"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "trial 99" in err and "Traceback" not in err


def test_errors_show_paths_as_the_user_gives_them(tmp_path, monkeypatch, capsys):
    """A collection file's error names it relative to where the command runs (never the
    absolute layout) and gives no Python advice (issue 22); the browser sees no server path."""
    from markovmotion.cli import relative_paths
    from markovmotion.errors import MotionFormatError
    from markovmotion.web.library import MotionLibrary

    (tmp_path / "data" / "c").mkdir(parents=True)
    take = tmp_path / "data" / "c" / "x.c3d"
    take.write_bytes(b"")
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    said = relative_paths(f"no take in '{take}' (see /no/such/place) 3 m/s")
    assert said == "no take in '../data/c/x.c3d' (see /no/such/place) 3 m/s"
    with pytest.raises(SystemExit):
        main(["info", "../data/c/x.c3d"])  # markers where a skeleton is needed
    with pytest.raises(SystemExit):
        main(["convert", str(take), "o.bvh"])
    lines = capsys.readouterr().err.splitlines()
    assert all("markovmotion.io" not in ln for ln in lines), lines
    assert lines[0].startswith("error: ../data/c/x.c3d: ")  # as typed
    assert lines[1].startswith(f"error: {take}: ")  # as typed, absolute
    library = MotionLibrary(tmp_path / "data")
    shown = library.public(str(MotionFormatError(take, "bad", 3)))
    assert shown == "c/x.c3d:3: bad" and str(tmp_path) not in library.public(f"{tmp_path}/data")


@pytest.mark.parametrize("method", ["apf", "monocular"])
def test_a_missing_video_is_named_not_its_camera_file(tmp_path, capsys, method):
    """``track --video`` of a file that does not exist, beside a real cameras.json: the
    video is what is missing, not the camera file."""
    (tmp_path / "cameras.json").write_text("{}")
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(tmp_path / "cam9.mp4"), "--method", method])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "cam9.mp4: no such video file" in err
    assert "cameras.json" not in err and len(err.strip().splitlines()) == 1


def test_index_mistakes_say_what_to_do(tmp_path, capsys):
    """A take given where an INDEX.csv is asked for, a row with an open quote, a label the
    index lacks, a partner with no row: one line each, saying what is wrong (not "get the
    data")."""
    from markovmotion.data.index import data_root

    take = next(data_root().glob("buetepage/shaking/*.c3d"))
    index = tmp_path / "INDEX.csv"
    index.write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
        'a.c3d,lab,"p9,rec0,interaction,handshake,b.c3d,30,10,my capture\n'
        "b.c3d,lab,p9,rec0,interaction,handshake,a.c3d,30,10,my capture\n"
    )
    (tmp_path / "one_way").mkdir()  # each take listed one way only: B has no row
    (tmp_path / "one_way" / "INDEX.csv").write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
        "a.c3d,lab,p9,rec0,interaction,handshake,b.c3d,30,10,my capture\n"
    )
    for args, message in (
        (["dualhmm", "crossval", "--data", str(take)], "is a file, not an INDEX.csv"),
        (["data", "list", "--data", str(tmp_path)], "check its quotes and commas"),
        (["dualhmm", "train", "--labels", "handshak", "--out", str(tmp_path / "m.npz")], "its two-person labels: "),
        (["dualhmm", "crossval", "--data", str(tmp_path / "one_way")], "give it a row of its own"),
    ):  # fmt: skip
        with pytest.raises(SystemExit) as stop:
            main(args)
        err = capsys.readouterr().err
        assert stop.value.code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_no_help_text_loses_square_brackets():
    """Typer shows help through Rich, whose markup takes ``[word]`` as a style and drops it
    ("needs [camera]" was shown as "needs "): no option's help may hold one."""
    import re

    import click
    import typer

    from markovmotion.cli import _register, app

    _register()

    def walk(command: click.Command, path: str):
        for param in command.params:
            yield path, param
        for name, sub in getattr(command, "commands", {}).items():
            yield from walk(sub, f"{path} {name}")

    tag = re.compile(r"(?<!\\)\[[a-zA-Z/ =_-]+\]")
    found = [
        f"{path} {param.name}: {param.help}"
        for path, param in walk(typer.main.get_command(app), "markovmotion")
        if getattr(param, "help", None) and tag.search(param.help)
    ]
    assert not found, found


def test_label_and_labels_are_both_spellings_everywhere():
    """``--label`` and ``--labels`` are taken by every command that selects labels (a new user
    wrote both), and a repeated or comma-separated list is one list."""
    import typer

    from markovmotion.cli import _register, app
    from markovmotion.cli.options import split_labels

    _register()  # the subcommands are attached when the command line first runs
    root = typer.main.get_command(app)
    for group, command in (("dualhmm", "train"), ("dualhmm", "evaluate"), ("dualhmm", "crossval"),
                           ("chain", "train"), ("chain", "evaluate"), ("chain", "crossval"),
                           ("vlmm", "train"), ("vlmm", "evaluate")):  # fmt: skip
        cmd = root.commands[group].commands[command]
        names = {o for p in cmd.params for o in getattr(p, "opts", ())}
        assert {"--label", "--labels"} <= names, (group, command)
    assert split_labels(["a,b", "c"]) == ["a", "b", "c"]
    assert split_labels(None) is None and split_labels([" , "]) is None


@pytest.mark.parametrize(
    "raised, code, line",
    [
        (KeyboardInterrupt(), 130, "interrupted"),
        ("numba", 130, "interrupted"),  # a Numba kernel wraps the Ctrl-C in a SystemError
        (MemoryError("Unable to allocate 21.8 GiB for an array"), 2, "out of memory: Unable"),
    ],
)
def test_ctrl_c_and_out_of_memory_are_one_line(monkeypatch, capsys, raised, code, line):
    """Ctrl-C stops with one line and exit 130 (it was silent; inside a Numba kernel a
    79-line traceback and exit 1); running out of memory is one line, exit 2 (a traceback)."""
    import markovmotion.cli.motion as motion_cli

    def boom(*args, **kwargs):
        if raised != "numba":
            raise raised
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("CPUDispatcher(...) returned a result with an exception set")  # noqa: B904 (as Numba does)

    monkeypatch.setattr(motion_cli, "read_listed_motion", boom)
    with pytest.raises(SystemExit) as exit_:
        main(["info", "x.bvh"])
    assert exit_.value.code == code
    err = capsys.readouterr().err
    assert (
        [ln for ln in err.splitlines() if ln.strip()][-1].startswith(
            ("interrupted", "error: out of memory")
        )
        and line in err
        and "Traceback" not in err
    )


def test_square_brackets_in_a_message_are_shown(tmp_path, capsys):
    """Rich read ``[int_cam01_img]`` (a Pose2Sim section, a file name) as a style and dropped
    it from errors and notes: ``fish.toml:  is a fisheye camera``."""
    from markovmotion.progress import note

    with pytest.raises(SystemExit):
        main(["info", str(tmp_path / "[int_cam01_img].bvh")])
    assert "[int_cam01_img].bvh" in capsys.readouterr().err
    note("section [int_cam01_img] kept")
    assert "section [int_cam01_img] kept" in capsys.readouterr().err

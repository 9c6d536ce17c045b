"""Progress off a terminal: plain lines for long work, nothing for short work."""

from __future__ import annotations

import itertools

from markovmotion import progress


def test_long_work_logs_plain_lines_off_a_terminal(monkeypatch, capsys):
    assert not progress.err_console.is_terminal  # pytest captures stderr
    monkeypatch.setattr(progress, "LOG_EVERY", 0.0)
    assert list(progress.track(range(3), "fitting")) == [0, 1, 2]
    lines = capsys.readouterr().err.splitlines()
    assert [ln.split(",")[0] for ln in lines] == ["fitting: 1/3", "fitting: 2/3", "fitting: 3/3"]


def test_long_work_that_printed_a_line_prints_its_end(monkeypatch, capsys):
    """A line came at 1/3 (its 30 s were up); the work ends before the next 30 s: the end is
    still printed, so that a log does not look as if the last steps were skipped."""
    clock = itertools.chain([0.0], itertools.count(40.0))  # 40 s, then a second a call
    monkeypatch.setattr(progress.time, "monotonic", lambda: next(clock))
    assert list(progress.track(range(3), "leave-one-out")) == [0, 1, 2]
    lines = capsys.readouterr().err.splitlines()
    assert [ln.split(",")[0] for ln in lines] == ["leave-one-out: 1/3", "leave-one-out: 3/3"]


def test_short_work_prints_nothing(capsys):
    assert list(progress.track(range(3), "fitting")) == [0, 1, 2]
    assert capsys.readouterr().err == ""


def test_video_tracking_reports_its_frames(monkeypatch, capsys):
    """``track`` on the real 4-view video: the particle filter's frames, counted against the
    videos' own length, and (the guide, MediaPipe) each camera's pass, as progress lines."""
    from markovmotion.cli import main
    from markovmotion.data.index import data_root

    monkeypatch.setattr(progress, "LOG_EVERY", 0.0)
    video = data_root().parent / "video" / "pose2sim_balancing"
    main(["track", "--video", str(video), "--max-frames", "3", "--particles", "10",
          "--layers", "2"])  # fmt: skip
    lines = [ln.split(",")[0] for ln in capsys.readouterr().err.splitlines()]
    assert [ln for ln in lines if ln.startswith("tracking")][-1] == "tracking: 3/3"
    assert {f"MediaPipe cam{k}: 3/3" for k in range(4)} <= set(lines)


def test_the_librarys_log_warnings_are_notes_once_each_on_the_command_line(capsys):
    """A warning logged once per model fitted (a cross-validation fits dozens) is one note
    and a count at the end, on stderr; the logger is left as it was."""
    import logging

    from markovmotion.cli import _log_as_notes

    log = logging.getLogger("markovmotion.models.hmm.gaussian")
    with _log_as_notes():
        for n in (3103, 3200, 3300):
            log.warning("Fitting a model with %d free scalar parameters", n)
        log.warning("another kind")
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "note: Fitting a model with 3103 free scalar parameters",
        "note: another kind",
        "note: 3 times in all, the first: Fitting a model with 3103 free scalar parameters",
    ]
    assert logging.getLogger("markovmotion").propagate
    assert not any(
        type(h).__name__ == "NoteOnce" for h in logging.getLogger("markovmotion").handlers
    )


def test_a_task_reused_for_several_files_says_each_end_once(monkeypatch, capsys):
    """One task reused file after file (``data fetch``'s bytes): a file that printed a line
    prints its end once; later updates of the ended task print nothing more."""
    clock = itertools.chain([0.0], itertools.count(40.0))  # 40 s, then a second a call
    monkeypatch.setattr(progress.time, "monotonic", lambda: next(clock))
    with progress.progress_bar() as bar:
        task = bar.add_task("bytes", total=None)
        for name in ("a", "b", "c"):
            bar.update(task, description=name, completed=0, total=None)
            for done in (500, 1000):
                bar.update(task, completed=done, total=1000)
            bar.update(task, visible=False)
    lines = [ln.split(",")[0] for ln in capsys.readouterr().err.splitlines()]
    assert lines == ["a: 0", "a: 1000/1000"]

"""Progress off a terminal: plain lines for long work, nothing for short work."""

from __future__ import annotations

from markovmotion import progress


def test_long_work_logs_plain_lines_off_a_terminal(monkeypatch, capsys):
    assert not progress.err_console.is_terminal  # pytest captures stderr
    monkeypatch.setattr(progress, "LOG_EVERY", 0.0)
    assert list(progress.track(range(3), "fitting")) == [0, 1, 2]
    lines = capsys.readouterr().err.splitlines()
    assert [ln.split(",")[0] for ln in lines] == ["fitting: 1/3", "fitting: 2/3", "fitting: 3/3"]


def test_short_work_prints_nothing(capsys):
    assert list(progress.track(range(3), "fitting")) == [0, 1, 2]
    assert capsys.readouterr().err == ""

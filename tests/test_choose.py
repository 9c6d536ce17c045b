"""The one settings choice of the two-person families (evaluate/choose.py): folds by pairs of
people, fits reused across generation-only settings, the pick is the lowest error, grids typed
from a model's defaults; and the one take-naming rule of their reports."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from markovmotion.evaluate import choose
from markovmotion.evaluate.takes import take_names


def test_folds_are_pairs_of_people_when_there_are_two_or_more_else_takes():
    assert choose.fold_groups(["p1", "p1", "p2"], ["a", "b", "c"]) == ["p1", "p1", "p2"]
    assert choose.fold_groups(["p1", "p1"], ["a", "b"]) == ["a", "b"]
    assert choose.fold_groups(None, ["a", "b"]) == ["a", "b"]
    with pytest.raises(ValueError, match="unique"):
        choose.fold_groups(["p1", "p1"], ["a", "a"])


def test_choice_never_fits_on_the_held_out_group_and_picks_the_lowest_error():
    groups = ["p1", "p1", "p2", "p3"]
    grid = [{"k": 1, "blend": 0}, {"k": 1, "blend": 5}, {"k": 2, "blend": 0}]
    fits: list[tuple[int, list[int]]] = []

    def fit(settings, train):
        fits.append((settings["k"], train))
        return settings["k"]

    def score(model, settings, test):  # error per frame: k 1 blend 5 is best
        assert all(groups[i] not in {groups[j] for j in fits[-1][1]} for i in test)
        return float(len(test) * (abs(model - 1) + abs(settings["blend"] - 5))), len(test)

    chosen = choose.choose_settings(grid, groups, fit, score, generation_only={"blend"})
    assert chosen["settings"] == {"k": 1, "blend": 5}
    assert chosen["inner_mm"] == {"k=1,blend=0": 5.0, "k=1,blend=5": 0.0, "k=2,blend=0": 6.0}
    # one fit per held-out pair and distinct trained setting (blend reuses the fit)
    assert [k for k, _ in fits] == [1, 2] * 3
    assert [train for _, train in fits[::2]] == [[2, 3], [0, 1, 3], [0, 1, 2]]


def test_grid_values_take_the_defaults_types_and_tied_parameters_move_together():
    defaults = {"n": 3, "rate": 0.5, "mode": "a", "size": None, "roles": "one"}
    grid = choose.parse_grid("n+size=1,2; rate=1; mode=b", defaults)
    assert grid == [
        {"n": 1, "size": 1, "rate": 1.0, "mode": "b"},
        {"n": 2, "size": 2, "rate": 1.0, "mode": "b"},
    ]
    assert isinstance(grid[0]["rate"], float)
    for bad, what in (("m=1", "PARAM one of"), ("n+m=1", "PARAM one of"), ("rate=x", "float")):
        with pytest.raises(ValueError, match=what):
            choose.parse_grid(bad, defaults)


@dataclass(frozen=True)
class _Entry:
    name: str
    label: str
    file: str


def test_take_names_keep_every_take_when_stems_collide():
    def pair(label: str, a: str, b: str, folder: str = "x") -> tuple[_Entry, _Entry]:
        return _Entry(a, label, f"{folder}/{a}.c3d"), _Entry(b, label, f"{folder}/{b}.c3d")

    pairs = [pair("handshake", "u1", "u2"), pair("wave", "u1", "u2"), pair("wave", "u3", "u4"),
             pair("wave", "u3", "u4", "y")]  # fmt: skip
    names = list(take_names(pairs).values())
    assert names[:2] == ["handshake u1+u2", "wave u1+u2"]
    assert names[2:] == ["x/u3.c3d+x/u4.c3d", "y/u3.c3d+y/u4.c3d"]
    assert list(take_names(pairs[:1]).values()) == ["u1+u2"]


def test_choosing_on_takes_of_one_pair_of_people_says_so_once(capsys):
    """Inner folds on one pair of people's takes leave one take out, scoring each setting on
    people it learnt from: said once on stderr; two pairs or more, or the outer folds, say
    nothing."""
    from markovmotion.evaluate.choose import _note_once, fold_groups

    _note_once.cache_clear()
    assert fold_groups(["p1", "p1"], ["a", "b"], choosing=True) == ["a", "b"]
    assert fold_groups(["p1", "p1"], ["a", "b"], choosing=True) == ["a", "b"]
    err = capsys.readouterr().err
    assert err.count("chosen by leaving one take out") == 1 and "(p1)" in err
    assert fold_groups(["p1", "p2"], ["a", "b"], choosing=True) == ["p1", "p2"]
    assert fold_groups(["p3", "p3"], ["a", "b"]) == ["a", "b"]
    assert capsys.readouterr().err == ""


def test_leaving_takes_out_without_people_says_so(capsys):
    """Takes whose INDEX.csv names no people (``subject`` empty or absent) are left out one
    at a time, and the line says that their people may be in the training folds."""
    from markovmotion.evaluate.choose import _note_once, fold_groups

    _note_once.cache_clear()
    assert fold_groups(["", ""], ["a", "b"]) == ["a", "b"]
    assert fold_groups(None, ["a", "b"]) == ["a", "b"]
    err = capsys.readouterr().err
    assert err.count("names no people") == 1

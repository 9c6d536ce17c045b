"""Bad option values: refused while the options are parsed (before any work), as one line
naming the option, with exit code 2 (issue 14)."""

from __future__ import annotations

import math
import time

import pytest
import typer
from hostile_corpus import COUNTS, check_clean, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markovmotion.cli import main
from markovmotion.cli.options import RANGES, check_range

# (command, option, kind): the options of the issue; the other arguments need not exist,
# since a bad option is refused before any file is opened
OPTIONS = [
    (["info", "x.bvh"], "--fps", "fps"),
    (["convert", "x.bvh", "y.bvh"], "--fps", "fps"),
    (["convert", "x.bvh", "y.bvh"], "--resample", "fps"),
    (["dualhmm", "respond", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--fps", "fps"),
    (["dualhmm", "respond", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--window", "window"),
    (["dualhmm", "train", "--out", "m.npz"], "--states", "states"),
    (["vlmm", "predict", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--fps", "fps"),
    (["vlmm", "predict", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--horizon", "horizon"),
    (["vlmm", "generate", "--model", "m.npz", "--out", "y.bvh"], "--seconds", "seconds"),
    (["chain", "respond", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--fps", "fps"),
    (["chain", "respond", "--model", "m.npz", "--input", "x.bvh", "--out", "y.bvh"], "--hypotheses", "hypotheses"),
    (["gait", "synthesize", "--model", "m.npz", "--out", "y.bvh"], "--seed", "seed"),
    (["gait", "synthesize", "--model", "m.npz", "--out", "y.bvh"], "--steps", "steps"),
    (["render", "x.bvh", "--out", "y.gif"], "--fps", "fps"),
    (["render", "x.bvh", "--out", "y.gif"], "--title", "title"),
]  # fmt: skip

INTEGER_KINDS = {"window", "states", "seed", "steps", "hypotheses"}


def _bad_values(kind: str) -> st.SearchStrategy[str]:
    """Values outside RANGES[kind], as the user would type them."""
    r = RANGES[kind]
    if r.max_length is not None:
        return st.integers(r.max_length + 1, 5000).map(lambda n: "a" * n)
    lo, hi = r.low(), r.high()
    if kind in INTEGER_KINDS:
        return st.one_of(
            st.integers(max_value=int(lo) - 1), st.integers(min_value=int(hi) + 1)
        ).map(str)
    return st.one_of(
        st.sampled_from(["nan", "inf", "-inf", "0", "-30", "1e308", "1e-300", "-0"]),
        st.floats(max_value=lo, exclude_max=True, allow_nan=False, allow_infinity=False),
        st.floats(min_value=hi, exclude_min=True, allow_nan=False),
    ).map(str)


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_out_of_range_option_is_one_line_before_any_work(capsys, data):
    args, option, kind = data.draw(st.sampled_from(OPTIONS))
    value = data.draw(_bad_values(kind))
    COUNTS["tried"] += 1
    start = time.process_time()
    with pytest.raises(SystemExit) as exc:
        main([*args, option, value])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert exc.value.code == 2, err
    assert len(lines) == 1 and f"'{option}'" in lines[0], err
    assert "Traceback" not in err
    assert time.process_time() - start < 10
    COUNTS["clean"] += 1


@settings(max_examples=40, deadline=None)
@given(kind=st.sampled_from(sorted(RANGES)), value=st.floats() | st.integers())
def test_check_range_agrees_with_the_declared_range(kind, value):
    r = RANGES[kind]
    if r.max_length is not None:
        return
    lo, hi = r.low(), r.high()
    ok = math.isfinite(value) and (value > lo if r.lo_open else value >= lo) and value <= hi
    if ok:
        assert check_range(kind, "--x", value) == value
    else:
        with pytest.raises(typer.BadParameter) as exc:
            check_range(kind, "--x", value)
        assert exc.value.param_hint == "'--x'" and "got" in str(exc.value)


@pytest.mark.parametrize(
    "args",
    [
        ["convert", "x.bvh", "y.bvh", "--resample", "nan"],
        ["dualhmm", "train", "--out", "m.npz", "--states", "0"],
        ["render", "x.bvh", "--out", "y.gif", "--fps", "1e6"],
    ],
)
def test_real_process_exit_code_and_one_line(args):
    """The real console entry point: exit status 2 and one line, no boxed usage panel."""
    check_clean(run_cli(args), f"'{args[-2]}'")

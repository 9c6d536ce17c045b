"""``dualhmm respond --input`` reads person A through the same checked reader as every other
command (issue 22): a NaN, infinite, non-numeric or extra value, or bytes that are not text,
is one line naming the file and line, exit 2, the very line ``markovmotion info`` prints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile_corpus import SMALL_CHANNELS, SMALL_HIERARCHY, bvh

from markovmotion.cli import main
from markovmotion.io.bvh import read_bvh
from markovmotion.models.hmm.dual import DualHMM


def _frames(rng: np.random.Generator, n: int) -> list[str]:
    rows = [np.r_[0.0, 90.0, 0.0, rng.normal(0, 20, SMALL_CHANNELS - 3)] for _ in range(n)]
    return [" ".join(f"{v:.3f}" for v in row) for row in rows]


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    """A dual HMM of the small hierarchy, so that A's files below fit it but for their damage."""
    folder = tmp_path_factory.mktemp("dual")
    rng = np.random.default_rng(0)
    for name in ("a", "b"):
        (folder / f"{name}.bvh").write_text(bvh(SMALL_HIERARCHY, _frames(rng, 60)))
    pair = (read_bvh(folder / "a.bvh"), read_bvh(folder / "b.bvh"))
    dual = DualHMM(n_states=2, n_iter=2, window=4, points="all", blend_window=1).fit([pair])
    dual.save(folder / "m.npz")
    return folder / "m.npz"


def _damaged(row: str, case: str) -> str:
    values = row.split()
    if case == "extra value":
        return row + " 1"
    if case == "missing value":
        return " ".join(values[:-1])
    return " ".join([{"NaN": "nan", "infinity": "-inf", "non-numeric": "abc"}[case]] + values[1:])


CASES = ["NaN", "infinity", "non-numeric", "extra value", "missing value", "invalid UTF-8"]


def _one_error(capsys, args: list[str]) -> str:
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("case", CASES)
def test_respond_refuses_what_info_refuses(model, tmp_path, capsys, case):
    rows = _frames(np.random.default_rng(1), 8)
    path = tmp_path / "a_damaged.bvh"
    if case == "invalid UTF-8":
        data = bvh(SMALL_HIERARCHY, rows).encode()
        path.write_bytes(data.replace(rows[3].encode(), b"0 \xff\xfe " + rows[3].encode(), 1))
    else:
        rows[3] = _damaged(rows[3], case)
        path.write_text(bvh(SMALL_HIERARCHY, rows))
    out = tmp_path / "b.bvh"
    said = _one_error(capsys, ["dualhmm", "respond", "--model", str(model)]
                      + ["--input", str(path), "--out", str(out)])  # fmt: skip
    assert said == _one_error(capsys, ["info", str(path)])
    assert path.name in said and ":" in said.split(path.name, 1)[1]  # the line is named
    assert not out.exists()


def test_respond_answers_an_intact_file(model, tmp_path, capsys):
    """The same small file undamaged is answered: B has A's frames."""
    path = tmp_path / "a.bvh"
    path.write_text(bvh(SMALL_HIERARCHY, _frames(np.random.default_rng(2), 8)))
    main(["dualhmm", "respond", "--model", str(model), "--input", str(path)]
         + ["--out", str(tmp_path / "b.bvh")])  # fmt: skip
    assert read_bvh(tmp_path / "b.bvh").n_frames == 8

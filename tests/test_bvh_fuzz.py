"""Property-based fuzzing of the BVH reader: damaged text gives a Motion or a MotionFormatError.

Characters, tokens, lines and keyword values are deleted, duplicated, replaced
or inserted, the text truncated, braces swapped. It found ``Frames: nan`` and
``Frames: inf`` escaping as ValueError / OverflowError (fixed in io/bvh.py).
"""

from __future__ import annotations

import re

import pytest
from conftest import make_motion
from hypothesis import given, settings
from hypothesis import strategies as st

from markovmotion import Motion, MotionFormatError
from markovmotion.io.bvh import bvh_text, read_bvh

VALID = bvh_text(make_motion(n_frames=3), precision=6)

# Things a damaged or hand-edited file may hold where a token belongs.
TOKENS = [
    "nan", "NaN", "inf", "-inf", "1e999", "-1e400", "1e-400", "0", "-0", "7", "6", "-1", "3.5",
    "2.", ".5", "1_0", "0x1f", "+-1", "1e", "--", "١", "½", "", "{", "}", "{}", "ROOT", "JOINT",
    "End", "Site", "OFFSET", "CHANNELS", "HIERARCHY", "MOTION", "Frames:", "Frame", "Time:",
    "Xposition", "Zrotation", "Qrotation", "hips", "\x00", "\t", "\r",
]  # fmt: skip
CHARS = list("{}.-+eE0123456789 \t\n\r:xX") + ["\x00", "é", "\u2028", "\x85"]


def _pick(draw, n: int) -> int:
    return draw(st.integers(0, max(n - 1, 0)))


def _char_edit(draw, text: str) -> str:
    i = _pick(draw, len(text))
    kind = draw(st.sampled_from(["delete", "duplicate", "replace", "insert"]))
    c = draw(st.sampled_from(CHARS))
    return {
        "delete": text[:i] + text[i + 1 :],
        "duplicate": text[: i + 1] + text[i:],
        "replace": text[:i] + c + text[i + 1 :],
        "insert": text[:i] + c + text[i:],
    }[kind]


def _token_edit(draw, text: str) -> str:
    parts = re.split(r"(\s+)", text)  # tokens at even indices, whitespace at odd ones
    i = 2 * _pick(draw, (len(parts) + 1) // 2)
    kind = draw(st.sampled_from(["delete", "duplicate", "replace", "insert"]))
    tok = draw(st.sampled_from(TOKENS))
    if kind == "delete":
        parts[i] = ""
    elif kind == "duplicate":
        parts[i] = f"{parts[i]} {parts[i]}"
    elif kind == "replace":
        parts[i] = tok
    else:
        parts[i] = f"{tok} {parts[i]}"
    return "".join(parts)


def _line_edit(draw, text: str) -> str:
    lines = text.split("\n")
    i, j = _pick(draw, len(lines)), _pick(draw, len(lines))
    kind = draw(st.sampled_from(["delete", "duplicate", "swap", "garbage"]))
    if kind == "delete":
        del lines[i]
    elif kind == "duplicate":
        lines.insert(i, lines[i])
    elif kind == "swap":
        lines[i], lines[j] = lines[j], lines[i]
    else:
        lines[i] = " ".join(draw(st.lists(st.sampled_from(TOKENS), max_size=5)))
    return "\n".join(lines)


def _value_edit(draw, text: str) -> str:
    """Replace the value after a keyword (the header's numbers hide among many tokens)."""
    key = draw(st.sampled_from(["Frames:", "Time:", "CHANNELS", "OFFSET"]))
    found = list(re.finditer(rf"{key}([ \t]+)(\S+)", text))
    if not found:
        return text
    m = found[_pick(draw, len(found))]
    return text[: m.start(2)] + draw(st.sampled_from(TOKENS)) + text[m.end(2) :]


def _truncate(draw, text: str) -> str:
    return text[: _pick(draw, len(text))]


def _swap_brace(draw, text: str) -> str:
    braces = [m.start() for m in re.finditer(r"[{}]", text)]
    if not braces:
        return text
    i = braces[_pick(draw, len(braces))]
    return text[:i] + ("}" if text[i] == "{" else "{") + text[i + 1 :]


EDITS = [_value_edit, _token_edit, _char_edit, _line_edit, _truncate, _swap_brace]


@st.composite
def damaged_bvh(draw) -> str:
    text = VALID
    for _ in range(draw(st.integers(1, 3))):
        text = draw(st.sampled_from(EDITS))(draw, text)
    return text


@pytest.fixture(scope="module")
def fuzz_path(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz") / "damaged.bvh"


@settings(max_examples=1000, deadline=None, database=None)
@given(text=damaged_bvh())
def test_damaged_bvh_reads_or_raises_format_error(fuzz_path, text):
    fuzz_path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        motion = read_bvh(fuzz_path)
    except MotionFormatError as exc:
        assert str(fuzz_path) in str(exc)
        assert "\n" not in str(exc).strip()
    else:
        assert isinstance(motion, Motion)
        assert motion.n_frames >= 1


def test_undamaged_text_reads(fuzz_path):
    """The fuzzing starts from a file that reads."""
    fuzz_path.write_text(VALID)
    assert read_bvh(fuzz_path).n_frames == 3

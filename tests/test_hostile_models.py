"""Tampered model files: one line naming the file and the field, never a traceback or a
model that loads with bad values (issue 14). Also the numerics of GaussianHMM.fit."""

from __future__ import annotations

import copy
import json
import zipfile

import numpy as np
import pytest
from hostile_corpus import COUNTS, check_clean, run_cli, write_npz, zip_bomb_model
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markovmotion.errors import ModelFormatError
from markovmotion.models.hmm.gaussian import GaussianHMM
from markovmotion.persist import FORMAT, load_npz
from markovmotion.state import estimator_state


@pytest.fixture(scope="module")
def valid():
    """(header, arrays) of a small fitted GaussianHMM saved as a model file."""
    rng = np.random.default_rng(0)
    hmm = GaussianHMM(n_components=2, n_iter=3).fit(rng.normal(size=(60, 3)))
    arrays: dict[str, np.ndarray] = {}
    state = estimator_state(hmm, "model", arrays)
    header = {
        "format": FORMAT,
        "format_version": 1,
        "library_version": "test",
        "kind": "gait-hsmm",
        "model": state,
    }
    return header, arrays


def test_the_untampered_file_loads(valid, tmp_path):
    header, arrays = valid
    back, a = load_npz(write_npz(tmp_path / "ok.npz", header, arrays))
    assert back["model"]["class"] == "GaussianHMM" and set(a) == set(arrays)


def _set(path: list, value):
    def mutate(header, arrays):
        node = header
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        return header, arrays

    return mutate


def _drop(path: list):
    def mutate(header, arrays):
        node = header
        for key in path[:-1]:
            node = node[key]
        node.pop(path[-1])
        return header, arrays

    return mutate


def _array(name: str, make):
    def mutate(header, arrays):
        arrays = dict(arrays)
        arrays[name] = make(arrays[name])
        return header, arrays

    return mutate


def _without(name: str):
    def mutate(header, arrays):
        return header, {k: v for k, v in arrays.items() if k != name}

    return mutate


def _nan_at(a):
    a = a.astype(float).copy()
    a.flat[0] = np.nan
    return a


MUTATIONS = {
    "header a list": lambda h, a: ([1, 2], a),
    "header null": lambda h, a: (None, a),
    "header a string": lambda h, a: ("model", a),
    "format_version a string": _set(["format_version"], "1"),
    "format_version a float": _set(["format_version"], 1.0),
    "format_version true": _set(["format_version"], True),
    "format_version 2": _set(["format_version"], 2),
    "no format_version": _drop(["format_version"]),
    "kind a number": _set(["kind"], 3),
    "kind missing": lambda h, a: ({k: v for k, v in h.items() if k != "kind"}, a),
    "unknown class": _set(["model", "class"], "EvilHMM"),
    "class a list": _set(["model", "class"], ["GaussianHMM"]),
    "params a list": _set(["model", "params"], [1]),
    "n_components a string": _set(["model", "params", "n_components"], "two"),
    "n_components a list": _set(["model", "params", "n_components"], [2]),
    "n_components 5": _set(["model", "params", "n_components"], 5),
    "var_floor a string": _set(["model", "params", "var_floor"], "x"),
    "unknown parameter": _set(["model", "params", "bogus"], 1),
    "learnt overrides a method": _set(["model", "learnt", "fit"], 1),
    "learnt dunder": _set(["model", "learnt", "__class__"], 1),
    "array reference missing": _set(["model", "learnt", "means_"], {"__array__": "nope"}),
    "array reference a number": _set(["model", "learnt", "means_"], {"__array__": 3}),
    "list marker not a list": _set(["model", "learnt", "history_"], {"__list__": 3}),
    "means_ missing": _without("model/means_"),
    "means_ NaN": _array("model/means_", _nan_at),
    "means_ inf": _array("model/means_", lambda a: a * np.inf),
    "means_ strings": _array("model/means_", lambda a: a.astype(str)),
    "means_ wrong shape": _array("model/means_", lambda a: a[:, :2]),
    "transmat_ rows": _array("model/transmat_", lambda a: a * 1.5),
    "startprob_ negative": _array("model/startprob_", lambda a: a - 1),
    "covars_ not positive": _array("model/covars_", lambda a: -a),
    "covars_ one state short": _array("model/covars_", lambda a: a[:1]),
}


def _write(tmp_path, header, arrays):
    path = tmp_path / "tampered.npz"
    if isinstance(header, dict | list | str | type(None)):
        write_npz(path, header, arrays)
    return path


def _assert_one_line_refusal(path):
    COUNTS["tried"] += 1
    try:
        with pytest.raises(ModelFormatError) as exc:
            load_npz(path)
        message = str(exc.value)
        assert "\n" not in message and message.startswith(f"{path}: "), message
    except BaseException:
        COUNTS["failed"] += 1
        raise
    COUNTS["clean"] += 1
    return message


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(names=st.lists(st.sampled_from(sorted(MUTATIONS)), min_size=1, max_size=3, unique=True))
def test_tampered_model_file_is_one_line(valid, tmp_path_factory, names):
    header, arrays = copy.deepcopy(valid[0]), dict(valid[1])
    for name in names:
        if isinstance(header, dict) and isinstance(header.get("model"), dict):
            try:
                header, arrays = MUTATIONS[name](header, arrays)
            except (KeyError, TypeError):  # an earlier mutation removed what this one changes
                continue
    if isinstance(header, dict) and header == valid[0] and arrays.keys() == valid[1].keys():
        return
    _assert_one_line_refusal(_write(tmp_path_factory.mktemp("m"), header, arrays))


@pytest.mark.parametrize(
    "name,field",
    [
        ("format_version a string", "format_version must be an integer"),
        ("kind missing", "header field 'kind' is missing"),
        ("header a list", "not an object"),
        ("unknown class", "model.class"),
        ("n_components a string", "model.params.n_components"),
        ("array reference missing", "model.learnt.means_"),
        ("means_ NaN", "model.learnt.means_: NaN"),
        ("means_ strings", "numbers or booleans"),
        ("transmat_ rows", "transmat_"),
        ("covars_ not positive", "positive definite"),
    ],
)
def test_the_line_names_the_field(valid, tmp_path, name, field):
    header, arrays = MUTATIONS[name](copy.deepcopy(valid[0]), dict(valid[1]))
    assert field in _assert_one_line_refusal(_write(tmp_path, header, arrays))


@settings(max_examples=15, deadline=None, suppress_health_check=list(HealthCheck))
@given(blob=st.binary(max_size=300))
def test_random_header_bytes_are_one_line(valid, tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("m") / "raw.npz"
    write_npz(path, None, valid[1], raw_header=blob)
    _assert_one_line_refusal(path)


def test_pickled_and_foreign_members_are_refused(valid, tmp_path):
    header, arrays = valid
    path = write_npz(tmp_path / "p.npz", header, arrays)
    with zipfile.ZipFile(path, "a") as zf:
        zf.writestr("evil.txt", "hello")
    assert "unexpected member" in _assert_one_line_refusal(path)
    obj = np.array([{"a": 1}], dtype=object)
    path = tmp_path / "o.npz"
    np.savez(path, __header__=np.frombuffer(json.dumps(header).encode(), np.uint8), x=obj)
    assert "numbers or booleans" in _assert_one_line_refusal(path)


def test_member_sizes_are_checked_before_decompressing(tmp_path, monkeypatch):
    path = zip_bomb_model(tmp_path / "bomb.npz", 24)
    monkeypatch.setenv("MARKOVMOTION_MAX_BYTES", "8000000")
    assert "decompresses to more than 8 MB" in _assert_one_line_refusal(path)


@pytest.mark.parametrize("case", ["format_version a string", "zip bomb"])
def test_real_process_on_a_tampered_model(valid, tmp_path, case):
    if case == "zip bomb":
        path, env = zip_bomb_model(tmp_path / "bomb.npz", 24), {"MARKOVMOTION_MAX_BYTES": "8000000"}
    else:
        header, arrays = MUTATIONS[case](copy.deepcopy(valid[0]), dict(valid[1]))
        path, env = _write(tmp_path, header, arrays), {}
    run = run_cli(
        ["gait", "synthesize", "--model", str(path), "--out", str(tmp_path / "o.bvh")], env
    )
    check_clean(run, path.name)
    assert not (tmp_path / "o.bvh").exists()


# ------------------------------------------------------------- numerics


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("frames", [np.ones((50, 3)), np.full((1, 4), 7.0)])
def test_gaussian_hmm_fits_constant_input_and_one_frame(frames):
    n = 2 if len(frames) > 1 else 1
    hmm = GaussianHMM(n_components=n, n_iter=5).fit(frames)
    assert np.isfinite(hmm.covars_).all() and np.all(np.linalg.eigvalsh(hmm.covars_) > 0)
    hmm.check_state()
    assert np.isfinite(hmm.score(frames))

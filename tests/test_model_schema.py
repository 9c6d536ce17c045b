"""The model-file schema (issue 14): every kind checks, on load, that its learnt arrays fit
each other -- shapes, index ranges, probability rows, positive variances, the learnt
attributes it needs -- and a file that does not is one line naming the file and the field."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from hostile_corpus import check_clean, run_cli, write_npz
from test_conformance import FAMILIES

from markovmotion.data.splits import held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.errors import ModelFormatError
from markovmotion.models import Model


@pytest.fixture(scope="module")
def saved(mocap, tmp_path_factory) -> dict[str, tuple[dict, dict[str, np.ndarray]]]:
    """(header, arrays) of each family's tiny fitted model, as its file holds them."""
    a, b = mocap.pairs(label="salsa")[0]
    pair = tuple(m.trim(0, 240) for m in mocap.load_pair(a, b))
    walks, _ = held_out_every(gait_entries(mocap, "normal"))
    data = {
        "pairs": [pair],
        "single": [mocap.load_motion(e).trim(0, 600) for e in mocap.query(category="exercise")[:2]],
        "walks": [mocap.load_motion(e) for e in walks[:2]],
    }
    folder = tmp_path_factory.mktemp("schema")
    out = {}
    for fam in FAMILIES:
        path = folder / f"{fam.name}.npz"
        fam.make().fit(data[fam.data]).save(path)
        with np.load(path) as npz:
            arrays = {k: npz[k] for k in npz.files}
        header = json.loads(arrays.pop("__header__").tobytes().decode())
        out[fam.name] = (header, arrays)
    return out


def _array(suffix: str, change):
    """Change the one array whose key ends with ``suffix``."""

    def mutate(header, arrays):
        (key,) = [k for k in arrays if k.endswith(suffix)]
        arrays[key] = change(arrays[key].copy())

    return mutate


def _learnt(path: list[str], value=None):
    """Drop (``value`` None) or set the learnt attribute at ``path`` below the model."""

    def mutate(header, arrays):
        node = header["model"]
        for name in path[:-1]:
            node = node["learnt"][name]["__estimator__"]
        if value is None:
            node["learnt"].pop(path[-1])
        else:
            node["learnt"][path[-1]] = value

    return mutate


def _both(*mutations):
    def mutate(header, arrays):
        for m in mutations:
            m(header, arrays)

    return mutate


def _at(i, v):
    def change(a):
        a.flat[i] = v
        return a

    return change


# family -> case -> (mutation, what the one line must name)
CASES = {
    "hmm": {
        "index": (_array("model/train_states_", _at(0, 4)), "train_states_: index 4"),
        "shape": (_array("model/train_a_", lambda a: a[:, :-1]), "train_a_: shape"),
        "probability": (_array("lambda_a_/transmat_", lambda a: a * 0.5), "transmat_"),
        "variance": (_array("lambda_b_/covars_", lambda a: -a), "lambda_b_"),
        "missing": (_learnt(["train_states_"]), "missing learnt attribute train_states_"),
        "width": (_array("pipeline_b_/param/steps/1/components_", lambda a: a[:-1]), "pipeline_b_"),
    },
    "vlmm": {
        "index": (_array("model/train_tokens_", _at(0, 12)), "train_tokens_: index 12"),
        "shape": (_array("model/prototypes_", lambda a: a[:, :-1]), "prototypes_: shape"),
        "probability": (_array("vlmm_/out_probs_", lambda a: a * 0.5), "out_probs_"),
        "variance": (_array("steps/3/scale_", lambda a: -a), "scale_: values must be positive"),
        "missing": (_learnt(["vlmm_"]), "missing learnt attribute vlmm_"),
        "automaton": (_array("vlmm_/next_state_", _at(0, 10**6)), "next_state_: index"),
        "pipeline": (
            _both(*(_array(f"steps/3/{k}", lambda a: a[:-1]) for k in ("min_", "scale_"))),
            "steps[3]: takes 65 features, steps[2] gives 66",
        ),
    },
    "structured_vlmm": {
        "index": (_array("model/keys_", _at(0, 12)), "keys_: index 12"),
        "shape": (_array("model/template_pairs_", lambda a: a[:, :1]), "template_pairs_: shape"),
        "probability": (_array("model/template_probs_", lambda a: a * 0.5), "template_probs_"),
        "variance": (_array("steps/3/scale_", lambda a: -a), "scale_: values must be positive"),
        "missing": (_learnt(["template_probs_"]), "missing learnt attribute template_probs_"),
        "nested": (_learnt(["prototype_model_", "prototypes_"]), "prototypes_"),
    },
    "gait": {
        "index": (_array("hsmm_/out_map_", _at(0, 999)), "out_map_: index 999"),
        "shape": (_array("model/gv_var_", lambda a: a[:-1]), "gv_var_: shape"),
        "probability": (_array("steps/0/reference_", lambda a: a * 2), "reference_"),
        "variance": (_array("hsmm_/variances_", _at(3, -1.0)), "variances_: values must be"),
        "missing": (_learnt(["hsmm_"]), "missing learnt attribute hsmm_"),
        "duration": (_array("hsmm_/dur_means_", _at(0, 0.0)), "dur_means_"),
    },
    "chain": {
        "index": (_array("chain_/chain_prototype_", _at(0, 99)), "chain_prototype_: index 99"),
        "shape": (_array("model/mean_shape_", lambda a: a[:-1]), "mean_shape_: shape"),
        "probability": (
            _array("chain_/transmat_", lambda a: a * 0.5),
            "transmat_: a probability row",
        ),
        "variance": (_learnt(["chain_", "interval_scale_"], -1.0), "interval_scale_"),
        "missing": (_learnt(["chain_"]), "missing learnt attribute chain_"),
        "top": (_learnt(["train_files_"]), "missing learnt attribute train_files_"),
    },
}


def _tampered(saved, family, case, path):
    header, arrays = copy.deepcopy(saved[family][0]), dict(saved[family][1])
    mutate, _ = CASES[family][case]
    mutate(header, arrays)
    return write_npz(path, header, arrays)


@pytest.mark.parametrize("family", sorted(CASES))
def test_untampered_models_load(saved, family, tmp_path):
    header, arrays = saved[family]
    model = Model.load(write_npz(tmp_path / "ok.npz", header, arrays))
    assert type(model).KIND == header["kind"]


@pytest.mark.parametrize(
    "family,case", [(f, c) for f in sorted(CASES) for c in CASES[f]], ids=lambda x: x
)
def test_tampered_model_is_one_line_naming_file_and_field(saved, family, case, tmp_path):
    path = _tampered(saved, family, case, tmp_path / "tampered.npz")
    with pytest.raises(ModelFormatError) as err:
        Model.load(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: damaged model: model"), message
    assert CASES[family][case][1] in message, message


@pytest.mark.parametrize(
    "family,case,args",
    [
        ("vlmm", "index", ["vlmm", "generate", "--seconds", "1"]),
        ("gait", "variance", ["gait", "synthesize"]),
    ],
)
def test_cli_refuses_a_tampered_model_in_one_line(saved, family, case, args, tmp_path):
    path = _tampered(saved, family, case, tmp_path / "tampered.npz")
    out = tmp_path / "o.bvh"
    run = run_cli([*args, "--model", str(path), "--out", str(out)])
    check_clean(run, "tampered.npz", CASES[family][case][1])
    assert not out.exists()

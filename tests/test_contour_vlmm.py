"""The VLMM on silhouette contours (VLMM paper §2.1.1, data set 1): a few seconds of one
exercise take rendered, tracked and learnt."""

from __future__ import annotations

import json

import numpy as np
import pytest

from markovmotion.data.index import MocapIndex
from markovmotion.errors import MotionFormatError
from markovmotion.evaluate.vlmm import ConfigurationSpace, ZeroVelocity, evaluate_horizon
from markovmotion.models.base import Model
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.video.contours import (
    HEAD_AT,
    configuration_control,
    contour_configurations,
    contour_scale,
    contour_strip,
    contour_track,
)

SECONDS = 4.0


@pytest.fixture(scope="module")
def contour_source(mocap: MocapIndex, tmp_path_factory):
    """The first exercise take the renderer draws, and the track of its first few seconds."""
    cache = tmp_path_factory.mktemp("contours")
    for entry in mocap.query(category="exercise"):
        try:
            return entry, contour_track(mocap, entry, cache, SECONDS)
        except MotionFormatError:
            continue
    pytest.skip("no exercise take with the renderer's joints")


@pytest.fixture(scope="module")
def contour_take(contour_source):
    return contour_source[1]


@pytest.fixture(scope="module")
def contour_model(contour_take):
    c = contour_configurations(contour_take, contour_scale([contour_take]))
    model = BehaviourModel(
        n_prototypes=8, max_memory=3, configuration="contour", fps=contour_take.fps
    )
    return model.fit([c]), c


def test_configurations_in_unit_box_and_follow_control_points(contour_take):
    scale = contour_scale([contour_take])
    c = contour_configurations(contour_take, scale)
    assert c.shape == (contour_take.n_frames, 64)
    assert c.min() >= 0.0 and c.max() <= 1.0
    # the body inside the box (hardly anything clipped), and the scaling undone exactly
    inside = (c > 0.0) & (c < 1.0)
    assert inside.mean() > 0.99
    rel = (contour_take.control[:, 0] - contour_take.reference[:, 0, None]).reshape(len(c), -1)
    back = configuration_control(c, scale).reshape(len(c), -1)
    np.testing.assert_allclose(back[inside], rel[inside], atol=1e-9)
    # the spline starts at the head reference point (the tracker resamples from it)
    off = np.abs(c[:, :2] - HEAD_AT)
    assert np.median(off) < 0.02 and off.max() < 0.1


def test_contour_vlmm_generates_and_predicts(contour_model):
    model, c = contour_model
    g = model.generate(2.0)
    assert g.shape == (int(round(2.0 * model.fps)) + 1, 64)
    assert np.isfinite(g).all()
    assert g.min() >= c.min() - 1e-9 and g.max() <= c.max() + 1e-9  # eq. 4 undone
    p = model.predict(c[:40], 1.0)
    assert p.shape == (40 + 25, 64)
    np.testing.assert_allclose(p[:40], c[:40], atol=1e-9)
    feats = model.observe([c])
    curve = evaluate_horizon(ConfigurationSpace(model), feats, 10, model.fps, 5, stride=5)
    still = evaluate_horizon(ConfigurationSpace(ZeroVelocity(model)), feats, 10, model.fps, 1, 5)
    assert np.isfinite(curve.mean).all()
    # eq. 9 in [0, 1]^64 (at most 8): the tracked contours jitter from frame to frame, so
    # holding the last one is already 1.5-2 away; the VLMM does no worse
    assert curve.at(0.2) < 3.0
    assert curve.at(0.2) < 1.25 * still.at(0.2)
    assert np.isfinite(model.score([c]))


def test_contour_model_round_trip(contour_model, tmp_path):
    model, c = contour_model
    path = tmp_path / "contour.npz"
    model.save(path)
    back = Model.load(path)
    assert isinstance(back, BehaviourModel) and back.configuration == "contour"
    np.testing.assert_array_equal(back.generate(2.0), model.generate(2.0))
    np.testing.assert_array_equal(back.predict(c[:30], 0.5), model.predict(c[:30], 0.5))


def test_contour_model_bad_input_one_line(contour_model):
    model, c = contour_model
    for bad in ([c[:, :63]], [c[:1]], c):
        with pytest.raises(ValueError) as err:
            model.observe(bad)
        assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="contour"):
        BehaviourModel(configuration="contour").fit([object()])


def test_contour_strip_png(contour_model, tmp_path):
    model, c = contour_model
    out = contour_strip(
        [c, model.generate(2.0)], tmp_path / "strip.png", 5, 5, titles=["tracked", "N = 3"]
    )
    import cv2

    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    assert img is not None and (img == 0).any() and (img == 255).any()


def test_cli_contour_train_generate_evaluate(contour_source, mocap, tmp_path, capsys):
    """vlmm train --source contour / generate (PNG) / evaluate (configuration, pixels), on a
    cache holding a short track for every take of one label (so nothing is rendered);
    bad combinations are one line, exit 2."""
    from markovmotion.cli import main
    from markovmotion.video.contours import take_name

    entry, track = contour_source
    cache = tmp_path / "cache"
    cache.mkdir()
    for e in mocap.query(category="exercise", label=entry.label):
        track.save(cache / f"{take_name(e)}.mp4.track.npz")
    model = tmp_path / "c.npz"
    main(["vlmm", "train", "--source", "contour", "--label", entry.label, "--cache", str(cache),
          "--prototypes", "8", "--max-memory", "3", "--lam", "10", "--out", str(model)])  # fmt: skip
    loaded = Model.load(model)
    assert loaded.configuration == "contour" and loaded.contour_scale_ > 0
    assert loaded.held_out_files_ and entry.file in {r["file"] for r in loaded.train_files_}
    assert loaded.data_index_["root"] == str(mocap.root.resolve())  # evaluate looks there
    main(["vlmm", "generate", "--model", str(model), "--seconds", "2", "--stochastic",
          "--out", str(tmp_path / "g.png")])  # fmt: skip
    assert (tmp_path / "g.png").stat().st_size > 500
    capsys.readouterr()
    for space in ("configuration", "pixels"):
        main(["vlmm", "evaluate", "--model", str(model), "--cache", str(cache), "--samples",
              "2", "--stride", "10", "--horizon", "1", "--space", space, "--json"])  # fmt: skip
        result = json.loads(capsys.readouterr().out)
        assert set(result["E_T"]) == {"vlmm", "first_order", "zero_velocity"}
        assert all(v["1"] > 0 for v in result["E_T"].values())
    structured = tmp_path / "s.npz"
    main(["vlmm", "train", "--source", "contour", "--label", entry.label, "--cache", str(cache),
          "--prototypes", "10", "--max-memory", "3", "--structured", "--out",
          str(structured)])  # fmt: skip
    main(["vlmm", "generate", "--model", str(structured), "--seconds", "2", "--stochastic",
          "--out", str(tmp_path / "s.png")])  # fmt: skip
    assert (tmp_path / "s.png").stat().st_size > 500
    capsys.readouterr()
    main(["vlmm", "evaluate", "--model", str(structured), "--cache", str(cache), "--samples",
          "2", "--stride", "10", "--horizon", "1", "--json"])  # fmt: skip
    assert "structured" in json.loads(capsys.readouterr().out)["E_T"]
    bad = [
        ["vlmm", "train", "--source", "contour", "--out", str(tmp_path / "x.npz")],
        ["vlmm", "evaluate", "--model", str(model)],
        ["vlmm", "evaluate", "--model", str(model), "--cache", str(cache), "--space", "mm"],
        ["vlmm", "generate", "--model", str(model), "--out", str(tmp_path / "g.bvh")],
        [
            "vlmm",
            "predict",
            "--model",
            str(model),
            "--input",
            str(tmp_path / "g.png"),
            "--out",
            str(tmp_path / "p.bvh"),
        ],  # fmt: skip
    ]
    for args in bad:
        with pytest.raises(SystemExit) as info:
            main(args)
        assert info.value.code == 2, args
        assert len(capsys.readouterr().err.strip().splitlines()) == 1, args


def test_structured_model_on_contours(contour_take, tmp_path):
    """The structured two-level model (§4) over a contour prototype model: generation and
    prediction give contour arrays, and it survives save/load."""
    from markovmotion.models.vlmm.structured import StructuredBehaviourModel

    c = contour_configurations(contour_take, contour_scale([contour_take]))
    base = BehaviourModel(n_prototypes=10, max_memory=3, configuration="contour", fps=25.0)
    model = StructuredBehaviourModel(base, max_memory=3, key_speed_quantile=0.5).fit([c])
    g = model.generate(2.0, np.random.default_rng(0))
    assert g.shape == (51, 64) and np.isfinite(g).all()
    assert model.predict(c[:30], 0.4).shape == (40, 64)
    model.save(tmp_path / "s.npz")
    back = Model.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(back.generate(2.0, np.random.default_rng(0)), g)


def test_contour_extrapolation_png(contour_model, tmp_path):
    """Fig. 7: recent contours and the first predicted frames at selected instants."""
    import cv2

    from markovmotion.video.contours import contour_extrapolation

    model, c = contour_model
    out = contour_extrapolation(model, c, [20, 50, 80], tmp_path / "fig7.png")
    img = cv2.imread(str(out))
    assert img.shape == (160, 480, 3)
    assert ((img[..., 2] > 150) & (img[..., 0] < 80)).any()  # red prediction outlines
    with pytest.raises(ValueError, match="outside"):
        contour_extrapolation(model, c, [len(c)], tmp_path / "x.png")

"""One contract for every family (models/base.py), checked over the list of top-level models.

As dynamax's ``models/test_models.py`` does over its model list: each model is
fitted on a few seconds of real motion, saved, loaded back (by its own class
and by ``Model.load``), and every verb it declares gives identical outputs
before and after; the verbs return Motions (``score`` a finite float);
``load`` of a file of another kind is a one-line error; the constructor
stores hyper-parameters only. A fifth family adds one entry to ``FAMILIES``.
"""

from __future__ import annotations

import functools
import itertools
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from sklearn.base import clone

from markovmotion.core.motion import Motion
from markovmotion.data.splits import held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.errors import ModelFormatError, TooLittleDataError
from markovmotion.models import KINDS, Model
from markovmotion.models.base import ALL_VERBS
from markovmotion.models.chain.behaviour_chain import BehaviourChain
from markovmotion.models.chain.partner import VirtualPartner
from markovmotion.models.gait.hsmm import HSMM
from markovmotion.models.gait.synthesizer import GaitSynthesizer
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.models.hmm.gaussian import GaussianHMM
from markovmotion.models.online import OnlinePartner, run
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.models.vlmm.prediction_suffix_tree import VLMM
from markovmotion.models.vlmm.structured import StructuredBehaviourModel


@dataclass
class Family:
    """A top-level model, how to make its training data, and how to call each of its verbs."""

    name: str
    make: Callable[[], Model]
    data: str  # key into the ``data`` fixture
    verbs: dict[str, Callable[[Any, Any], Any]]


def _pairs_input(data):
    return data[0][0]


FAMILIES = [
    Family(
        "hmm",
        lambda: DualHMM(n_states=4, n_iter=3, window=4, placement_window=3),
        "pairs",
        {
            "respond": lambda m, d: m.respond(_pairs_input(d), method="windowed"),
            "score": lambda m, d: m.score(_pairs_input(d)),
            "partner": lambda m, d: run(m.partner(), _pairs_input(d)),
        },
    ),
    Family(
        "vlmm",
        lambda: BehaviourModel(n_prototypes=12, max_memory=3, fps=15.0, random_state=0),
        "single",
        {
            "generate": lambda m, d: m.generate(2.0, rng=np.random.default_rng(0)),
            "predict": lambda m, d: m.predict(d[0], 0.5, rng=np.random.default_rng(0)),
            "score": lambda m, d: m.score(d),
        },
    ),
    Family(
        "structured_vlmm",
        lambda: StructuredBehaviourModel(
            prototype_model=BehaviourModel(n_prototypes=12, max_memory=3, fps=15.0, random_state=0)
        ),
        "single",
        {
            "generate": lambda m, d: m.generate(2.0, rng=np.random.default_rng(0)),
            "predict": lambda m, d: m.predict(d[0], 0.5, rng=np.random.default_rng(0)),
            "score": lambda m, d: m.score(d),
        },
    ),
    Family(
        "gait",
        lambda: GaitSynthesizer(n_iter=1),
        "walks",
        {
            "generate": lambda m, d: m.generate(n_steps=3, rng=np.random.default_rng(0)),
            "score": lambda m, d: m.score(d[:1]),
        },
    ),
    Family(
        "chain",
        lambda: VirtualPartner(n_state_prototypes=12, n_behaviour_prototypes=8, n_epochs=2),
        "pairs",
        {
            "respond": lambda m, d: m.respond(_pairs_input(d)),
            "partner": lambda m, d: run(m.partner(), _pairs_input(d)),
        },
    ),
]


@pytest.fixture(scope="module")
def data(mocap) -> dict[str, list]:
    """A few seconds of real motion of each kind the families learn from."""
    a, b = mocap.pairs(label="salsa")[0]
    pair = tuple(m.trim(0, 240) for m in mocap.load_pair(a, b))  # 4 s at 60 fps
    single = [mocap.load_motion(e).trim(0, 600) for e in mocap.query(category="exercise")[:2]]
    walks, _ = held_out_every(gait_entries(mocap, "normal"))
    return {
        "pairs": [pair],
        "single": single,
        "walks": [mocap.load_motion(e) for e in walks[:2]],
    }


@pytest.fixture(scope="module")
def fitted(data) -> dict[str, Model]:
    out = {}
    for fam in FAMILIES:
        model = fam.make()
        assert model.fit(data[fam.data]) is model, f"{fam.name}: fit must return self"
        out[fam.name] = model
    return out


def _same(a: Any, b: Any) -> None:
    if isinstance(a, Motion):
        assert isinstance(b, Motion)
        np.testing.assert_array_equal(a.rotations, b.rotations)
        np.testing.assert_array_equal(a.translations, b.translations)
        assert a.fps == b.fps
    else:
        assert a == b


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_verbs_are_declared_and_give_motions(fam, fitted, data):
    model = fitted[fam.name]
    assert set(model.VERBS) == set(fam.verbs), (
        "every declared verb is exercised here, and only those"
    )
    assert set(model.VERBS) <= set(ALL_VERBS)
    for verb, call in fam.verbs.items():
        out = call(model, data[fam.data])
        if verb == "score":
            assert isinstance(out, float) and np.isfinite(out)
        else:
            assert isinstance(out, Motion) and out.n_frames > 0, verb
            assert np.isfinite(out.positions()).all(), verb


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_save_load_gives_identical_outputs(fam, fitted, data, tmp_path):
    model = fitted[fam.name]
    path = tmp_path / f"{fam.name}.npz"
    model.save(path, note="kept")
    for loaded in (type(model).load(path), Model.load(path)):
        assert type(loaded) is type(model)
        assert loaded.note_ == "kept"
        assert loaded.train_files_ == model.train_files_
        assert loaded.get_params(deep=False).keys() == model.get_params(deep=False).keys()
        for call in fam.verbs.values():
            _same(call(model, data[fam.data]), call(loaded, data[fam.data]))


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_training_files_are_recorded_by_content(fam, fitted, data):
    model = fitted[fam.name]
    sources = {
        m.source for take in data[fam.data] for m in (take if isinstance(take, tuple) else (take,))
    }
    assert model.train_files_ and len(model.train_files_) == len(sources)
    for rec in model.train_files_:
        assert len(rec["sha256"]) == 64 and rec["file"].endswith(
            (".bvh.gz", ".bvh", ".amc", ".amc.gz")
        )


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_constructor_stores_hyperparameters_only(fam):
    model = fam.make()
    learnt = [k for k in vars(model) if k.endswith("_") and not k.startswith("_")]
    assert not learnt, f"learnt attributes before fit: {learnt}"
    assert type(model).KIND in KINDS and KINDS[type(model).KIND] is type(model)
    twin = clone(model)
    assert twin.get_params(deep=False).keys() == model.get_params(deep=False).keys()
    # one default seed in every family: the same call gives the same answer (gait's was None)
    model = type(model)()
    seeds = {k: v for k, v in model.get_params(deep=True).items() if k.endswith("random_state")}
    assert set(seeds.values()) <= {0}, seeds
    assert seeds or fam.name == "structured_vlmm"  # its default prototype model's seed is 0


@pytest.mark.parametrize(
    "saved, loader",
    [(a, b) for a, b in itertools.permutations(FAMILIES, 2)],
    ids=lambda f: f.name,
)
def test_loading_a_file_of_another_kind_is_one_line(saved, loader, fitted, tmp_path):
    model = fitted[saved.name]
    cls = type(fitted[loader.name])
    if issubclass(type(model), cls):
        pytest.skip("a file of a subclass loads")
    path = tmp_path / "other.npz"
    model.save(path)
    with pytest.raises(ModelFormatError) as err:
        cls.load(path)
    message = str(err.value)
    assert "\n" not in message and "other.npz" in message and type(model).KIND in message


@pytest.mark.parametrize("fam", [f for f in FAMILIES if "partner" in f.verbs], ids=lambda f: f.name)
def test_online_partners_follow_the_protocol(fam, fitted, data):
    model = fitted[fam.name]
    partner = model.partner()
    assert isinstance(partner, OnlinePartner)
    a = _pairs_input(data[fam.data])
    a = a.resample(partner.fps)
    out = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    shown = [f for f in out if f is not None] + partner.finish()
    assert all(f is None for f in out[: partner.lag])
    assert len(shown) == a.n_frames
    assert all(f.n_frames == 1 and f.skeleton.names == partner.skeleton.names for f in shown)


@pytest.mark.parametrize("fam", [f for f in FAMILIES if "partner" in f.verbs], ids=lambda f: f.name)
def test_online_partners_answer_every_step_even_before_a_is_seen(fam, fitted, data):
    """N calls of ``step`` give N frames of B (those ``step`` returns and ``finish``'s), the
    stream starting with frames missing (``step(None)``: a camera that sees no one yet) or
    not: the chain did not count the missing frames before the first person (2 missing + 18
    real frames gave 18, the dual HMM's 20). Before A is seen both answer a finite B frame
    (the dual HMM from its dynamics, at the origin; the chain its training people's mean
    shape, for an A at the origin)."""
    model = fitted[fam.name]
    a = _pairs_input(data[fam.data])
    for missing in (0, 2, 7):
        partner = model.partner()
        frames = a.resample(partner.fps)
        out = [partner.step(None) for _ in range(missing)]
        out += [partner.step(frames.trim(t, t + 1)) for t in range(18)]
        assert all(f is None for f in out[: partner.lag])
        assert all(f is not None for f in out[partner.lag :]), "one answer per step"
        shown = [f for f in out if f is not None] + partner.finish()
        assert len(shown) == missing + 18
        assert all(f.n_frames == 1 and np.isfinite(f.positions()).all() for f in shown)
    partner = model.partner()
    nobody = [partner.step(None) for _ in range(5)] + partner.finish()
    assert len([f for f in nobody if f is not None]) == 5


@pytest.mark.parametrize("fam", [f for f in FAMILIES if "partner" in f.verbs], ids=lambda f: f.name)
def test_online_partners_log_a_missing_frame_once_per_stream(fam, fitted, data, caplog):
    """A frame of A missing (None, or NaN) is one logged warning per stream, on the logger
    ``markovmotion``, in the same words from either partner (the chain's said nothing); a
    frame the caller dropped (``skip``, ``drop``) is not one."""
    model = fitted[fam.name]
    for missing in (0, 3):  # A unseen at first, or lost at frame 3; then a frame of NaN
        partner = model.partner()
        a = _pairs_input(data[fam.data]).resample(partner.fps).trim(0, 12).copy()
        a.rotations[7] = np.nan
        caplog.clear()
        with caplog.at_level("WARNING", logger="markovmotion"):
            for t in range(a.n_frames):
                partner.step(None if t == missing else a.trim(t, t + 1))
            partner.skip()
            partner.drop()
            partner.finish()
        said = [r.getMessage() for r in caplog.records]
        assert said == [f"frame {missing} of A is missing or holds NaN: skipped"]
        assert all(r.name.startswith("markovmotion.") for r in caplog.records)


@pytest.mark.parametrize("fam", [f for f in FAMILIES if "partner" in f.verbs], ids=lambda f: f.name)
def test_online_partners_go_on_after_dropped_frames(fam, fitted, data):
    """``drop()`` (a live session behind its clock) answers nothing, and the partner goes on
    in step with the stream: every frame not dropped gets its B frame, the first frame after
    the drops at once (no new look-ahead), each finite."""
    model = fitted[fam.name]
    partner = model.partner()
    a = _pairs_input(data[fam.data]).resample(partner.fps)
    dropped = range(partner.lag + 2, partner.lag + 7)
    out = []
    for t in range(a.n_frames):
        if t in dropped:
            assert partner.drop() is None
        else:
            out.append(partner.step(a.trim(t, t + 1)))
    assert out[partner.lag + 2] is not None  # the frame after the drops
    shown = [f for f in out if f is not None] + partner.finish()
    assert len(shown) == a.n_frames - len(dropped)
    assert all(f.n_frames == 1 and np.isfinite(f.positions()).all() for f in shown)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_verb_before_fit_raises_not_fitted(kind):
    """scikit-learn's convention (issue 26): NotFittedError, not an AttributeError from inside."""
    from sklearn.exceptions import NotFittedError

    cls = KINDS[kind]
    for verb in cls.VERBS:
        with pytest.raises(NotFittedError, match=f"{cls.__name__} is not fitted"):
            getattr(cls(), verb)(*([] if verb in ("partner", "generate") else [np.zeros((3, 2))]))


def _contours(n: int = 3, width: int = 8) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [np.cumsum(rng.normal(size=(60, width)), axis=0) for _ in range(n)]


# Every estimator that learns from arrays of frames, and how to fit it on a list of them.
ARRAY_ESTIMATORS = {
    "GaussianHMM": lambda xs: GaussianHMM(2, n_iter=2).fit(xs[0]),
    "HSMM": lambda xs: HSMM(n_states=2, n_iter=1, n_iter_untied=1).fit(
        xs, [np.zeros(2, int)] * len(xs), [np.array([0, 30, 60])] * len(xs), 1
    ),
    "BehaviourChain": lambda xs: BehaviourChain(n_state_prototypes=5, n_behaviour_prototypes=4).fit(
        xs
    ),
    "BehaviourModel (contour)": lambda xs: BehaviourModel(
        configuration="contour", n_prototypes=6, max_memory=2, fps=15.0
    ).fit(xs),
}


@pytest.mark.parametrize("name", ARRAY_ESTIMATORS)
def test_array_input_follows_scikit_learn(name):
    """scikit-learn's conventions where a model takes arrays (issue 26): ``n_features_in_``
    after fit; complex or sparse frames refused in one line (not cast with a warning, not an
    unrelated error)."""
    import scipy.sparse

    fit = ARRAY_ESTIMATORS[name]
    assert fit(_contours()).n_features_in_ == 8
    for bad, message in (
        ([x * (1 + 1j) for x in _contours()], "Complex data not supported"),
        ([scipy.sparse.csr_matrix(x) for x in _contours()], "sparse matrix"),
    ):
        with pytest.raises(ValueError, match=message) as err:
            fit(bad)
        assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    "call",
    [
        lambda: HSMM().score([np.zeros((4, 2))], [np.zeros(1, int)]),
        lambda: HSMM().sample(np.zeros(2, int), np.random.default_rng(0)),
        lambda: VLMM().log_likelihood(np.zeros(3, int)),
        lambda: VLMM().generate(5),
        lambda: BehaviourChain().recognise(np.zeros((3, 4))),
        lambda: GaussianHMM(2).score(np.zeros((3, 2))),
    ],
    ids=["HSMM.score", "HSMM.sample", "VLMM.log_likelihood", "VLMM.generate", "chain", "hmm"],
)
def test_the_models_components_before_fit_raise_not_fitted(call):
    """The estimators the models are built of follow the same convention (issue 26)."""
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError, match="is not fitted"):
        call()


def _broken(motion: Motion, value: float, frames: slice) -> Motion:
    out = motion.copy()
    out.rotations[frames, 1] = value
    return out


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_wrong_takes_to_fit_and_score_are_one_line_alike_in_every_family(fam, fitted, data):
    """``fit([])`` was an IndexError (VLMM), NumPy's "need at least one array" (gait);
    ``fit("x")`` and ``fit([None])`` AttributeErrors from inside; ``gait.score([])`` a
    ZeroDivisionError; NaN or infinite frames were learnt and scored without a word (VLMM),
    SVD errors (gait), PCA's "Input X contains NaN" (dual HMM) or "sequence 0 holds NaN"
    (chain). Every family's takes are now checked alike (``models.base.check_takes``): one
    line naming the model, the verb, the take and what is wrong with it."""
    model = fitted[fam.name]
    name = type(model).__name__
    takes = data[fam.data]
    pairs = fam.data == "pairs"
    verbs = {"fit": lambda t: fam.make().fit(t)}
    if "score" in model.VERBS and not type(model).SCORES_ONE:
        verbs["score"] = model.score
    for verb, call in verbs.items():
        what = "take" if verb == "fit" else "motion"
        error = TooLittleDataError if verb == "fit" else ValueError
        with pytest.raises(error, match=rf"^{name}\.{verb}: no .* \(the list is empty\)$"):
            call([])
        for bad in ("x", None, 3):
            with pytest.raises(TypeError, match=rf"^{name}\.{verb} takes a list of .*, not "):
                call(bad)
        with pytest.raises(TypeError, match=rf"^{name}\.{verb}: {what} 0 is None, not a"):
            call([None])
        nan, inf = r"3 frames \(first 5, last 7\)", r"1 frame \(first 5, last 5\)"
        if pairs:
            a, b = takes[0]
            cases = [
                ([(a, b), (_broken(a, np.nan, slice(5, 8)), b)], r"take 1 \(A\)", nan),
                ([(a, _broken(b, np.inf, slice(5, 6)))], r"take 0 \(B\)", inf),
            ]
        else:
            cases = [
                ([takes[0], _broken(takes[1], np.nan, slice(5, 8))], f"{what} 1", nan),
                ([_broken(takes[0], np.inf, slice(5, 6)), takes[1]], f"{what} 0", inf),
            ]
        for bad, at, frames in cases:
            with pytest.raises(ValueError, match=rf"^{name}\.{verb}: {at}: .* holds NaN or") as err:
                call(bad)
            assert re.search(frames, str(err.value)) and "\n" not in str(err.value)
    if fam.name == "hmm":  # on markers a gap is filled (virtual markers too): still learnt
        a, b = takes[0]
        on_markers = DualHMM(n_states=4, n_iter=3, window=4, placement_window=3, markers=13)
        assert on_markers.fit([(_broken(a, np.nan, slice(5, 8)), b)]) is on_markers


def _first_motion(fam: Family, data: dict) -> Motion:
    takes = data[fam.data]
    return takes[0][0] if fam.data == "pairs" else takes[0]


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_wrong_arguments_are_one_line_alike_in_every_family(fam, fitted, data):
    """A new user's trial met "'Motion' object is not iterable", "'int' object has no
    attribute 'choice'" and NumPy's broadcasting errors from deep inside, each family its
    own: every verb's arguments are now checked alike (``models.base.check_arguments``)."""
    model, motion = fitted[fam.name], _first_motion(fam, data)
    name = type(model).__name__
    takes = data[fam.data]
    with pytest.raises(TypeError, match=rf"{name}.fit takes a list of"):
        fam.make().fit(takes[0])  # one take (or one pair) where a list is meant
    if fam.data == "pairs":
        a, b = takes[0]
        with pytest.raises(ValueError, match="differ in length"):  # the chain cut it silently
            fam.make().fit([(a, b.trim(0, b.n_frames // 2))])
        with pytest.raises(ValueError, match="fps and B"):  # as many frames, another rate
            fam.make().fit([(a, b.resample(b.fps / 2).trim(0, a.n_frames // 2)), (a, b)])
    for verb in ("respond", "predict"):
        if verb in model.VERBS:
            method = getattr(model, verb)
            if verb == "predict":
                method = functools.partial(method, seconds=0.5)
            with pytest.raises(TypeError, match=rf"{name}.{verb} takes a Motion"):
                method(motion.positions())
            with pytest.raises(ValueError, match="has no frame"):
                method(motion.trim(0, 0))
            broken = motion.trim(0, 40)
            broken.rotations[10:13] = np.nan
            if type(model).TAKES_MISSING:
                assert np.isfinite(method(broken).positions()).all()
            else:  # "Probabilities contain NaN", "zero norm quaternions" before
                with pytest.raises(ValueError, match=r"3 frames \(first 10, last 12\)"):
                    method(broken)
    if "score" in model.VERBS and not type(model).SCORES_ONE:
        one = takes[0]  # one motion where a list is meant: a list of one
        assert model.score(one) == model.score([one])
    if "generate" in model.VERBS:  # an integer rng is a seed, as random_state is
        seeded = fam.verbs["generate"]
        out = seeded(model, takes)
        again = (
            model.generate(2.0, rng=0) if fam.name != "gait" else model.generate(n_steps=3, rng=0)
        )
        assert isinstance(out, Motion) and isinstance(again, Motion)
        if fam.name != "gait":
            with pytest.raises(ValueError, match="seconds must be a non-negative number"):
                model.generate(seconds=-1.0)
    if "predict" in model.VERBS:
        with pytest.raises(ValueError, match="seconds must be a positive number"):
            model.predict(motion, seconds=0)

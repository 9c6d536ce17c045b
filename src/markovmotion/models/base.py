"""The one contract every top-level model of markovmotion follows.

scikit-learn's conventions (``sklearn/base.py``), turned into a model file:

- the constructor stores hyper-parameters only, unchanged; ``fit`` does the
  work and returns ``self``; everything learnt ends in ``_``;
- ``save(path)`` writes an ``.npz`` with a JSON header (never pickled) from
  the constructor's parameters and the ``_`` attributes (:mod:`markovmotion.state`);
  ``Model.load(path)`` (or ``DualHMM.load(path)``) returns the model alone,
  whatever its kind, found through the ``KIND`` each class registers once;
  extra header entries given to ``save`` come back as attributes (``source``
  -> ``source_``);
- ``train_files_`` always says what the model was trained on (file name and
  content hash, :func:`file_record`), so evaluation on any INDEX.csv can leave
  those takes out (:mod:`markovmotion.evaluate.takes`);
- the verbs of DESIGN.md, each with one meaning, where the model has it:
  ``generate`` (new motion), ``predict`` (continue an observed motion),
  ``respond`` (a whole partner motion for a whole input motion), ``score``
  (log-likelihood), and ``partner()`` for the online protocol of
  :mod:`markovmotion.models.online`. ``VERBS`` lists those a class offers;
  each raises scikit-learn's ``NotFittedError`` before ``fit``;
- the arguments of ``fit`` and of every verb are checked alike in every family
  (:func:`check_takes`, :func:`check_arguments`), so a wrong one is one line
  naming the model and the verb.

Randomness: ``random_state`` at construction, ``rng`` (a
:class:`numpy.random.Generator`, or an integer seed) at call time, and
``stochastic=`` where a verb can either draw or take the most likely choice.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import math
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.errors import ModelFormatError, NothingRecordedError, TooLittleDataError
from markovmotion.persist import load_npz, save_npz
from markovmotion.state import estimator_state, is_fitted, register, restore_estimator

#: Every model kind, by the ``KIND`` its class declares (filled at class creation).
KINDS: dict[str, type[Model]] = {}

#: The verbs of the contract, in the order the docs list them.
ALL_VERBS = ("generate", "predict", "respond", "score", "partner")
#: Methods besides the verbs that need a fitted model (the gait model's style adaptation).
FITTED_FIRST = ("adapt",)


class Component(BaseEstimator):
    """Base of the estimators the models are built of (HSMM, VLMM, behaviour chain).

    Reading a learnt attribute (a name ending in ``_``, or a property made of them) of one
    that has learnt nothing raises scikit-learn's ``NotFittedError`` (an ``AttributeError``
    too, so ``hasattr`` still says False), so every verb used before ``fit`` says so instead
    of naming an attribute; once fitted, this costs nothing (Python asks ``__getattr__`` only
    for missing attributes).
    """

    def __getattr__(self, name: str) -> Any:
        learnt = name.endswith("_") and not name.startswith("_")
        derived = isinstance(getattr(type(self), name, None), property)  # it read a learnt one
        if (learnt or derived) and not is_fitted(self):
            raise NotFittedError(
                f"This {type(self).__name__} is not fitted yet: call fit before using it "
                f"(no {name})"
            )
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


class Model(BaseEstimator):
    """Base of every top-level model (module docstring).

    Subclasses set ``KIND`` (the name written into model files) and ``VERBS``
    (which of :data:`ALL_VERBS` they implement). Registration happens when the
    class is created, so loading never needs a lazy import.
    """

    KIND: ClassVar[str] = ""
    VERBS: ClassVar[tuple[str, ...]] = ()
    #: Whether ``score`` takes one motion (the dual HMM: log P(A)) rather than a list of
    #: them (one motion given to a list's ``score`` is taken as a list of one).
    SCORES_ONE: ClassVar[bool] = False
    #: Whether ``respond``, ``predict`` and ``score`` take a Motion whose frames hold NaN
    #: (missing) and answer them, and ``fit`` learns from one (the dual HMM: on markers; on
    #: joints it refuses one itself); the others refuse one in one line, naming the frames
    #: (markers' gaps are filled by every model that reads markers).
    TAKES_MISSING: ClassVar[bool] = False
    #: Whether ``fit`` learns from two-person takes, (A, B) pairs (else from takes).
    FITS_PAIRS: ClassVar[bool] = False
    #: What one take of ``fit`` (of a pair: each of A and B) and one motion of a list's
    #: ``score`` may be (:func:`check_takes`; the gait model: Motions only).
    TAKES: ClassVar[tuple[type, ...]] = (Motion, Markers)
    #: Two-person takes a pair family's ``fit`` also learns from as they are (the behaviour
    #: chain's TwoPeople of silhouettes tracked in video).
    PREPARED_TAKES: ClassVar[tuple[type, ...]] = ()
    #: Header entries of :meth:`save` that are not extras (everything else is one).
    _RESERVED: ClassVar[frozenset[str]] = frozenset(
        {"format", "format_version", "library_version", "kind", "model"}
    )

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        register(cls)
        kind = cls.__dict__.get("KIND")
        if kind:
            if kind in KINDS and KINDS[kind].__qualname__ != cls.__qualname__:
                raise TypeError(f"model kind {kind!r} is taken by {KINDS[kind].__name__}")
            KINDS[kind] = cls
        unknown = set(cls.VERBS) - set(ALL_VERBS)
        if unknown:
            raise TypeError(f"{cls.__name__}.VERBS names unknown verbs {sorted(unknown)}")
        for verb in (*cls.VERBS, *FITTED_FIRST):
            method = cls.__dict__.get(verb)
            if callable(method):
                setattr(cls, verb, _fitted_first(method))
        if callable(fit := cls.__dict__.get("fit")):
            cls.fit = _takes_checked(fit)

    def check_params(self) -> None:
        """Raise ValueError (one line, naming the parameter) for a hyper-parameter out of its
        choices or range; ``fit`` calls it before it looks at its takes, so a wrong setting is
        said whatever the data (the dual HMM and the chain check theirs here)."""

    @property
    def takes_arrays(self) -> bool:
        """Whether ``fit``, ``score``, ``predict`` and ``respond`` take arrays of features rather
        than motions (the VLMM's contour models)."""
        return False

    # ------------------------------------------------------------ files
    def save(self, path: str | os.PathLike[str], **extras: Any) -> None:
        """Write the model to ``path`` (``.npz`` + JSON header), atomically.

        ``extras`` (JSON values) are stored in the header and come back from
        :meth:`load` as attributes with a trailing ``_`` (``source="mocap"`` ->
        ``model.source_``).
        """
        if not self.KIND:
            raise TypeError(f"{type(self).__name__} declares no KIND and cannot be saved")
        clash = self._RESERVED & set(extras)
        if clash:
            raise ValueError(f"header entries {sorted(clash)} are reserved")
        if not hasattr(self, "train_files_"):
            raise NotFittedError(f"This {type(self).__name__} is not fitted: nothing to save")
        arrays: dict[str, np.ndarray] = {}
        header = {"model": estimator_state(self, "model", arrays), **extras}
        save_npz(path, self.KIND, header, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Self:
        """The model in ``path``, of this class (or any kind when called on :class:`Model`).

        Raises:
            ModelFormatError: not a model file, damaged, or of another kind.
        """
        header, arrays = load_npz(path)
        kind = header.get("kind")
        found = KINDS.get(kind) if isinstance(kind, str) else None
        if found is None:
            raise ModelFormatError(path, f"unknown model kind {kind!r}")
        if not issubclass(found, cls):
            raise ModelFormatError(path, f"is a {kind!r} model, expected {cls.KIND!r}")
        state = header.get("model")
        if not isinstance(state, dict):
            raise ModelFormatError(path, "damaged model header (no model state)")
        try:
            model = restore_estimator(state, arrays)
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ModelFormatError(path, f"damaged model ({type(exc).__name__}: {exc})") from None
        if not isinstance(model, found):
            raise ModelFormatError(path, f"header says {kind!r} but holds {type(model).__name__}")
        if not hasattr(model, "train_files_"):  # saved models are fitted (see save)
            raise ModelFormatError(
                path, "damaged model: model: missing learnt attribute train_files_"
            )
        for key, value in header.items():
            if key not in cls._RESERVED:
                setattr(model, f"{key}_", value)
        return model

    # ------------------------------------------------------------ training files
    def record_training(self, motions: Iterable[Motion | Markers]) -> None:
        """Set ``train_files_`` from the motions ``fit`` was given (:func:`file_record`)."""
        seen: dict[str, dict[str, str]] = {}
        for motion in motions:
            rec = file_record(motion)
            seen.setdefault(rec["sha256"], rec)
        self.train_files_ = list(seen.values())


def _fitted_first(method: Callable[..., Any]) -> Callable[..., Any]:
    """``method`` raising scikit-learn's NotFittedError while the model has learnt nothing,
    its arguments checked first (:func:`check_arguments`)."""

    @functools.wraps(method)
    def verb(self: Model, *args: Any, **kwargs: Any) -> Any:
        if not is_fitted(self):
            raise NotFittedError(
                f"This {type(self).__name__} is not fitted yet: call fit (or load a model "
                f"file) before {method.__name__}"
            )
        args, kwargs = check_arguments(self, method.__name__, args, kwargs)
        return method(self, *args, **kwargs)

    return verb


def finite_frames(motion: Motion | Markers) -> np.ndarray:
    """(F,) whether each frame's rotations and translations (markers: positions) are all
    finite numbers."""
    if isinstance(motion, Markers):
        return np.isfinite(motion.positions).all(axis=(1, 2))
    if motion.n_frames == 1:  # online: one frame, one sum (NaN or inf if any value is)
        return np.array([math.isfinite(motion.rotations.sum() + motion.translations.sum())])
    return np.isfinite(motion.rotations).all(axis=(1, 2)) & np.isfinite(motion.translations).all(
        axis=(1, 2)
    )


def check_motion(motion: object, where: str, missing: bool = True) -> None:
    """Raise (one line, naming ``where``) unless ``motion`` is a Motion or Markers with
    frames (TypeError, ValueError); with ``missing`` False, also unless every frame of a
    Motion is finite (ValueError naming the frames that are not; markers go unseen now and
    then, and every model that reads them fills their gaps); and unless something of it
    was recorded: a whole frame of a Motion, one finite value of Markers (a take of NaN
    alone was answered, and scored as certain, by the dual HMM; a take of markers never
    seen failed deep inside the chain). Those two are :class:`NothingRecordedError`, an
    expected error (one line on the command line) that is also a ValueError."""
    if not isinstance(motion, (Motion, Markers)):
        raise TypeError(f"{where} takes a Motion (or Markers), not {type(motion).__name__}")
    if motion.n_frames == 0:
        raise NothingRecordedError(f"{where}: {motion.name or 'the motion'} has no frame")
    finite = finite_frames(motion) if isinstance(motion, Motion) else None
    seen = finite.any() if finite is not None else np.isfinite(motion.positions).any()
    if not seen:
        n = motion.n_frames
        raise NothingRecordedError(
            f"{where}: {motion.name or 'the motion'} holds NaN or infinite values in "
            f"{'every one of its ' + str(n) + ' frames' if n > 1 else 'its one frame'}: "
            "nothing of it was recorded"
        )
    if not missing and finite is not None:
        bad = np.flatnonzero(~finite)
        if len(bad):
            raise ValueError(
                f"{where}: {motion.name or 'the motion'} holds NaN or infinite values in "
                f"{len(bad)} frame{'s' if len(bad) > 1 else ''} (first {bad[0]}, last "
                f"{bad[-1]}); this model takes whole frames only: cut or fill them first"
            )


def check_arguments(
    model: Model, verb: str, args: tuple, kwargs: dict[str, Any]
) -> tuple[tuple, dict[str, Any]]:
    """A verb's arguments checked alike in every family, so a wrong one is one line, not an
    error from deep inside: the motion of ``respond`` and ``predict`` (:func:`check_motion`;
    frames holding NaN unless the class :attr:`~Model.TAKES_MISSING`); ``score``'s one motion
    (:attr:`~Model.SCORES_ONE`) or list of them (:func:`check_takes`), one motion given for a
    list taken as a list of one; ``seconds`` finite and positive (``generate``: or 0); an
    integer ``rng`` is a seed (``np.random.default_rng``), as ``random_state`` is. The
    arguments, so changed."""
    where = f"{type(model).__name__}.{verb}"
    first = args[0] if args else None
    arrays = model.takes_arrays and isinstance(first, np.ndarray)
    if verb in ("respond", "predict") and args and not arrays:
        check_motion(first, where, missing=type(model).TAKES_MISSING)
    elif verb == "score" and args:
        if type(model).SCORES_ONE:
            check_motion(first, where)
        else:
            one = isinstance(first, (Motion, Markers))
            args = (check_takes(model, [first] if one else first, verb), *args[1:])
    seconds = kwargs.get("seconds")
    if seconds is not None:
        low_ok = verb == "generate"
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds)) or not (
            seconds > 0 or (low_ok and seconds == 0)
        ):
            raise ValueError(
                f"{where}: seconds must be a {'non-negative' if low_ok else 'positive'} "
                f"number, got {seconds!r}"
            )
    rng = kwargs.get("rng")
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        kwargs = {**kwargs, "rng": np.random.default_rng(int(rng))}
    return args, kwargs


def _takes_checked(fit: Callable[..., Any]) -> Callable[..., Any]:
    """``fit`` with its hyper-parameters (:meth:`Model.check_params`), then its takes checked
    first (:func:`check_takes`, the one place every family's takes are checked): a lone take
    (or a lone pair) where a list of them is meant failed deep inside with "'Motion' object
    is not iterable", an empty list with an IndexError."""

    first = list(inspect.signature(fit).parameters)[1]  # after self: the takes

    @functools.wraps(fit)
    def checked(self: Model, *args: Any, **kwargs: Any) -> Any:
        self.check_params()  # a wrong setting first, whatever the takes
        if args:
            args = (check_takes(self, args[0], "fit"), *args[1:])
        elif first in kwargs:
            kwargs = {**kwargs, first: check_takes(self, kwargs[first], "fit")}
        return fit(self, *args, **kwargs)

    return checked


def check_takes(model: Model, takes: object, verb: str = "fit") -> Sequence[Any]:
    """``takes`` as ``model``'s ``fit`` (or a list's ``score``, ``verb``) may take them, else
    one line naming the model, the verb and the take (index from 0):

    - TypeError: not a list (one take, one (A, B) pair, a string, None...); a take that is not
      a Motion or Markers (:attr:`~Model.TAKES`; a contour model's arrays too, a pair family's
      :attr:`~Model.PREPARED_TAKES`), or, where ``fit`` learns from pairs, not an (A, B) pair;
    - ValueError: an empty list (:class:`~markovmotion.errors.TooLittleDataError` for
      ``fit``); a pair whose A and B differ in length or rate (A and B are recorded together,
      frame for frame); a take with no frame, or (unless the class
      :attr:`~Model.TAKES_MISSING`) a Motion with NaN or infinite values
      (:func:`check_motion`: the frames named; markers' gaps are filled by every model).

    Returns the takes, an iterator (a generator) as a list."""
    where = f"{type(model).__name__}.{verb}"
    pairs = verb == "fit" and type(model).FITS_PAIRS
    one = (Motion, Markers)
    kinds = type(model).TAKES
    arrays = model.takes_arrays
    noun = "(A, B) pairs" if pairs else "takes" if verb == "fit" else "Motions"
    if isinstance(takes, one):
        raise TypeError(f"{where} takes a list of {noun}: give [take]")
    if (
        pairs
        and isinstance(takes, tuple)
        and len(takes) == 2
        and all(isinstance(m, one) for m in takes)
    ):
        raise TypeError(f"{where} takes a list of (A, B) pairs: give [(a, b)]")
    if isinstance(takes, Iterator):
        takes = list(takes)
    if not isinstance(takes, Sequence) or isinstance(takes, (str, bytes)):
        also = " (or of (frames, 2n) arrays)" if arrays else ""
        raise TypeError(f"{where} takes a list of {noun}{also}, not {type(takes).__name__}")
    if not len(takes):
        if verb == "fit":
            raise TooLittleDataError(f"{where}: no {noun} to learn from (the list is empty)")
        raise ValueError(f"{where}: no motion to score (the list is empty)")
    what = "take" if verb == "fit" else "motion"
    missing = type(model).TAKES_MISSING
    for i, take in enumerate(takes):
        if pairs:
            if isinstance(take, type(model).PREPARED_TAKES):
                continue
            if isinstance(take, one):
                raise TypeError(f"{where}: take {i} is one motion, not an (A, B) pair")
            if not isinstance(take, (tuple, list)) or len(take) != 2:
                held = f" of {len(take)}" if isinstance(take, (tuple, list)) else ""
                raise TypeError(
                    f"{where}: take {i} is {_a(take)}{held}, not an (A, B) pair of Motions (or "
                    "Markers)"
                )
            for role, m in zip("AB", take, strict=True):
                if not isinstance(m, kinds):
                    raise TypeError(f"{where}: take {i}: {role} is {_a(m)}, not {_kinds(kinds)}")
            _check_pair(take, f"{where}: take {i}")
            for role, m in zip("AB", take, strict=True):
                check_motion(m, f"{where}: take {i} ({role})", missing=missing)
        elif arrays and not isinstance(take, one):
            continue  # a contour model checks its arrays itself (contour_arrays)
        elif not isinstance(take, kinds):
            raise TypeError(f"{where}: {what} {i} is {_a(take)}, not {_kinds(kinds)}")
        else:
            check_motion(take, f"{where}: {what} {i}", missing=missing)
    return takes


def _check_pair(pair: Sequence[Motion | Markers], where: str) -> None:
    """Raise ValueError (one line) unless A and B of ``pair`` have one rate and one length."""
    a, b = pair
    if not math.isclose(a.fps, b.fps, rel_tol=1e-6):
        raise ValueError(
            f"{where}: A ({a.name or 'unnamed'}) at {a.fps:g} fps and B "
            f"({b.name or 'unnamed'}) at {b.fps:g}: a pair is recorded together, frame "
            "for frame (give both at one rate)"
        )
    if a.n_frames != b.n_frames:
        raise ValueError(
            f"{where}: A ({a.name or 'unnamed'}, {a.n_frames} frames) and B "
            f"({b.name or 'unnamed'}, {b.n_frames}) differ in length: a pair is "
            "recorded together, frame for frame (trim both to the same frames)"
        )


def _a(value: object) -> str:
    """What ``value`` is, for messages: "None", "a str", "an int", "an ndarray", "Markers"."""
    if value is None:
        return "None"
    name = type(value).__name__
    if name.endswith("s"):  # Markers
        return name
    return f"{'an' if name[0] in 'AEIOUaeiou' or name == 'ndarray' else 'a'} {name}"


def _kinds(kinds: tuple[type, ...]) -> str:
    """What a take of ``kinds`` may be, for messages: "a Motion (or Markers)", "a Motion"."""
    first, *rest = (k.__name__ for k in kinds)
    return f"a {first}" + (f" (or {', '.join(rest)})" if rest else "")


def file_record(motion: Motion | Markers) -> dict[str, Any]:
    """Name and content hash of what ``motion`` (or markers) was read from, and
    :func:`motion_key`, what the take holds whatever file it is written in (``content``),
    and :func:`motion_signature`, what it holds at whatever frame rate (``signature``).

    The SHA-256 of the file's bytes when the motion came from a file (so the
    same take under another path or name is recognised), else of its arrays.
    """
    key, signature = motion_content(motion)
    if motion.source and os.path.isfile(motion.source):
        return {
            "file": os.path.basename(motion.source),
            "sha256": file_sha256(motion.source),
            "content": key,
            "signature": signature,
        }
    digest = hashlib.sha256()
    arrays = (
        (motion.positions,)
        if isinstance(motion, Markers)
        else (motion.rotations, motion.translations)
    )
    for arr in arrays:
        digest.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return {
        "file": motion.name or "(in memory)",
        "sha256": digest.hexdigest(),
        "content": key,
        "signature": signature,
    }


def motion_content(motion: Motion | Markers) -> tuple[str, list[float]]:
    """:func:`motion_key` and :func:`motion_signature` of a take, its points (joints by
    forward kinematics, or markers) worked out once."""
    points = _points(motion)
    return motion_key(motion, points), motion_signature(motion, points)


def _points(motion: Motion | Markers, points: np.ndarray | None = None) -> np.ndarray:
    """``points`` if given, else the take's points (F, P, 3): joints by forward kinematics,
    or markers."""
    if points is not None:
        return points
    return np.asarray(
        motion.positions if isinstance(motion, Markers) else motion.positions(), dtype=float
    )


def motion_key(motion: Motion | Markers, points: np.ndarray | None = None) -> str:
    """A take's content as read (mm, Y up), whatever file holds it: its frame count and the
    mean and spread of its points (joints by forward kinematics, or markers seen) along each
    axis, to 1 mm, hashed. The same take written again another way (line endings, rotation
    order, units, axes, marker labels or order) has the same key; a file's bytes
    (:func:`file_sha256`) differ, and a training take so re-saved had been evaluated as a
    test take. Our own: six rounded numbers, so a re-saving's rounding (1e-5 mm) changes the
    key only for a number within that of a millimetre's edge. ``points``: the take's
    (:func:`motion_content`), if already worked out."""
    flat = _points(motion, points).reshape(-1, 3)
    flat = flat[np.isfinite(flat).all(axis=1)]
    stats = np.r_[flat.mean(axis=0), flat.std(axis=0)] if len(flat) else np.zeros(6)
    text = f"{motion.n_frames}:" + ",".join(f"{v:.0f}" for v in np.round(stats) + 0.0)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


#: Moments across a take at which :func:`motion_signature` samples it.
SIGNATURE_MOMENTS = 32
#: Two signatures are of one take when their spans differ by at most this (s) plus 1 %...
SIGNATURE_SPAN_S = 0.05
#: ... and their sampled means and spreads by at most this root mean square (mm).
SIGNATURE_MM = 10.0


def motion_signature(motion: Motion | Markers, points: np.ndarray | None = None) -> list[float]:
    """A take's content at no particular frame rate: the time from its first frame to its
    last (s), then, at :data:`SIGNATURE_MOMENTS` moments evenly across that time, the mean
    and spread of its points (joints by forward kinematics, or markers seen) along each axis
    (mm, Y up; linear between frames), to 0.1 mm. A copy at another rate (a 30 fps take
    resampled to 120) has nearly the same numbers (:func:`same_signature`); its frame count,
    and so :func:`motion_key`, differ, and such a training take had been evaluated as a
    test take. Our own: no library compares takes across frame rates. ``points``: as for
    :func:`motion_key`."""
    points = _points(motion, points)
    seen = np.isfinite(points).all(axis=-1, keepdims=True)
    count = seen.sum(axis=1)  # (F, 1)
    known = count[:, 0] > 0
    span = (motion.n_frames - 1) / motion.fps
    if not known.any():
        return [round(span, 4)]
    total = np.where(seen, points, 0.0).sum(axis=1)
    mean = total[known] / count[known]
    square = np.where(seen, points**2, 0.0).sum(axis=1)[known] / count[known]
    spread = np.sqrt(np.maximum(square - mean**2, 0.0))
    stats = np.c_[mean, spread]  # (frames known, 6)
    times = np.flatnonzero(known) / motion.fps
    moments = np.linspace(0.0, span, SIGNATURE_MOMENTS)
    sampled = np.stack([np.interp(moments, times, column) for column in stats.T], axis=1)
    return [round(span, 4), *np.round(sampled.ravel(), 1).tolist()]


def same_signature(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether two :func:`motion_signature` are of one take (within :data:`SIGNATURE_SPAN_S`
    plus 1 % and :data:`SIGNATURE_MM`); False for a malformed one (a model file's, tampered)."""
    try:
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    except (TypeError, ValueError):
        return False
    size = 1 + 6 * SIGNATURE_MOMENTS
    if (
        x.shape != (size,)
        or y.shape != (size,)
        or not (np.isfinite(x).all() and np.isfinite(y).all())
    ):
        return False
    if abs(x[0] - y[0]) > SIGNATURE_SPAN_S + 0.01 * max(x[0], y[0]):
        return False
    return float(np.sqrt(np.mean((x[1:] - y[1:]) ** 2))) <= SIGNATURE_MM


_HASHES: dict[tuple[str, int, int], str] = {}


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks (memoised by path, size and mtime)."""
    st = os.stat(path)
    key = (os.path.realpath(path), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        digest = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
        _HASHES[key] = digest.hexdigest()
    return _HASHES[key]


def training_hashes(model: Model) -> set[str]:
    """The content hashes of the files ``model`` was trained on."""
    return {rec["sha256"] for rec in getattr(model, "train_files_", [])}


def training_signatures(model: Model) -> list[Sequence[float]]:
    """The :func:`motion_signature` of each take ``model`` was trained on (none for a model
    saved before they were recorded)."""
    return [
        rec["signature"]
        for rec in getattr(model, "train_files_", [])
        if isinstance(rec, dict) and rec.get("signature")
    ]


def training_keys(model: Model) -> set[str]:
    """The :func:`motion_key` of each take ``model`` was trained on (none for a model saved
    before they were recorded)."""
    return {rec["content"] for rec in getattr(model, "train_files_", []) if rec.get("content")}


def flatten(takes: Sequence[Any]) -> list[Motion | Markers]:
    """Motions (or Markers) in ``takes`` (them, or tuples of them as two-person takes)."""
    out: list[Motion | Markers] = []
    for take in takes:
        if isinstance(take, Motion | Markers):
            out.append(take)
        elif isinstance(take, tuple | list):
            out.extend(m for m in take if isinstance(m, Motion | Markers))
    return out

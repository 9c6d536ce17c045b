"""Turning fitted estimators into JSON + arrays and back, for :mod:`markovmotion.persist`;
and results as strict JSON text (:func:`json_text`).

An estimator (feature step or model) follows scikit-learn's conventions: its
constructor stores hyper-parameters (``get_params``), and everything learnt
ends in ``_``. Its state is then the hyper-parameters and the learnt
attributes; arrays go to the ``.npz``, everything else to the JSON header.
"""

from __future__ import annotations

import inspect
import json
import math
from typing import Any

import numpy as np

from markovmotion.core.skeleton import Skeleton

_REGISTRY: dict[str, type] = {}


def register(cls: type) -> type:
    """Class decorator: make ``cls`` restorable by name from a saved state."""
    _REGISTRY[cls.__name__] = cls
    return cls


def _is_json_scalar(v: Any) -> bool:
    return v is None or isinstance(v, bool | int | float | str)


def _to_json(value: Any, key: str, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(value, np.ndarray):
        arrays[key] = value
        return {"__array__": key}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Skeleton):
        return {"__skeleton__": value.to_dict()}
    if isinstance(value, list | tuple):
        return {"__list__": [_to_json(v, f"{key}/{i}", arrays) for i, v in enumerate(value)]}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError(f"cannot save dict with non-string keys in {key!r}")
        return {"__dict__": {k: _to_json(v, f"{key}/{k}", arrays) for k, v in value.items()}}
    if hasattr(value, "get_params") and type(value).__name__ in _REGISTRY:
        return {"__estimator__": estimator_state(value, key, arrays)}
    if _is_json_scalar(value):
        return value
    raise TypeError(f"cannot save attribute {key!r} of type {type(value).__name__}")


class StateError(ValueError):
    """A saved state that does not fit what it claims to be; the message names the field."""


def check_array(arr: Any, field: str) -> np.ndarray:
    """``arr`` if it is a NumPy array of numbers or booleans with only finite floats.

    Raises :class:`StateError` naming ``field`` otherwise.
    """
    if not isinstance(arr, np.ndarray):
        raise StateError(f"{field}: expected an array, found {type(arr).__name__}")
    if arr.dtype.kind not in "biufc":
        raise StateError(f"{field}: array of {arr.dtype} (numbers or booleans only)")
    if arr.dtype.kind in "fc" and not np.isfinite(arr).all():
        raise StateError(f"{field}: NaN or infinite values")
    return arr


# ------------------------------------------------------------ checks for ``check_state``
# Small, cheap checks shared by every estimator's ``check_state`` (they run on every load);
# each raises StateError naming the learnt attribute (``restore_estimator`` adds the field).


def is_fitted(est: Any) -> bool:
    """Whether ``est`` holds any learnt attribute (an unfitted estimator, e.g. a
    hyper-parameter template, has nothing to check)."""
    return any(k.endswith("_") and not k.startswith("_") for k in vars(est))


def require(est: Any, *names: str) -> None:
    """Raise ``missing learnt attribute NAME`` unless ``est`` has every one of ``names``."""
    for name in names:
        if not hasattr(est, name):
            raise StateError(f"missing learnt attribute {name}")


def require_types(est: Any, **types: type) -> None:
    """Raise unless ``est`` has each learnt attribute ``name=type`` given, of that type."""
    require(est, *types)
    for name, cls in types.items():
        if not isinstance(getattr(est, name), cls):
            found = type(getattr(est, name)).__name__
            raise StateError(f"{name}: expected a {cls.__name__}, found {found}")


def check_shape(name: str, arr: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """``arr`` if it is an array of ``shape`` (``None`` matches any length)."""
    if not isinstance(arr, np.ndarray):
        raise StateError(f"{name}: expected an array, found {type(arr).__name__}")
    if arr.ndim != len(shape) or any(
        e is not None and e != n for e, n in zip(shape, arr.shape, strict=True)
    ):
        want = ", ".join("*" if e is None else str(e) for e in shape)
        raise StateError(f"{name}: shape {arr.shape}, expected ({want}{',' * (len(shape) == 1)})")
    return arr


def check_index(name: str, arr: Any, n: int, low: int = 0) -> np.ndarray:
    """``arr`` if it is an integer array (or integer) with every value in ``[low, n)``."""
    a = np.asarray(arr)
    if a.dtype.kind not in "iu" or isinstance(arr, bool):
        raise StateError(f"{name}: expected integer indices, found {a.dtype}")
    if a.size and (a.min() < low or a.max() >= n):
        bad = a[(a < low) | (a >= n)].flat[0]
        raise StateError(f"{name}: index {bad} outside [{low}, {n})")
    return a


def check_count(name: str, value: Any, minimum: int = 1) -> int:
    """``value`` if it is an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise StateError(f"{name}: expected an integer >= {minimum}, found {value!r}")
    return int(value)


def check_lengths(name: str, lengths: Any, total: int) -> np.ndarray:
    """``lengths`` if it is a 1-D array of non-negative integers summing to ``total``
    (the sequence lengths of a concatenated array of ``total`` items)."""
    check_index(name, check_shape(name, lengths, (None,)), total + 1)
    if int(lengths.sum()) != total:
        raise StateError(f"{name}: lengths sum to {int(lengths.sum())}, not {total}")
    return lengths


def check_positive(name: str, arr: Any) -> np.ndarray:
    """``arr`` if every value is > 0 (variances, scales, durations)."""
    a = np.asarray(arr)
    if a.size and not np.all(a > 0):
        raise StateError(f"{name}: values must be positive (found {np.min(a):.3g})")
    return a


def check_distribution_rows(name: str, arr: Any, indptr: Any = None) -> np.ndarray:
    """``arr`` if its values are in [0, 1] and each row sums to 1: rows along the last
    axis, or the segments ``arr[indptr[i]:indptr[i + 1]]`` (non-empty ones) of a flat array."""
    a = np.asarray(arr, dtype=float)
    if a.size and not (np.all(a >= 0) and np.all(a <= 1)):
        raise StateError(f"{name}: probabilities outside [0, 1]")
    if indptr is None:
        sums = a.sum(axis=-1) if a.size else np.ones(1)
    else:
        ptr = np.asarray(indptr)
        starts = ptr[:-1][ptr[1:] > ptr[:-1]]
        sums = np.add.reduceat(a, starts) if len(starts) else np.ones(1)
    if not np.allclose(sums, 1.0, atol=1e-6):
        raise StateError(f"{name}: a probability row does not sum to 1")
    return a


def check_indptr(name: str, ptr: Any, n_rows: int, n_values: int) -> np.ndarray:
    """``ptr`` if it is a CSR row pointer: ``n_rows + 1`` non-decreasing integers
    from 0 to ``n_values``."""
    check_shape(name, ptr, (n_rows + 1,))
    check_index(name, ptr, n_values + 1)
    if ptr[0] != 0 or ptr[-1] != n_values or np.any(np.diff(ptr) < 0):
        raise StateError(f"{name}: not a row pointer from 0 to {n_values}")
    return ptr


def check_joint_index(est: Any) -> None:
    """A fitted step's ``skeleton_`` is a Skeleton and its ``joint_index_`` joints of it."""
    if is_fitted(est):
        require(est, "skeleton_", "joint_index_")
        if not isinstance(est.skeleton_, Skeleton):
            raise StateError(
                f"skeleton_: expected a skeleton, found {type(est.skeleton_).__name__}"
            )
        check_index(
            "joint_index_",
            check_shape("joint_index_", est.joint_index_, (None,)),
            est.skeleton_.n_joints,
        )


def _from_json(value: Any, arrays: dict[str, np.ndarray], field: str = "model") -> Any:
    if isinstance(value, dict):
        if "__array__" in value:
            key = value["__array__"]
            if not isinstance(key, str) or key not in arrays:
                raise StateError(f"{field}: array {key!r} is missing from the file")
            return check_array(arrays[key], field)
        if "__skeleton__" in value:
            try:
                return Skeleton.from_dict(value["__skeleton__"])
            except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
                raise StateError(f"{field}: not a skeleton ({exc})") from None
        if "__list__" in value:
            items = value["__list__"]
            if not isinstance(items, list):
                raise StateError(f"{field}: '__list__' is not a list")
            return [_from_json(v, arrays, f"{field}[{i}]") for i, v in enumerate(items)]
        if "__dict__" in value:
            items = value["__dict__"]
            if not isinstance(items, dict):
                raise StateError(f"{field}: '__dict__' is not an object")
            return {k: _from_json(v, arrays, f"{field}.{k}") for k, v in items.items()}
        if "__estimator__" in value:
            return restore_estimator(value["__estimator__"], arrays, field)
    if isinstance(value, float) and not np.isfinite(value):
        raise StateError(f"{field}: NaN or infinite value")
    if isinstance(value, list):
        return [_from_json(v, arrays, f"{field}[{i}]") for i, v in enumerate(value)]
    return value


def estimator_state(est: Any, prefix: str, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """JSON description of ``est``; its arrays are added to ``arrays`` under ``prefix/``."""
    learnt = {
        k: _to_json(v, f"{prefix}/{k}", arrays)
        for k, v in vars(est).items()
        if k.endswith("_") and not k.startswith("_")
    }
    params = {
        k: _to_json(v, f"{prefix}/param/{k}", arrays) for k, v in est.get_params(deep=False).items()
    }
    return {"class": type(est).__name__, "params": params, "learnt": learnt}


def restore_estimator(
    state: dict[str, Any], arrays: dict[str, np.ndarray], field: str = "model"
) -> Any:
    """The estimator described by ``state`` (from :func:`estimator_state`).

    Checked before anything is used: the class is a registered one, every
    parameter is a constructor parameter of the type of its default, every
    learnt attribute is a public name ending in ``_``, every array referenced
    exists and holds finite numbers (or booleans). Then the class's optional
    ``check_state()`` (shapes, index ranges, probabilities) runs.

    Raises:
        StateError: (a ``ValueError``) naming the field (``field`` is the path of
            ``state`` in the header, ``"model"`` at the top) and the problem.
    """
    if not isinstance(state, dict):
        raise StateError(f"{field}: expected an estimator state, found {type(state).__name__}")
    name = state.get("class")
    cls = _REGISTRY.get(name) if isinstance(name, str) else None
    if cls is None:
        raise StateError(f"{field}.class: unknown estimator class {name!r}")
    params, learnt = state.get("params", {}), state.get("learnt", {})
    if not isinstance(params, dict) or not isinstance(learnt, dict):
        raise StateError(f"{field}: 'params' and 'learnt' must be objects")
    signature = _parameters(cls)
    kwargs = {}
    for k, v in params.items():
        where = f"{field}.params.{k}"
        if k not in signature and "**" not in signature:
            raise StateError(f"{where}: not a parameter of {cls.__name__}")
        default = signature.get(k, inspect.Parameter.empty)
        kwargs[k] = _check_param(_from_json(v, arrays, where), default, where)
    # a parameter added since a file was saved: the value it was saved with, not today's default
    for k, v in getattr(cls, "PARAMS_OF_OLDER_FILES", {}).items():
        kwargs.setdefault(k, v)
    try:
        est = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise StateError(f"{field}.params: {cls.__name__} refuses them ({exc})") from None
    for k, v in learnt.items():
        where = f"{field}.learnt.{k}"
        if not (isinstance(k, str) and k.isidentifier() and k.endswith("_")) or k.startswith("_"):
            raise StateError(f"{where}: not a learnt attribute name")
        attr = getattr(cls, k, None)
        if callable(attr) or (isinstance(attr, property) and attr.fset is None):
            # a property with a setter (GaussianHMM.covars_) checks what it is given
            raise StateError(f"{where}: would replace a method of {cls.__name__}")
        try:
            setattr(est, k, _from_json(v, arrays, where))
        except ValueError as exc:  # a property's setter refused it
            raise StateError(f"{where}: {exc}") from None
    check = getattr(est, "check_state", None)
    if callable(check):
        try:
            check()
        except StateError as exc:
            raise StateError(f"{field}: {cls.__name__} {exc}") from None
        except (ValueError, TypeError, IndexError, KeyError, AttributeError) as exc:
            raise StateError(f"{field}: {cls.__name__} state is inconsistent ({exc})") from None
    return est


def _parameters(cls: type) -> dict[str, Any]:
    """Constructor parameter name -> default (``inspect.Parameter.empty`` if none);
    ``"**"`` is a key when the constructor takes any keyword."""
    sig = inspect.signature(cls.__init__)
    out: dict[str, Any] = {
        p.name: p.default
        for p in list(sig.parameters.values())[1:]
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }
    if any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values()):
        out["**"] = inspect.Parameter.empty
    return out


def _check_param(value: Any, default: Any, field: str) -> Any:
    """``value`` if it has the simple type of the constructor ``default`` (when it has one)."""
    if default is inspect.Parameter.empty or default is None or value is None:
        return value
    expected: tuple[type, ...] | None = None
    if isinstance(default, bool):
        expected = (bool,)
    elif isinstance(default, int):
        expected = (int, np.integer)
    elif isinstance(default, float):
        expected = (int, float, np.integer, np.floating)
    elif isinstance(default, str):
        expected = (str,)
    elif isinstance(default, list | tuple):
        expected = (list, tuple)
    elif isinstance(default, dict):
        expected = (dict,)
    if expected is None:
        return value
    if isinstance(value, bool) and bool not in expected:
        expected = ()
    if not isinstance(value, expected):
        raise StateError(
            f"{field}: expected {type(default).__name__}, found {type(value).__name__}"
        )
    return value


def finite(value: object) -> object:
    """``value`` with NaN and infinities (Python or NumPy floats, at any depth of dicts,
    lists and tuples) as None: JSON has no NaN, and strict parsers (JavaScript's
    ``JSON.parse``, ``json.loads`` with ``parse_constant``) refuse Python's ``NaN``."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):  # NumPy floats are floats
        return None
    return value


def json_text(value: object, indent: int | None = None) -> str:
    """``value`` as strict JSON (:func:`finite`: NaN as null)."""
    return json.dumps(finite(value), indent=indent, allow_nan=False)

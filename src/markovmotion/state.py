"""Turning fitted estimators into JSON + arrays and back, for :mod:`markovmotion.persist`.

An estimator (feature step or model) follows scikit-learn's conventions: its
constructor stores hyper-parameters (``get_params``), and everything learnt
ends in ``_``. Its state is then the hyper-parameters and the learnt
attributes; arrays go to the ``.npz``, everything else to the JSON header.
"""

from __future__ import annotations

import inspect
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
    try:
        est = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise StateError(f"{field}.params: {cls.__name__} refuses them ({exc})") from None
    for k, v in learnt.items():
        where = f"{field}.learnt.{k}"
        if not (isinstance(k, str) and k.isidentifier() and k.endswith("_")) or k.startswith("_"):
            raise StateError(f"{where}: not a learnt attribute name")
        if callable(getattr(cls, k, None)) or isinstance(getattr(cls, k, None), property):
            raise StateError(f"{where}: would replace a method of {cls.__name__}")
        setattr(est, k, _from_json(v, arrays, where))
    check = getattr(est, "check_state", None)
    if callable(check):
        try:
            check()
        except StateError:
            raise
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

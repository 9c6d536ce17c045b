"""Turning fitted estimators into JSON + arrays and back, for :mod:`markovmotion.persist`.

An estimator (feature step or model) follows scikit-learn's conventions: its
constructor stores hyper-parameters (``get_params``), and everything learnt
ends in ``_``. Its state is then the hyper-parameters and the learnt
attributes; arrays go to the ``.npz``, everything else to the JSON header.
"""

from __future__ import annotations

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


def _from_json(value: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(value, dict):
        if "__array__" in value:
            return arrays[value["__array__"]]
        if "__skeleton__" in value:
            return Skeleton.from_dict(value["__skeleton__"])
        if "__list__" in value:
            return [_from_json(v, arrays) for v in value["__list__"]]
        if "__dict__" in value:
            return {k: _from_json(v, arrays) for k, v in value["__dict__"].items()}
        if "__estimator__" in value:
            return restore_estimator(value["__estimator__"], arrays)
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


def restore_estimator(state: dict[str, Any], arrays: dict[str, np.ndarray]) -> Any:
    """The estimator described by ``state`` (from :func:`estimator_state`)."""
    try:
        cls = _REGISTRY[state["class"]]
    except KeyError:
        raise ValueError(f"unknown estimator class {state.get('class')!r}") from None
    est = cls(**{k: _from_json(v, arrays) for k, v in state["params"].items()})
    for k, v in state["learnt"].items():
        setattr(est, k, _from_json(v, arrays))
    return est

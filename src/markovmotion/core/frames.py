"""Frames given as arrays, checked once where they enter a model (scikit-learn's
``check_array`` in the library's words, without importing scikit-learn or SciPy)."""

from __future__ import annotations

from typing import Any

import numpy as np


def is_sparse(x: Any) -> bool:
    """Whether ``x`` is a SciPy sparse matrix or array (without importing SciPy)."""
    return type(x).__module__.startswith("scipy.sparse")


def check_frames(x: Any, name: str = "X") -> np.ndarray:
    """``x`` as a finite float (frames, dims) array with at least one of each.

    Raises:
        ValueError: one line naming ``name`` and the problem: a sparse matrix (the models
            need dense frames), complex numbers (scikit-learn's wording), not 2-D, no frames
            or no features, NaN or infinite values.
    """
    if is_sparse(x):
        raise ValueError(f"{name} is a sparse matrix: give dense frames (its .toarray())")
    x = np.asarray(x)
    if np.iscomplexobj(x):
        raise ValueError(f"Complex data not supported: {name} holds complex numbers")
    x = np.asarray(x, dtype=float)
    if x.ndim != 2:
        raise ValueError(
            f"{name} must be a (frames, dims) array, got shape {x.shape}: Reshape your data"
        )
    if len(x) == 0 or x.shape[1] == 0:
        raise ValueError(
            f"{name} has {len(x)} frame(s) and {x.shape[1]} feature(s) (shape={x.shape}) while "
            "a minimum of 1 is required."
        )
    if not np.isfinite(x).all():
        raise ValueError(f"{name} holds NaN or infinite values")
    return x

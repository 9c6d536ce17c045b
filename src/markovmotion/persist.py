"""Model files: NumPy arrays in an ``.npz`` with a JSON header; no Python objects are ever unpickled.

The header records the file format version, the library version, the model
kind, its hyper-parameters and the feature pipeline it was trained with, so a
model file read back turns raw motion into motion again without the caller
remembering anything.
"""

from __future__ import annotations

import json
import os
import zipfile
from typing import Any

import numpy as np

from markovmotion.errors import ModelFormatError
from markovmotion.io.files import atomic_write

FORMAT = "markovmotion-model"
FORMAT_VERSION = 1
_HEADER_KEY = "__header__"


def check_model_output(path: str | os.PathLike[str]) -> None:
    """Raise :class:`ModelFormatError` unless ``path`` names an ``.npz`` model file."""
    if not str(path).lower().endswith(".npz"):
        raise ModelFormatError(path, "models are written as .npz: use a .npz name")


def save_npz(
    path: str | os.PathLike[str], kind: str, header: dict[str, Any], arrays: dict[str, np.ndarray]
) -> None:
    """Write ``arrays`` and a JSON ``header`` to ``path`` atomically (compressed ``.npz``)."""
    from markovmotion import __version__

    check_model_output(path)
    if _HEADER_KEY in arrays:
        raise ValueError(f"array name {_HEADER_KEY!r} is reserved")
    full = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "library_version": __version__,
        "kind": kind,
        **header,
    }
    blob = np.frombuffer(json.dumps(full).encode("utf-8"), dtype=np.uint8)
    with atomic_write(path, "wb") as fh:
        np.savez_compressed(fh, **{_HEADER_KEY: blob}, **arrays)


def load_npz(
    path: str | os.PathLike[str], kind: str | None = None
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a file written by :func:`save_npz`; returns ``(header, arrays)``.

    Raises:
        ModelFormatError: the file is missing, not a model file, damaged, of
            another format version, or of another kind than ``kind``.
    """
    if os.path.isfile(path) and not zipfile.is_zipfile(path):
        raise ModelFormatError(path, "not a markovmotion model file (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise ModelFormatError(path, "no such model file") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ModelFormatError(path, f"not a markovmotion model file ({exc})") from None
    if not isinstance(arrays, dict) or _HEADER_KEY not in arrays:
        raise ModelFormatError(path, "not a markovmotion model file (no header)")
    try:
        header = json.loads(arrays.pop(_HEADER_KEY).tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise ModelFormatError(path, "damaged model header") from None
    if header.get("format") != FORMAT:
        raise ModelFormatError(path, "not a markovmotion model file")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelFormatError(
            path,
            f"model file format version {version} (written by markovmotion "
            f"{header.get('library_version', '?')}); this markovmotion reads version "
            f"{FORMAT_VERSION}: retrain the model",
        )
    if kind is not None and header.get("kind") != kind:
        raise ModelFormatError(path, f"is a {header.get('kind')!r} model, expected {kind!r}")
    return header, arrays

"""Model files: NumPy arrays in an ``.npz`` with a JSON header; no Python objects are ever unpickled.

The header records the file format version, the library version, the model
kind, its hyper-parameters and the feature pipeline it was trained with, so a
model file read back turns raw motion into motion again without the caller
remembering anything.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
import zlib
from typing import Any

import numpy as np

from markovmotion.errors import ModelFormatError, MotionFormatError
from markovmotion.io.files import atomic_write, open_regular
from markovmotion.limits import MAX_BYTES, max_bytes, megabytes

FORMAT = "markovmotion-model"
FORMAT_VERSION = 1
_HEADER_KEY = "__header__"
_MAX_MEMBERS = 100_000


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

    Everything is checked before any array is used: the file is a regular
    file; every member's size (from the zip directory, before decompressing)
    is within :data:`markovmotion.limits.MAX_BYTES`; every member is a plain
    ``.npy`` array of numbers or booleans (never pickled); the header is a
    JSON object of this format and version (an integer); and every estimator
    state in the header restores (:func:`markovmotion.state.restore_estimator`:
    classes, parameter types, arrays present and finite, the class's own
    ``check_state``).

    Raises:
        ModelFormatError: the file is missing, not a model file, damaged, of
            another format version, or of another kind than ``kind``; one line
            naming the file and the field.
    """
    try:
        handle = open_regular(path)
    except MotionFormatError as exc:
        problem = "no such model file" if exc.problem == "no such file" else exc.problem
        raise ModelFormatError(path, problem) from None
    with handle:
        arrays = _read_members(path, handle)
    if _HEADER_KEY not in arrays:
        raise ModelFormatError(path, "not a markovmotion model file (no header)")
    try:
        header = json.loads(arrays.pop(_HEADER_KEY).tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise ModelFormatError(path, "damaged model header (not JSON)") from None
    if not isinstance(header, dict):
        found = {list: "array", str: "string", type(None): "null", bool: "boolean"}.get(
            type(header), "number"
        )
        raise ModelFormatError(path, f"damaged model header (a JSON {found}, not an object)")
    if header.get("format") != FORMAT:
        raise ModelFormatError(path, "not a markovmotion model file")
    version = header.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise ModelFormatError(
            path, f"format_version must be an integer, found {json.dumps(version)[:40]}"
        )
    if version != FORMAT_VERSION:
        raise ModelFormatError(
            path,
            f"model file format version {version} (written by markovmotion "
            f"{str(header.get('library_version', '?'))[:40]}); this markovmotion reads version "
            f"{FORMAT_VERSION}: retrain the model",
        )
    if "kind" not in header:
        raise ModelFormatError(path, "header field 'kind' is missing (damaged or not a model?)")
    if not isinstance(header.get("kind"), str):
        raise ModelFormatError(path, "header field 'kind' must be a string")
    if kind is not None and header.get("kind") != kind:
        raise ModelFormatError(path, f"is a {header.get('kind')!r} model, expected {kind!r}")
    _check_states(path, header, arrays)
    return header, arrays


def _read_members(path: str | os.PathLike[str], handle) -> dict[str, np.ndarray]:
    """The arrays of the zip archive open in ``handle``, sizes checked before decompressing."""
    if not zipfile.is_zipfile(handle):
        raise ModelFormatError(
            path,
            "not a markovmotion model file (not an .npz archive: another file, or one cut short)",
        )
    cap = max_bytes()
    arrays: dict[str, np.ndarray] = {}
    try:
        handle.seek(0)
        with zipfile.ZipFile(handle) as archive:
            infos = archive.infolist()
            if len(infos) > _MAX_MEMBERS:
                raise ModelFormatError(path, f"more than {_MAX_MEMBERS} arrays in the file")
            total = 0
            for info in infos:
                total += info.file_size
                if info.file_size > cap or total > cap:
                    raise ModelFormatError(
                        path,
                        f"array {info.filename[:60]!r} decompresses to more than "
                        f"{megabytes(cap)} (limit {MAX_BYTES.env})",
                    )
                if not info.filename.endswith(".npy"):
                    raise ModelFormatError(path, f"unexpected member {info.filename[:60]!r}")
            for info in infos:
                name = info.filename[: -len(".npy")]
                with archive.open(info) as member:
                    arrays[name] = _read_array(path, name, member, info.file_size)
    except ModelFormatError:
        raise
    except (
        OSError,
        EOFError,
        ValueError,
        zipfile.BadZipFile,
        zlib.error,
        NotImplementedError,
    ) as exc:
        raise ModelFormatError(path, f"not a markovmotion model file ({exc})") from None
    return arrays


def _read_array(path, name: str, member, size: int) -> np.ndarray:
    """One ``.npy`` member: numbers or booleans only, shape consistent with its size."""
    fmt = np.lib.format
    version = fmt.read_magic(member)
    if version == (1, 0):
        shape, fortran, dtype = fmt.read_array_header_1_0(member)
    elif version in ((2, 0), (3, 0)):
        shape, fortran, dtype = fmt.read_array_header_2_0(member)
    else:  # pragma: no cover - read_magic refuses other versions
        raise ModelFormatError(path, f"array {name!r}: unknown .npy version {version}")
    if dtype.hasobject or dtype.kind not in "biufc":
        raise ModelFormatError(path, f"array {name!r}: dtype {dtype} (numbers or booleans only)")
    count = math.prod(shape)
    if count * dtype.itemsize > size:
        raise ModelFormatError(
            path, f"array {name!r}: shape {shape} does not fit its {size} bytes (damaged)"
        )
    member.seek(0)
    return fmt.read_array(member, allow_pickle=False)


def _check_states(path, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Every estimator state at the top of ``header`` restores (and is then discarded)."""
    from markovmotion.state import restore_estimator

    for key, value in header.items():
        if isinstance(value, dict) and "class" in value and "learnt" in value:
            try:
                restore_estimator(value, arrays, key)
            except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
                raise ModelFormatError(path, f"damaged model: {exc}") from None
            except RecursionError:
                raise ModelFormatError(path, f"damaged model: {key} nests too deeply") from None

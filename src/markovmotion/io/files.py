"""File plumbing shared by every reader and writer: gzip by suffix, atomic writes."""

from __future__ import annotations

import gzip
import os
import secrets
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from markovmotion.errors import MotionFormatError


def is_gzip(path: str | os.PathLike[str]) -> bool:
    return str(path).endswith(".gz")


def base_suffix(path: str | os.PathLike[str]) -> str:
    """The format suffix, ignoring a trailing ``.gz`` (``walk.bvh.gz`` -> ``.bvh``)."""
    p = Path(path)
    if p.suffix == ".gz":
        p = p.with_suffix("")
    return p.suffix.lower()


def read_text(path: str | os.PathLike[str]) -> str:
    """The whole text of ``path``, decompressed if it ends in ``.gz``.

    Raises :class:`MotionFormatError` for a missing, unreadable, binary or
    truncated compressed file.
    """
    try:
        if is_gzip(path):
            with gzip.open(path, "rb") as fh:
                raw = fh.read()
        else:
            raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise MotionFormatError(path, "no such file") from None
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise MotionFormatError(path, f"cannot read file ({exc})") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        try:
            return raw.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes any byte
            raise MotionFormatError(path, "not a text file") from None


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO]:
    """Write ``path`` through a temporary file in the same folder, renamed on success.

    A failure part-way leaves any previous file untouched and no partial file behind.
    Paths ending in ``.gz`` are gzip-compressed (text or binary as ``mode`` says).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:  # name the output, not the folder or temporary file that failed
        if isinstance(exc, FileExistsError):
            problem = f"cannot write: {exc.filename} is a file, not a folder"
        else:
            problem = f"cannot write into the folder {path.parent} ({exc.strerror})"
        raise OSError(exc.errno, problem, str(path)) from None
    try:
        with os.fdopen(fd, "wb") as raw:
            if is_gzip(path):
                with gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as gz:
                    yield gz if "b" in mode else _TextOver(gz)
            elif "b" in mode:
                yield raw
            else:
                yield _TextOver(raw)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A fresh name with ``path``'s suffix in its folder, renamed to ``path`` on success.

    For writers that open the file themselves (ffmpeg); they create it with the
    usual permissions. On failure nothing is left behind.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class _TextOver:
    """Minimal text writer over a binary handle (UTF-8)."""

    def __init__(self, raw: IO[bytes]):
        self._raw = raw

    def write(self, text: str) -> int:
        return self._raw.write(text.encode("utf-8"))

"""File plumbing shared by every reader and writer: gzip by suffix, atomic writes."""

from __future__ import annotations

import atexit
import errno
import gzip
import os
import secrets
import signal
import stat
import tempfile
import threading
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from markovmotion.errors import MotionFormatError
from markovmotion.limits import MAX_BYTES, max_bytes, megabytes


def is_gzip(path: str | os.PathLike[str]) -> bool:
    return str(path).endswith(".gz")


def base_suffix(path: str | os.PathLike[str]) -> str:
    """The format suffix, ignoring a trailing ``.gz`` (``walk.bvh.gz`` -> ``.bvh``)."""
    p = Path(path)
    if p.suffix == ".gz":
        p = p.with_suffix("")
    return p.suffix.lower()


def open_regular(path: str | os.PathLike[str]) -> IO[bytes]:
    """``path`` opened for binary reading if it is a regular file (links followed).

    FIFOs, devices (``/dev/zero``, ``/dev/urandom`` or links to them), sockets,
    folders and symbolic-link loops are refused by name with
    :class:`MotionFormatError`, without blocking on a FIFO.
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise MotionFormatError(path, "no such file") from None
    except IsADirectoryError:
        raise MotionFormatError(path, "is a folder, not a file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise MotionFormatError(path, "symbolic link loop") from None
        raise MotionFormatError(path, f"cannot read file ({exc.strerror or exc})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise MotionFormatError(path, f"is {_kind(mode)}, not a regular file")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a file"


def read_bytes(path: str | os.PathLike[str], limit: int | None = None) -> bytes:
    """The bytes of regular file ``path``, decompressed if it ends in ``.gz``, at most ``limit``.

    ``limit`` defaults to :data:`markovmotion.limits.MAX_BYTES`; a larger file, or
    a ``.gz`` that decompresses to more, is refused after reading at most
    ``limit`` bytes (a gzip bomb is never inflated whole).
    """
    cap = max_bytes() if limit is None else int(limit)
    too_big = f"more than {megabytes(cap)} (limit {MAX_BYTES.env})"
    with open_regular(path) as fh:
        try:
            if not is_gzip(path):
                if os.fstat(fh.fileno()).st_size > cap:
                    raise MotionFormatError(path, f"the file is {too_big}")
                return fh.read(cap + 1)
            chunks: list[bytes] = []
            total = 0
            with gzip.GzipFile(fileobj=fh, mode="rb") as gz:
                while chunk := gz.read(min(1 << 20, cap + 1 - total)):
                    total += len(chunk)
                    if total > cap:
                        raise MotionFormatError(path, f"decompresses to {too_big}")
                    chunks.append(chunk)
            return b"".join(chunks)
        except (OSError, EOFError, zlib.error) as exc:
            raise MotionFormatError(path, f"cannot read file ({exc})") from None


def read_text(path: str | os.PathLike[str]) -> str:
    """The whole text of ``path``, decompressed if it ends in ``.gz``.

    Raises :class:`MotionFormatError` for a missing, unreadable, binary or
    truncated compressed file, one that is not a regular file, or one larger
    than :data:`markovmotion.limits.MAX_BYTES` (after decompression).
    """
    raw = read_bytes(path)
    try:
        return raw.decode("utf-8-sig")  # a byte order mark (Excel's "CSV UTF-8") dropped
    except UnicodeDecodeError:
        try:
            return raw.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes any byte
            raise MotionFormatError(path, "not a text file") from None


def _not_a_folder(path: Path) -> None:
    """Raise an :class:`OSError` naming the output ``path`` when it is an existing folder
    (the rename had failed naming the temporary file: ".out.mp4.1d07fb674826.tmp.mp4: Is a
    directory")."""
    if path.is_dir():
        raise OSError(errno.EISDIR, "is a folder", str(path))


def _cannot_write(path: Path, exc: OSError) -> OSError:
    """The error of an output ``path`` whose folder could not be made or take a new file:
    naming the output, not the folder or temporary file that failed."""
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        problem = f"cannot write: {exc.filename} is a file, not a folder"
    else:
        problem = f"cannot write into the folder {path.parent} ({exc.strerror})"
    return OSError(exc.errno, problem, str(path))


def check_writable(path: str | os.PathLike[str]) -> None:
    """Raise the :class:`OSError` writing ``path`` would raise (one line naming it: a folder,
    a file where a folder above it should be, a folder that takes no new file), before the
    work that makes what goes there: a file is made and removed in the nearest folder of
    ``path`` that exists (what the writers do; permissions alone do not say, root is
    refused by /sys and /proc all the same). An unwritable ``--out`` had been found after
    all the tracking."""
    path = Path(path)
    _not_a_folder(path)
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        if not folder.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(folder))
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    os.close(fd)
    os.unlink(tmp)


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO]:
    """Write ``path`` through a temporary file in the same folder, renamed on success.

    A failure part-way leaves any previous file untouched and no partial file behind.
    Paths ending in ``.gz`` are gzip-compressed (text or binary as ``mode`` says).
    """
    path = Path(path)
    _not_a_folder(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    _live(tmp)
    try:
        with os.fdopen(fd, "wb") as raw:
            if is_gzip(path):
                with gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as gz:
                    yield gz if "b" in mode else _TextOver(gz)
            elif "b" in mode:
                yield raw
            else:
                yield _TextOver(raw)
            raw.flush()
            os.fsync(raw.fileno())  # the data is on disk before the name points at it
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        _done(tmp)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A fresh name with ``path``'s suffix in its folder, renamed to ``path`` on success.

    For writers that open the file themselves (ffmpeg); they create it with the
    usual permissions. On failure nothing is left behind.
    """
    path = Path(path)
    _not_a_folder(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp{path.suffix}")
    _live(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        _done(tmp)


# Temporary outputs being written, removed on every exit path: normal exit and
# exceptions (above), interpreter exit (atexit) and SIGTERM/SIGHUP (handler below;
# SIGINT arrives as KeyboardInterrupt and takes the exception path).
_LIVE: set[str] = set()
_LIVE_LOCK = threading.Lock()
_HANDLED: set[int] = set()


def _live(tmp: str | os.PathLike[str]) -> None:
    with _LIVE_LOCK:
        _LIVE.add(os.fspath(tmp))
    _install_handlers()


def _done(tmp: str | os.PathLike[str]) -> None:
    with _LIVE_LOCK:
        _LIVE.discard(os.fspath(tmp))


def remove_live_temporaries() -> None:
    """Delete every temporary output still being written (atexit and signal handlers)."""
    with _LIVE_LOCK:
        names = list(_LIVE)
        _LIVE.clear()
    for name in names:
        try:
            os.unlink(name)
        except OSError:
            pass


def _on_signal(signum: int, frame) -> None:
    """SIGTERM/SIGHUP: remove the temporary outputs, then unwind as an exit (status
    128 + signal), so that ``finally`` blocks run and child processes (ffmpeg) are stopped."""
    remove_live_temporaries()
    raise SystemExit(128 + signum)


def _install_handlers() -> None:
    """Once per signal, in the main thread, and only where no one else handles it."""
    if threading.current_thread() is not threading.main_thread():
        return
    if not _HANDLED:
        atexit.register(remove_live_temporaries)
    for name in ("SIGTERM", "SIGHUP"):
        signum = getattr(signal, name, None)
        if signum is None or signum in _HANDLED:
            continue
        _HANDLED.add(signum)
        try:
            if signal.getsignal(signum) == signal.SIG_DFL:
                signal.signal(signum, _on_signal)
        except (ValueError, OSError):  # pragma: no cover - not the main interpreter thread
            pass


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

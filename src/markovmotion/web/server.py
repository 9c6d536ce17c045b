"""Running the app with uvicorn: in a background thread (tests, benchmarks, notebooks), or
in worker processes sharing one listening socket (``serve --workers N``).

A live session runs its partner in the server's interpreter; one process is one core. With
``workers`` processes each connection (a page, a live session) is taken by one of them,
so live sessions spread over the cores. Each worker builds its own app from the same
options (:func:`markovmotion.web.create_app`); the evaluation answers go to the one
SQLite file, whose writes are serialised by SQLite's lock (``BEGIN IMMEDIATE``).
"""

from __future__ import annotations

import errno
import logging
import multiprocessing
import os
import secrets
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import uvicorn
from fastapi import FastAPI

from markovmotion.web.live import DROP_LATE


class PortInUseError(OSError):
    """The address cannot be listened on (port taken, address not local, no permission)."""


def listen(host: str, port: int, workers: int = 1) -> socket.socket:
    """A socket bound to ``host:port`` (IPv4 or IPv6) and listening, before anything is
    printed; :class:`PortInUseError` with one line if that fails.

    For ``workers`` > 1 processes on a system with ``SO_REUSEPORT``, the socket is bound
    (the port is ours) but not listening: each worker listens on its own socket on the
    same port (:func:`start_workers`) and the kernel spreads the connections over them.
    One listening socket shared by all would let the first worker to wake take all of
    40 sessions opened at once (seen: one worker at 100 % CPU, the other idle)."""
    return _bind(
        host,
        port,
        reuse_port=workers > 1 and _REUSE_PORT,
        listening=not (workers > 1 and _REUSE_PORT),
    )


_REUSE_PORT = hasattr(socket, "SO_REUSEPORT")


def _bind(host: str, port: int, reuse_port: bool, listening: bool) -> socket.socket:
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        # IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY on accepted connections only when the
        # listening socket names its protocol; without it every small reply waits ~40 ms.
        sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    except OSError as exc:
        raise PortInUseError(f"cannot listen on {host}: {exc.strerror or exc}") from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if reuse_port:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.bind((host, port))
        if listening:
            sock.listen(2048)
    except (OSError, OverflowError, UnicodeError) as exc:
        sock.close()
        where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
            raise PortInUseError(f"{where} is already in use: choose another --port") from None
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise PortInUseError(f"cannot listen on {where}: {reason}") from None
    return sock


class _ClientUtf8(logging.Filter):
    """uvicorn's log of a WebSocket text message that is not UTF-8 (a client's fault: it
    closes that connection with 1007, invalid payload) as one line, not a traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, UnicodeDecodeError) and "UTF-8" in str(record.msg):
            record.msg, record.args = (
                "a WebSocket client sent a text message that is not UTF-8: closed (1007)",
                (),
            )
            record.exc_info = record.exc_text = None
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


_CLIENT_UTF8 = _ClientUtf8()


def uvicorn_server(app: FastAPI) -> uvicorn.Server:
    """The uvicorn server for ``app`` (``serve`` and :func:`running` alike).

    WebSocket compression (permessage-deflate) is off: the live page's frames are
    small and sent 30 times a second per session, and compressing each one took a
    third of the time spent sending it (py-spy under ``benchmarks/web_load.py``).
    A WebSocket text message that is not UTF-8 is logged in one line (:class:`_ClientUtf8`)."""
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", ws_per_message_deflate=False))
    logger = logging.getLogger("uvicorn.error")
    if _CLIENT_UTF8 not in logger.filters:
        logger.addFilter(_CLIENT_UTF8)
    return server


@contextmanager
def running(app: FastAPI, host: str = "127.0.0.1", port: int = 0) -> Iterator[str]:
    """Serve ``app`` on ``host:port`` (a free port if 0) while in the block; yields its base URL."""
    sock = listen(host, port)
    server = uvicorn_server(app)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("the web server did not start")
        time.sleep(0.02)
    try:
        yield f"http://{host}:{sock.getsockname()[1]}"
    finally:
        server.should_exit = True
        thread.join(timeout=10)
        sock.close()


@dataclass(frozen=True)
class AppOptions:
    """What each worker process builds its app from (:func:`markovmotion.web.create_app`);
    the partner as a model file, loaded in each worker."""

    library: Path
    db: Path | None = None
    stimuli: Path | None = None
    admin_token: str | None = None
    partner: Path | None = None
    allow_hosts: tuple[str, ...] = field(default_factory=tuple)
    #: The camera page's tracker (a module-level class or function: it goes to the workers).
    camera: Callable[..., object] | None = None
    #: Seconds a live session may fall behind its clock before it drops frames.
    drop_late: float = DROP_LATE

    def build(self) -> FastAPI:
        from markovmotion.web.app import create_app
        from markovmotion.web.live import model_partner

        return create_app(
            self.library,
            self.db,
            stimuli=self.stimuli,
            admin_token=self.admin_token,
            partner=model_partner(self.partner) if self.partner else None,
            allow_hosts=self.allow_hosts,
            camera=self.camera,
            drop_late=self.drop_late,
        )


def _worker(options: AppOptions, sock: socket.socket, ready) -> None:  # pragma: no cover - child
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops the workers
    if _REUSE_PORT and sock.getsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT):
        # the parent's socket holds the port; this worker listens on its own (see listen)
        host, port = sock.getsockname()[:2]
        sock = _bind(host, port, reuse_port=True, listening=True)
    server = uvicorn_server(options.build())

    def tell_when_started() -> None:
        while not server.started and not server.should_exit:
            time.sleep(0.02)
        ready.set()

    threading.Thread(target=tell_when_started, daemon=True).start()
    server.run(sockets=[sock])


def start_workers(
    options: AppOptions, sock: socket.socket, workers: int, timeout: float = 120
) -> list[multiprocessing.process.BaseProcess]:
    """``workers`` processes serving ``options``' app on ``sock``'s port (:func:`listen`
    with the same ``workers``), returned once all are serving; OSError (one line from
    ``serve``) if one dies first or ``timeout`` seconds pass."""
    spawn = multiprocessing.get_context("spawn")
    events = [spawn.Event() for _ in range(workers)]
    procs = [spawn.Process(target=_worker, args=(options, sock, ev), daemon=True) for ev in events]
    for p in procs:
        p.start()
    deadline = time.monotonic() + timeout
    for ev in events:
        while not ev.wait(0.1):
            if any(not p.is_alive() for p in procs) or time.monotonic() > deadline:
                stop_workers(procs)
                raise OSError("the web server's workers did not start (see their output above)")
    return procs


def stop_workers(procs: list[multiprocessing.process.BaseProcess], timeout: float = 10) -> None:
    """Ask the workers to finish (SIGTERM: uvicorn closes its connections), then kill any
    that do not within ``timeout`` seconds."""
    for p in procs:
        if p.is_alive() and p.pid is not None:
            os.kill(p.pid, signal.SIGTERM)
    deadline = time.monotonic() + timeout
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            p.kill()
            p.join()


@contextmanager
def running_workers(
    options: AppOptions, workers: int = 2, host: str = "127.0.0.1", port: int = 0
) -> Iterator[str]:
    """:func:`running` with ``workers`` processes (module docstring); yields the base URL."""
    sock = listen(host, port, workers)
    if options.admin_token is None:  # one token for every worker
        options = replace(options, admin_token=secrets.token_urlsafe(18))
    procs = start_workers(options, sock, workers)
    try:
        yield f"http://{host}:{sock.getsockname()[1]}"
    finally:
        stop_workers(procs)
        sock.close()

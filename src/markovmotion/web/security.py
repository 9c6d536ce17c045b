"""Request guards of the web server, applied to every request in one place.

* **Host allow-list** (DNS rebinding): the ``Host`` header must name
  ``127.0.0.1``, ``localhost``, ``::1``, the bound address or a name given with
  ``serve --allow-host``; anything else gets 400.
* **Origin check** (cross-site requests): a state-changing request (POST, PUT,
  PATCH, DELETE) or a WebSocket whose ``Origin`` header is present must come
  from an allowed host; anything else gets 403 (a WebSocket is closed, 1008).
* **Bounded bodies**: a body is counted as it arrives and refused with 413 as
  soon as it passes its limit (uploads: the upload limit; any other request:
  :data:`MAX_BODY`), a declared ``Content-Length`` above it before reading.
* **Security headers** on every HTTP response: :data:`SECURITY_HEADERS`.
"""

from __future__ import annotations

from collections.abc import Iterable
from urllib.parse import urlsplit

from fastapi import HTTPException
from starlette.datastructures import Headers
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

DEFAULT_HOSTS = ("127.0.0.1", "localhost", "::1")
"""Host names every server answers to (plus the bound address and ``--allow-host``)."""
STATE_CHANGING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
MAX_BODY = 64 * 1024
"""Largest body of a request other than an upload: JSON answers are a few bytes (a comment
of 2,000 astral characters, each escaped as two ``\\uXXXX``, 24 KB). Parsing and validating
a JSON body happens on the event loop: a hostile 1 MiB body (100,000 unknown fields,
350,000 empty arrays) held it 0.75 and 0.48 s, a 64 KiB one at most 14 ms."""
UPLOAD_SLACK = 64 * 1024
"""Room for the multipart envelope around an uploaded file."""
CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; font-src 'self'; object-src 'none'; base-uri 'none'; "
    "form-action 'self'; frame-ancestors 'none'"
)
SECURITY_HEADERS = (
    ("content-security-policy", CSP),
    ("x-frame-options", "DENY"),
    ("x-content-type-options", "nosniff"),
    ("referrer-policy", "no-referrer"),
)


def host_name(value: str) -> str | None:
    """The host of a ``Host`` header (lower case, no port, no brackets); None if malformed."""
    value = value.strip().lower()
    if value.startswith("["):
        end = value.find("]")
        host, rest = value[1:end], value[end + 1 :]
        if end < 0 or (rest and not (rest[:1] == ":" and rest[1:].isdigit())):
            return None
    elif value.count(":") == 1:
        host, _, port = value.partition(":")
        if not port.isdigit():
            return None
    else:
        host = value
    host = host.rstrip(".")
    return host or None


def normalise_hosts(hosts: Iterable[str]) -> frozenset[str]:
    """Allowed host names as :func:`host_name` gives them (``[::1]`` -> ``::1``)."""
    out = set(DEFAULT_HOSTS)
    for h in hosts:
        h = h.strip().lower()
        if h.startswith("[") and h.endswith("]"):
            h = h[1:-1]
        if h:
            out.add(h.rstrip("."))
    return frozenset(out)


class Guard:
    """ASGI middleware applying the checks of this module (see the module docstring)."""

    def __init__(
        self, app: ASGIApp, hosts: Iterable[str] = (), upload_path: str = "", upload_limit=None
    ):
        self.app = app
        self.hosts = normalise_hosts(hosts)
        self.upload_path = upload_path
        self.upload_limit = upload_limit

    def _problem(self, scope: Scope, headers: Headers) -> tuple[int, str] | None:
        raw = headers.get("host")
        host = host_name(raw) if raw is not None else None
        if host is None or host not in self.hosts:
            return 400, "this server does not answer to that Host (see serve --allow-host)"
        origin = headers.get("origin")
        if origin is not None and (
            scope["type"] == "websocket" or scope["method"] in STATE_CHANGING
        ):
            try:
                parts = urlsplit(origin.strip())
                allowed = parts.scheme in ("http", "https") and (parts.hostname or "") in self.hosts
            except ValueError:
                allowed = False
            if not allowed:
                return 403, "cross-origin request refused (Origin is not an allowed host)"
        return None

    def _body_limit(self, scope: Scope) -> int:
        if self.upload_path and scope["path"] == self.upload_path and self.upload_limit:
            return int(self.upload_limit()) + UPLOAD_SLACK
        return MAX_BODY

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        problem = self._problem(scope, headers)
        if scope["type"] == "websocket":
            if problem is not None:
                await send({"type": "websocket.close", "code": 1008, "reason": problem[1]})
                return
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                present = {k.lower() for k, _ in message.get("headers", [])}
                extra = [
                    (k.encode(), v.encode())
                    for k, v in SECURITY_HEADERS
                    if k.encode() not in present
                ]
                message["headers"] = [*message.get("headers", []), *extra]
            await send(message)

        limit = self._body_limit(scope)
        declared = headers.get("content-length")
        if problem is None and declared is not None:
            if not declared.strip().isdigit():
                problem = 400, "Content-Length is not a number"
            elif int(declared) > limit:
                problem = 413, f"request body larger than {limit} bytes"
        if problem is not None:
            status, detail = problem
            await JSONResponse({"detail": detail}, status)(scope, receive, send_with_headers)
            return

        seen = 0

        async def bounded_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise HTTPException(413, f"request body larger than {limit} bytes")
            return message

        await self.app(scope, bounded_receive, send_with_headers)

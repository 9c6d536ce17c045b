"""The web application: viewer, live partner, perceptual evaluation and its results.

``create_app`` builds a FastAPI app over a :class:`MotionLibrary` folder and an
evaluation database; ``markovmotion serve`` runs it with uvicorn. Pages are
plain HTML with their own JavaScript (no library, nothing loaded from a
network): see ``pages/`` and ``static/``.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import tempfile
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, BinaryIO, Literal

from fastapi import FastAPI, HTTPException, Request, WebSocket
from fastapi import Path as PathParam
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser

from markovmotion.errors import MarkovMotionError
from markovmotion.evaluate.interaction import (
    INTERACTION,
    INTERACTION_MANIFEST,
    MAX_COMMENT,
    QUESTION,
    read_interaction_manifest,
    summarise_interaction,
)
from markovmotion.evaluate.interaction import choice_labels as interaction_choices
from markovmotion.evaluate.perceptual import (
    TESTS,
    answers_csv,
    choice_labels,
    choices,
    summarise,
)
from markovmotion.evaluate.stimuli import MANIFEST, read_manifest
from markovmotion.evaluate.store import EvaluationError, EvaluationStore
from markovmotion.state import json_text
from markovmotion.viz.point_light import point_lights
from markovmotion.web.camera import TrackerFactory, camera_session
from markovmotion.web.library import (
    LibraryPathError,
    MotionLibrary,
    UploadBusyError,
    UploadTooLargeError,
    markers_payload,
    max_upload_bytes,
    motion_json,
    read_upload,
    shown,
)
from markovmotion.web.live import DROP_LATE, PartnerFactory, live_session
from markovmotion.web.security import UPLOAD_SLACK, Guard

HERE = Path(__file__).parent
PAGES_DIR = HERE / "pages"
QUESTIONS = {
    "naturalness": "Does this walk look real or synthetic?",
    "recognition": "In which style is this person walking?",
    "resemblance": "How much do these two walks resemble each other?",
}


class Answer(BaseModel):
    """An answer's JSON body, strictly: a string answer (one of the test's choices), and in
    the interaction study a ``true``/``false`` ``unusual`` and a string ``comment``; no
    other field, nothing converted (``"1"`` or ``1`` is not ``true``)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    answer: str
    unusual: bool = False  # the interaction study: noticed something strange or unusual
    comment: str = Field("", max_length=MAX_COMMENT)


Study = Literal["gait", "interaction"]


class StudyChoice(BaseModel):
    """``POST /api/evaluation``'s optional JSON body: the study, as the query's ``study``."""

    model_config = ConfigDict(extra="forbid", strict=True)
    study: Study | None = None


Position = Annotated[int, PathParam(ge=0, le=1_000_000)]
"""An item's position in a test (bounded: SQLite integers are 64-bit)."""


MAX_DIGITS = 20
"""Longest integer, in digits, a JSON body may hold (no field takes a number; 64-bit
integers have at most 19 digits, and Python refuses to convert more than 4300)."""

_JSON_KINDS = {
    type(None): "null",
    bool: "true or false",
    int: "a number",
    float: "a number",
    str: "a string",
    list: "an array",
    dict: "an object",
}


def _json_kind(value: object) -> str:
    """What a parsed JSON ``value`` is, in JSON's words ("an array", "a string", ...)."""
    return _JSON_KINDS.get(type(value), "bytes" if isinstance(value, bytes) else "a value")


class _Refused:
    """A value :func:`json_body` does not take, left in the parsed tree to be found with its
    path (the JSON parser's hooks do not know where they are)."""

    def __init__(self, problem: str):
        self.problem = problem


def _first_refused(value: dict) -> str:
    """``path: problem`` of the first :class:`_Refused` in ``value`` (``comment``, ``a.0.b``):
    depth first with an iterator per container, so nothing is copied."""
    stack: list[tuple[str, Iterator[tuple[Any, Any]]]] = [("", iter(value.items()))]
    while stack:
        parent, items = stack[-1]
        for key, v in items:
            if isinstance(v, (_Refused, dict, list)):
                path = f"{parent}.{key}" if parent else str(key)
                if isinstance(v, _Refused):
                    return f"{shown(path, 60)}: {v.problem}"
                stack.append((path, iter(v.items()) if isinstance(v, dict) else enumerate(v)))
                break
        else:
            stack.pop()
    return "body: refused"  # not reached: called when a hook refused a value


def json_body(body: bytes) -> Any:
    """A request's JSON body, strictly (RFC 8259): UTF-8, a JSON object, no ``NaN`` or
    ``Infinity``, finite numbers, integers of at most :data:`MAX_DIGITS` digits, no key given
    twice, nested less deep than the interpreter's recursion limit. Any other body raises
    :class:`json.JSONDecodeError` whose message is the one line to answer with, naming the
    field (FastAPI turns it into a :class:`RequestValidationError`: see :func:`_one_line`)."""
    refused: list[_Refused] = []  # the first refusal (the others as cheap as can be)

    def refuse(problem: str) -> _Refused:
        if not refused:
            refused.append(_Refused(problem))
        return refused[0]

    def number(text: str) -> int | _Refused:
        digits = len(text.lstrip("-"))
        if digits > MAX_DIGITS:
            return refuse(f"a number of {digits} digits (at most {MAX_DIGITS})")
        return int(text)

    def real(text: str) -> float | _Refused:
        value = float(text)
        return value if math.isfinite(value) else refuse(f"{text[:20]} is too large a number")

    def constant(name: str) -> _Refused:
        return refuse(f"{name} is not JSON (JSON numbers are finite)")

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in items:
            out[key] = refuse("given twice") if key in out else value
        return out

    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise json.JSONDecodeError(
            f"body: not UTF-8 text (byte {exc.start})", repr(body[:80]), 0
        ) from None
    try:
        value = json.loads(
            text, parse_int=number, parse_float=real, parse_constant=constant,
            object_pairs_hook=pairs,
        )  # fmt: skip
    except json.JSONDecodeError as exc:
        raise json.JSONDecodeError(f"body: not JSON ({exc})", text, exc.pos) from None
    except RecursionError:
        raise json.JSONDecodeError("body: JSON nested too deeply", text, 0) from None
    if not isinstance(value, dict):
        raise json.JSONDecodeError(
            f"body: expected a JSON object, found {_json_kind(value)}", text, 0
        )
    if refused:
        raise json.JSONDecodeError(_first_refused(value), text, 0)
    return value


class _JSONRequest(Request):
    """A request whose JSON body is read by :func:`json_body`."""

    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            self._json = json_body(await self.body())
        return self._json


class _JSONRoute(APIRoute):
    """Every route of the app: its JSON body read by :func:`json_body` (FastAPI's own reading
    answers a body too deep or with a 5,000-digit number with a generic 400)."""

    def get_route_handler(self) -> Callable:
        handler = super().get_route_handler()

        async def strict_json(request: Request) -> Response:
            return await handler(_JSONRequest(request.scope, request.receive))

        return strict_json


def _one_line(exc: RequestValidationError) -> str:
    """The first problem of a request that does not validate, as one line naming the field
    (``comment``, ``query.study``, ``path.position``) or the body."""
    errors = exc.errors()
    if not errors:
        return "invalid request"
    first = errors[0]
    loc = tuple(first.get("loc", ()))
    kind, msg = str(first.get("type", "")), str(first.get("msg", "invalid"))
    if kind == "json_invalid":  # json_body's line, naming the field or the body already
        return shown(str(first.get("ctx", {}).get("error", "body: not JSON")), 200)
    where = shown(".".join(str(part) for part in loc if part != "body"), 60)
    where = where or ("body" if loc[:1] == ("body",) else "request")
    value = first.get("input")
    if loc == ("body",) and kind == "missing":
        msg = "missing (send a JSON object, Content-Type: application/json)"
    elif loc == ("body",) and isinstance(value, bytes):  # not sent as JSON: FastAPI left it
        msg = "not sent as JSON (send a JSON object, Content-Type: application/json)"
    elif kind == "extra_forbidden":
        msg = "not a field of this request"
    elif kind == "string_unicode":
        msg = "not Unicode text (a lone surrogate escape)"
    elif loc[:1] == ("body",) and kind.endswith("_type"):
        msg = f"{msg}, found {_json_kind(value)}"
    return shown(f"{where}: {msg}", 200)


async def _bounded(stream: AsyncIterator[bytes], limit: int) -> AsyncIterator[bytes]:
    """``stream`` as it arrives, refused with 413 as soon as it passes ``limit`` bytes."""
    seen = 0
    async for chunk in stream:
        seen += len(chunk)
        if seen > limit:
            raise HTTPException(413, f"upload larger than {limit // 2**20} MiB")
        yield chunk


NAV = (
    ("/viewer", "Viewer"),
    ("/live", "Live partner"),
    ("/camera", "Camera partner"),
    ("/evaluation", "Evaluation"),
)
PAGES = {
    "/": ("index", "Home"),
    "/viewer": ("viewer", "Viewer"),
    "/live": ("live", "Live partner"),
    "/camera": ("camera", "Camera partner"),
    "/evaluation": ("evaluation-start", "Evaluation"),
}
"""Pages without parameters: path -> (file in ``pages/``, title)."""


def _page(name: str, title: str, here: str = "", status: int = 200) -> HTMLResponse:
    """``pages/<name>.html`` inside the common layout (head, navigation bar)."""
    nav = "".join(
        f'<a href="{href}" class="here">{label}</a>'
        if href == here
        else f'<a href="{href}">{label}</a>'
        for href, label in NAV
    )
    html = (PAGES_DIR / "layout.html").read_text(encoding="utf-8")
    main = (PAGES_DIR / f"{name}.html").read_text(encoding="utf-8")
    html = html.replace("{{title}}", title).replace("{{nav}}", nav).replace("{{main}}", main)
    return HTMLResponse(html, status_code=status)


def create_app(
    library: str | os.PathLike[str] | MotionLibrary,
    db: str | os.PathLike[str] | None = None,
    *,
    stimuli: str | os.PathLike[str] | None = None,
    admin_token: str | None = None,
    partner: PartnerFactory | None = None,
    allow_hosts: Iterable[str] = (),
    camera: TrackerFactory | None = None,
    drop_late: float = DROP_LATE,
) -> FastAPI:
    """The app serving ``library``; the evaluation runs when a stimuli folder is given
    (default: ``library/stimuli`` if it holds a manifest) and stores answers in ``db``.
    The folder's ``manifest.csv`` gives the gait study, its ``interaction.json`` the
    interaction observer study (:mod:`markovmotion.evaluate.interaction`); either or both.

    ``admin_token`` guards the results (a random one if omitted: read it from
    ``app.state.admin_token``); ``partner`` builds the live partner of a session;
    ``camera`` the camera page's tracker (:mod:`markovmotion.web.camera`; ``serve`` gives
    :class:`markovmotion.video.webcam.WebcamTracker`).
    The server answers to 127.0.0.1, localhost and ::1 and to ``allow_hosts``
    (the bound address, ``serve --allow-host``): see :mod:`markovmotion.web.security`.
    ``drop_late`` (seconds, ``math.inf`` for never): when a live session behind its clock
    drops frames (:func:`markovmotion.web.live.live_session`).
    """
    lib = library if isinstance(library, MotionLibrary) else MotionLibrary(library)
    if stimuli is None and any(
        (lib.root / "stimuli" / name).is_file() for name in (MANIFEST, INTERACTION_MANIFEST)
    ):
        stimuli = lib.root / "stimuli"
    store = stim_lib = None
    offered: list[str] = []  # the studies of the stimuli folder (the database may hold more)
    if stimuli is not None:
        stim_lib = MotionLibrary(stimuli, anonymous=True)
        clips = None
        if (Path(stimuli) / INTERACTION_MANIFEST).is_file():
            clips = read_interaction_manifest(stimuli)
        gait = (
            read_manifest(stimuli)
            if clips is None or (Path(stimuli) / MANIFEST).is_file()
            else None
        )
        store = EvaluationStore(db or "results.sqlite", gait, clips)
        offered = [s for s, given in (("gait", gait), ("interaction", clips)) if given is not None]
    elif db is not None and Path(db).is_file():
        store = EvaluationStore(db)

    app = FastAPI(title="markovmotion", docs_url=None, redoc_url=None)
    app.router.route_class = _JSONRoute  # before any route is added
    app.state.admin_token = admin_token or secrets.token_urlsafe(18)
    app.state.store = store
    app.state.library = lib
    app.state.allow_hosts = tuple(allow_hosts)
    app.add_middleware(
        Guard,
        hosts=app.state.allow_hosts,
        upload_path="/api/upload",
        upload_limit=max_upload_bytes,
    )
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")

    @app.exception_handler(RequestValidationError)
    async def invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"detail": _one_line(exc)}, 422)

    @app.exception_handler(MarkovMotionError)
    async def library_error(request: Request, exc: MarkovMotionError) -> JSONResponse:
        return JSONResponse({"detail": shown(lib.public(str(exc)), 300)}, 422)

    def need_store() -> EvaluationStore:
        if store is None or stim_lib is None:
            raise HTTPException(503, "no evaluation on this server: start it with --stimuli DIR")
        return store

    def need_evaluator(token: str) -> EvaluationStore:
        s = need_store()
        if not s.exists(token):
            raise HTTPException(404, "unknown evaluator token")
        return s

    def need_admin(token: str | None) -> EvaluationStore:
        if not token or not secrets.compare_digest(
            token.encode("utf-8", "replace"), app.state.admin_token.encode()
        ):
            raise HTTPException(403, "the results need the admin token printed at start-up")
        if store is None:
            raise HTTPException(503, "no evaluation database on this server")
        return store

    # ------------------------------------------------------------ pages
    for path, (name, title) in PAGES.items():
        if path != "/evaluation":
            app.get(path, response_class=HTMLResponse, name=name)(
                lambda name=name, title=title, path=path: _page(name, title, path)
            )

    @app.get("/evaluation", response_class=HTMLResponse)
    def evaluation_start() -> HTMLResponse:
        """The studies this server runs; without stimuli, the first page says there are none
        (and how to start a server with some) instead of offering a Begin that fails."""
        if not offered:
            return _page("no-evaluation", "No evaluation", "/evaluation", status=503)
        return _page(*PAGES["/evaluation"], "/evaluation")

    @app.get("/evaluation/{token}", response_class=HTMLResponse)
    def evaluation(token: str) -> HTMLResponse:
        if store is None or not store.exists(token):
            return _page("not-found", "Unknown link", status=404)
        if store.study(token) == "interaction":
            return _page("interaction", "Evaluation", "/evaluation")
        return _page("evaluation", "Evaluation", "/evaluation")

    @app.get("/results", response_class=HTMLResponse)
    def results(token: str | None = None) -> HTMLResponse:
        try:
            need_admin(token)
        except HTTPException as exc:
            if exc.status_code == 403:
                return _page("forbidden", "Forbidden", status=403)
            return _page("no-evaluation", "No evaluation", status=exc.status_code)
        return _page("results", "Results")

    # ------------------------------------------------------------ motions
    @app.get("/api/motions")
    def motions() -> dict:
        # partner_reads: "skeleton" (a C3D file is refused), "markers", or "any" (a factory
        # given in code that does not say)
        reads = getattr(partner, "reads", "any")
        return {"files": lib.files(), "partner": partner is not None, "partner_reads": reads}

    @app.get("/api/motion")
    def motion(path: str) -> Response:
        try:
            return Response(lib.json(path), media_type="application/json")
        except LibraryPathError as exc:
            raise HTTPException(404, shown(lib.public(str(exc)), 300)) from None
        except MarkovMotionError as exc:
            raise HTTPException(422, shown(lib.public(str(exc)), 300)) from None
        except (RecursionError, MemoryError, ValueError) as exc:
            problem = "nested too deeply" if isinstance(exc, RecursionError) else "cannot be read"
            raise HTTPException(422, f"{shown(path)}: {problem}") from None

    @app.post("/api/upload")
    async def upload(request: Request, name: str = "upload.bvh") -> Response:
        """A BVH (or .bvh.gz) as the form field ``file`` or as the raw body (``?name=``),
        streamed to disk with a running count: 413 past the upload limit, counted again
        after decompression; any problem reading it is a 422 with one line."""
        limit = max_upload_bytes()
        kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
        if kind in ("application/json", "application/x-www-form-urlencoded"):
            raise HTTPException(  # a motion file is neither: say how to send one
                415, f"{kind}: send the BVH file as multipart/form-data (field \"file\") or "
                "as the raw body",
            )  # fmt: skip
        stream = _bounded(request.stream(), limit + UPLOAD_SLACK)
        form = None
        try:
            if kind == "multipart/form-data":
                parser = MultiPartParser(request.headers, stream, max_files=1, max_fields=8)
                try:
                    form = await parser.parse()
                except MultiPartException as exc:
                    raise HTTPException(400, shown(str(exc.message), 200)) from None
                file = form.get("file")
                if not isinstance(file, UploadFile):
                    raise HTTPException(
                        422, 'no whole form field "file" (cut short?): send the BVH file as it'
                    )
                name, fh = file.filename or "upload.bvh", file.file
            else:
                fh = tempfile.SpooledTemporaryFile(max_size=1 << 20)
                async for chunk in stream:
                    fh.write(chunk)
                fh.seek(0)
            payload = await run_in_threadpool(_read_payload, name, fh)
        except UploadTooLargeError as exc:
            raise HTTPException(413, shown(str(exc), 300)) from None
        except UploadBusyError as exc:
            raise HTTPException(429, shown(str(exc), 300)) from None
        except MarkovMotionError as exc:
            raise HTTPException(422, shown(lib.public(str(exc)), 300)) from None
        finally:
            if form is not None:
                await form.close()
        return Response(payload, media_type="application/json")

    @app.websocket("/ws/live")
    async def live_ws(ws: WebSocket) -> None:
        await live_session(ws, lib, partner, drop_late)

    app.state.camera_sessions = []

    @app.websocket("/ws/camera")
    async def camera_ws(ws: WebSocket) -> None:
        await camera_session(ws, partner, camera, app.state.camera_sessions)

    # ------------------------------------------------------------ evaluation
    @app.get("/api/studies")
    def studies() -> dict:
        return {"studies": offered}

    @app.post("/api/evaluation")
    def new_evaluator(study: Study | None = None, body: StudyChoice | None = None) -> dict:
        """A new evaluator's token; the study from the query or a JSON body (gait if neither)."""
        s = need_store()
        chosen = body.study if body is not None else None
        if chosen is not None and study is not None and chosen != study:
            raise HTTPException(422, f"study {study!r} in the query but {chosen!r} in the body")
        study = chosen or study or "gait"
        if study not in offered:
            raise HTTPException(404, f"no {study} study on this server")
        return {"token": s.create_evaluator(study=study)}

    @app.get("/api/evaluation/{token}")
    def evaluator_state(token: str) -> dict:
        s = need_evaluator(token)
        items = s.items(token)
        if s.study(token) == "interaction" and s.interaction is not None:
            return {
                "study": "interaction",
                "tests": [
                    {
                        "name": INTERACTION,
                        "question": QUESTION,
                        "choices": interaction_choices(s.interaction.labels),
                        "items": [
                            {
                                "position": i.position,
                                "answer": i.answer,
                                "unusual": i.unusual,
                                "comment": i.comment,
                            }
                            for i in items
                        ],
                    }
                ],
            }
        return {
            "study": "gait",
            "tests": [
                {
                    "name": test,
                    "question": QUESTIONS[test],
                    "choices": choice_labels(test, s.styles),
                    "items": [
                        {"position": i.position, "answer": i.answer, "pair": i.file_b is not None}
                        for i in items
                        if i.test == test
                    ],
                }
                for test in TESTS
            ],
        }

    @lru_cache(maxsize=64)
    def clip_json(file_a: str, file_b: str) -> bytes:
        """Both people of a clip as one point-light figure (anonymous), encoded."""
        cloud = point_lights([stim_lib.motion(file_a), stim_lib.motion(file_b)])
        return json.dumps(markers_payload(cloud), separators=(",", ":")).encode()

    @app.get("/api/evaluation/{token}/{test}/{position}/{side}")
    def stimulus(token: str, test: str, position: Position, side: Position) -> Response:
        s = need_evaluator(token)
        item = s.item(token, test, position)
        if test == INTERACTION:
            clip = s.interaction.clip(item.file) if item and s.interaction else None
            if clip is None or side != 0:
                raise HTTPException(404, "no such stimulus")
            try:
                return Response(clip_json(clip.file_a, clip.file_b), media_type="application/json")
            except LibraryPathError as exc:
                raise HTTPException(404, shown(stim_lib.public(str(exc)), 300)) from None
            except (RecursionError, MemoryError, ValueError):
                raise HTTPException(422, f"clip {shown(clip.id)}: cannot be read") from None
        files = (item.file, item.file_b) if item is not None else ()
        if side not in range(len(files)) or files[side] is None:
            raise HTTPException(404, "no such stimulus")
        try:
            return Response(stim_lib.json(files[side]), media_type="application/json")
        except LibraryPathError as exc:
            raise HTTPException(404, shown(stim_lib.public(str(exc)), 300)) from None

    @app.post("/api/evaluation/{token}/{test}/{position}")
    def answer(token: str, test: str, position: Position, body: Answer) -> dict:
        s = need_evaluator(token)
        if test in TESTS:  # a walk's answer is its choice alone
            given = sorted(body.model_fields_set - {"answer"})
            if given:
                raise HTTPException(422, f"{given[0]}: only the interaction study takes it")
            offered = choices(test, s.styles)
        else:
            offered = s.interaction.choices() if test == INTERACTION and s.interaction else None
        if offered is not None and body.answer not in offered:
            value = shown(repr(body.answer), 60)
            problem = f"{value} is not a choice of the {test} test ({', '.join(offered)})"
            raise HTTPException(422, shown(f"answer: {problem}", 200))
        try:
            s.answer(token, test, position, body.answer, body.unusual, body.comment)
        except EvaluationError as exc:
            raise HTTPException(422, shown(lib.public(str(exc)), 300)) from None
        return {"ok": True}

    # ------------------------------------------------------------ results
    @app.get("/api/results")
    def results_json(token: str | None = None) -> Response:
        s = need_admin(token)
        answered = s.answered()
        report = summarise([i for i in answered if i.test in TESTS], s.styles).to_dict()
        report["registered"] = s.count_evaluators()
        report["studies"] = s.studies()
        report["interaction"] = (
            summarise_interaction(answered, s.interaction.labels, s.interaction.clips)
            if s.interaction is not None
            else None
        )
        return Response(json_text(report), media_type="application/json")

    @app.get("/api/results.csv")
    def results_csv(token: str | None = None) -> Response:
        s = need_admin(token)
        return Response(
            answers_csv(s.answered()),
            media_type="text/csv",
            headers={"Content-Disposition": 'attachment; filename="answers.csv"'},
        )

    return app


def _read_payload(name: str, fh: BinaryIO) -> bytes:
    """The JSON of an uploaded BVH, encoded (in a worker thread: reading may take a while),
    by :func:`~markovmotion.web.library.motion_json`: a JSONResponse had encoded it in the
    event loop in one go (3 s for a 60 MB BVH, every live session stopped meanwhile)."""
    try:
        motion = read_upload(name, fh)
    finally:
        fh.close()
    return motion_json(motion)

"""The live virtual partner over a WebSocket: person A streamed at its frame rate, B answered.

Protocol (JSON text messages):

1. the page sends ``{"path": "walk.bvh"}`` (a library file: a skeleton's take, or a C3D
   file's markers for a partner of markers, their gaps filled) or
   ``{"bvh": "<file text>", "name": "mine.bvh"}`` (an upload), optionally
   with ``"loop": true`` to repeat A until the page stops;
2. the server answers ``{"type": "start", "fps", "frames", "parents_a",
   "parents_b", "lag"}`` or ``{"type": "error", "message"}`` and closes;
3. then, at A's frame rate (or the partner's, A resampled to it),
   ``{"type": "frame", "i", "a", "b", "latency_ms", "skipped"}``
   with frame ``i`` of the stream (counted on through loops), A's and B's
   joint positions (mm, flat) and the time the partner took for that frame;
   ``b`` is ``null`` while the partner's window fills. A session that falls
   behind its clock by more than :data:`DROP_LATE` (``serve --drop-late``; the clock
   starts when the first frame is sent, as a first step may load or compile) drops
   frames instead of
   sending a backlog: the frames whose successors are already due are given to
   the partner as dropped (:meth:`LivePartner.drop`, the online protocol's
   ``drop()``: ``skip()`` without B's answer) and not sent, so the next frame
   sent is the present one; ``skipped`` counts the frames dropped so far (``i``
   jumps over them);
4. ``{"type": "end", "frames", "skipped"}`` when A is over (frames sent, frames
   dropped). The page may send ``{"type": "stop"}``; anything else, or closing
   the tab, ends the session.
"""

from __future__ import annotations

import asyncio
import collections
import json
import os
import threading
import time
import weakref
from collections.abc import Callable
from functools import partial
from typing import ClassVar, Protocol

import numpy as np
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import MarkovMotionError, ModelFormatError
from markovmotion.models.base import KINDS, Model
from markovmotion.web.library import (
    MotionLibrary,
    display_parents,
    encoded_frames,
    figure_parents,
    positions_json,
    read_upload,
)

START_TIMEOUT = 30.0

DROP_LATE = 0.07
"""A live session that falls further behind its clock than this (seconds; two frames at
30 fps) drops the frames it is late with (:func:`live_session`); a jitter below it is
caught up with, frame by frame."""


class LivePartner(Protocol):
    """One session's online partner: A's frame in, B's pose out, frame by frame."""

    parents: list[int]
    """Parent of each of B's joints (-1: no bone), to draw B (see ``display_parents``)."""
    lag: int
    """How many frames B's answer trails A's (the partner's look-ahead)."""
    fps: float | None
    """The rate A must come at (A is resampled to it), or None for A's own."""

    def step(self, frame_a: Motion) -> np.ndarray | None:
        """One frame of A (a one-frame Motion) -> B's joint positions (J_B, 3) mm, or None."""
        ...

    def drop(self) -> None:
        """A frame of A dropped because the session fell behind (the online protocol's
        ``drop()``): the partner goes on without it; B's frame for it is not wanted."""
        ...


def _one_frame_steps(partner: LivePartner, motion: Motion) -> Callable[[int], np.ndarray | None]:
    """Frame ``i`` of ``motion`` to ``partner.step`` as a one-frame Motion."""
    return lambda i: partner.step(motion.trim(i, i + 1))


def stepper(partner: LivePartner, motion: Motion) -> Callable[[int], np.ndarray | None]:
    """How a session steps ``partner`` through frame ``i`` of A's ``motion``: the partner's
    own ``stepper(motion)`` where it has one (:meth:`ModelPartner.stepper`: A seen once,
    not frame by frame), else ``step`` of each one-frame Motion."""
    own = getattr(partner, "stepper", None)
    return own(motion) if own is not None else _one_frame_steps(partner, motion)


PartnerFactory = Callable[[Motion], LivePartner]
"""Builds a fresh partner for a session from person A's motion (raising a
:class:`MarkovMotionError` if it cannot answer that motion)."""


class ModelPartner:
    """A model's online partner (``model.partner()``, :mod:`markovmotion.models.online`) as a
    LivePartner: the dual HMM's windowed-Viterbi partner or the behaviour chain's CONDENSATION
    partner, one per session."""

    def __init__(self, model: Model, motion_a: Motion):
        check = getattr(model, "check_input", None)
        if check is not None:
            check(motion_a)
        self._model = model
        self._partner = model.partner()
        self.lag = int(self._partner.lag)
        self.fps = float(self._partner.fps)
        skeleton = self._partner.skeleton  # None: B comes as markers, drawn without bones
        # B's markers: the dual HMM's marker_names_b_, the chain's markers_ (both people's)
        names = getattr(model, "marker_names_b_", None) or getattr(model, "markers_", None) or ()
        # B's markers as a stick figure where their names say which body point they are
        self.parents = display_parents(skeleton if skeleton is not None else list(names))

    def step(self, frame_a: Motion) -> np.ndarray | None:
        return self._positions(self._partner.step(frame_a))

    def stepper(self, motion_a: Motion) -> Callable[[int], np.ndarray | None]:
        """Frame ``i`` of ``motion_a`` (at the partner's rate) in, B's pose out: through the
        partner's ``see`` (A's whole motion seen at once; the dual HMM's
        :meth:`~markovmotion.models.hmm.partner.Partner.see`) where it offers one, else
        :meth:`step` of the one-frame motion."""
        see = getattr(self._partner, "see", None)
        seen = self._seen(see, motion_a) if see is not None else None
        if seen is None:
            return _one_frame_steps(self, motion_a)
        step_seen = self._partner.step_seen
        return lambda i: self._positions(step_seen(seen, i))

    def skip(self) -> np.ndarray | None:
        """A frame of A missed (the camera page's frames come when they can)."""
        return self._positions(self._partner.skip())

    _SEEN: ClassVar[collections.OrderedDict] = collections.OrderedDict()
    _SEEN_LOCK = threading.Lock()

    def _seen(self, see: Callable, motion_a: Motion):
        """``see(motion_a)``, computed once for every session that streams the same motion
        object (a library file: :meth:`MotionLibrary.stream` gives each the same) with the
        same model; the last 8 kept."""
        key = (id(self._model), id(motion_a))
        with self._SEEN_LOCK:
            hit = self._SEEN.get(key)
            if hit is not None and hit[0] is self._model and hit[1] is motion_a:
                self._SEEN.move_to_end(key)
                return hit[2]
            seen = see(motion_a)
            self._SEEN[key] = (self._model, motion_a, seen)  # the objects kept: ids stay theirs
            while len(self._SEEN) > 8:
                self._SEEN.popitem(last=False)
        return seen

    @staticmethod
    def _positions(out) -> np.ndarray | None:
        if out is None:
            return None
        return out.positions()[0] if isinstance(out, Motion) else out.positions[0]

    def drop(self) -> None:
        self._partner.drop()


def load_partner_model(path: str | os.PathLike[str]) -> Model:
    """The model saved at ``path``, of any kind that offers ``partner()``.

    Raises:
        ModelFormatError: not a model file, or (one line naming the file and
            its kind) a model without an online partner.
    """
    import importlib
    import pkgutil

    import markovmotion.models as models

    for info in pkgutil.walk_packages(models.__path__, f"{models.__name__}."):
        importlib.import_module(info.name)  # every family's KIND registered
    model = Model.load(path)
    if "partner" not in type(model).VERBS:
        partners = sorted(k for k, c in KINDS.items() if "partner" in c.VERBS)
        raise ModelFormatError(
            path,
            f"a {model.KIND!r} model has no online partner (models that have: "
            f"{', '.join(partners)})",
        )
    return model


def model_partner(path: str | os.PathLike[str]) -> PartnerFactory:
    """Sessions answered by the model saved at ``path`` (:func:`load_partner_model`), its
    compiled kernels ready (:func:`warm_up`)."""
    model = load_partner_model(path)
    warm_up(model)
    factory = partial(ModelPartner, model)
    # what person A may be: a skeleton model refuses markers (the live page lists no C3D)
    factory.reads = "markers" if getattr(model, "uses_markers", False) else "skeleton"
    return factory


def warm_up(model: Model) -> None:
    """Step a partner of ``model`` through a person A standing still (the rest pose of the
    model's A skeleton, if it has one), stepped and seen, so that numba's kernels are
    compiled or loaded from their cache before a session needs them. A first session
    compiling them held every session of its worker for seconds (the event loop and
    numba's compile lock; on a fresh clone the 40 sessions of the load test all timed out)."""
    skeleton = getattr(model, "skeleton_a_", None)
    fps = getattr(model, "fps", None)
    if not isinstance(skeleton, Skeleton) or not fps:
        return
    frames = 2 * int(getattr(model, "window", 10)) + 2
    still = np.tile([0.0, 0.0, 0.0, 1.0], (frames, skeleton.n_joints, 1))
    rest = Motion.from_rotations(skeleton, still, fps=float(fps), name="warm-up")
    try:
        partner = ModelPartner(model, rest)
        step = stepper(partner, rest)
        for i in range(frames):
            step(i)
        partner = ModelPartner(model, rest)
        for i in range(frames):
            partner.step(rest.trim(i, i + 1))
    except MarkovMotionError:
        return  # a model this cannot warm (its first session compiles)


#: The factory's name from when only the dual HMM could answer on the live page.
dual_hmm_partner = model_partner


class _Garbage(ValueError):
    """A message that is not part of the protocol (closed with 1008, policy violation)."""

    code = 1008


class _Binary(_Garbage):
    """A binary frame: the protocol is JSON text (closed with 1003, unsupported data)."""

    code = 1003


async def _receive_text(ws: WebSocket) -> str:
    """The next text message; :class:`_Binary` for a binary frame, WebSocketDisconnect at the end."""
    message = await ws.receive()
    if message["type"] == "websocket.disconnect":
        raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
    text = message.get("text")
    if text is None:
        raise _Binary("binary frames are not supported: send JSON text messages")
    return text


def _parse(text: str) -> dict:
    try:
        msg = json.loads(text)
    except json.JSONDecodeError:
        raise _Garbage("the message is not JSON") from None
    except (RecursionError, ValueError):  # ValueError: an integer of over 4300 digits
        raise _Garbage("the message is not JSON (nested too deeply or a number too long)") from None
    if not isinstance(msg, dict):
        raise _Garbage("the message is not a JSON object")
    return msg


_START_FIELDS = {
    "path": (str, "a library file's path (a string)"),
    "bvh": (str, "the BVH file's text (a string)"),
    "name": (str | None, "the uploaded file's name (a string)"),
    "loop": (bool, "true or false"),
}


def _start_request(msg: dict) -> dict:
    """The page's first message, its fields of the right types (:class:`_Garbage` naming the
    first that is not: ``"loop": "no"`` had looped, a ``"name"`` object was shown as Python)."""
    for key, (kind, what) in _START_FIELDS.items():
        if key in msg and not isinstance(msg[key], kind):
            raise _Garbage(f"{key}: {what}")
    if "path" not in msg and "bvh" not in msg:
        raise _Garbage('the first message must hold "path" or "bvh"')
    return msg


def _motion_of(msg: dict, library: MotionLibrary) -> Motion | Markers:
    if isinstance(msg.get("path"), str):
        return library.motion(msg["path"])
    if isinstance(msg.get("bvh"), str):
        return read_upload(str(msg.get("name") or "upload.bvh"), msg["bvh"].encode())
    raise _Garbage('the first message must hold "path" or "bvh"')


def _stream(msg: dict, library: MotionLibrary, factory: PartnerFactory):
    """Person A (at the partner's rate), A's frames as JSON text, the session's partner and
    how to step it frame by frame (:func:`stepper`).

    A library file is read, resampled and encoded once for every session that streams
    it (:meth:`MotionLibrary.stream`); an upload for its own session."""
    if isinstance(msg.get("path"), str):
        partner = factory(library.motion(msg["path"]))
        motion, poses = library.stream(msg["path"], partner.fps)
    else:
        motion = _motion_of(msg, library)
        partner = factory(motion)
        motion = motion.resample(partner.fps) if partner.fps else motion
        poses = encoded_frames(motion)
    return motion, poses, partner, stepper(partner, motion)


async def _send(ws: WebSocket, msg: dict) -> None:
    await ws.send_text(json.dumps(msg, separators=(",", ":")))


def _reason(message: str) -> str:
    """A close reason: one line of at most 123 bytes (the WebSocket limit)."""
    line = " ".join(message.split())
    if len(line.encode()) <= 123:
        return line
    return line.encode()[:120].decode(errors="ignore") + "..."


async def _close(ws: WebSocket, code: int = 1000, reason: str | None = None) -> None:
    if ws.application_state != WebSocketState.DISCONNECTED:
        try:
            await ws.close(code, _reason(reason) if reason else None)
        except (RuntimeError, WebSocketDisconnect, OSError):
            pass


async def _listen(ws: WebSocket, stop: asyncio.Event, garbage: list[_Garbage]) -> None:
    """Stop the session on ``{"type": "stop"}``, on garbage (kept in ``garbage`` for the
    close frame) or when the page goes away."""
    try:
        while True:
            msg = await _receive_text(ws)
            if _parse(msg).get("type") == "stop":
                break
            raise _Garbage("unexpected message during streaming")
    except _Garbage as exc:
        garbage.append(exc)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        stop.set()


TICK = 0.004
"""A worker's live sessions are stepped by one task (:class:`_Ticker`) that wakes when the
first of them is due and serves every session due within this many seconds (an eighth of a
frame at 30 fps): a wake-up per tick, not per frame and session."""


class _Stream:
    """One live session's place in its stream: frame k of A is due at ``start + k / fps``."""

    def __init__(
        self,
        ws: WebSocket,
        motion: Motion,
        poses_a: list[str],
        partner: LivePartner,
        step: Callable[[int], np.ndarray | None],
        loop: bool,
        drop_late: float,
        stop: asyncio.Event,
    ):
        self.ws, self.motion, self.poses_a = ws, motion, poses_a
        self.partner, self.step, self.loop, self.drop_late = partner, step, loop, drop_late
        self.period = 1.0 / motion.fps
        self.start = time.perf_counter()
        self.frame = self.skipped = self.sent = 0  # frames stepped or dropped; dropped; sent
        self.stop = stop
        self.done: asyncio.Future = asyncio.get_running_loop().create_future()
        self.sending: asyncio.Future | None = None  # a send that had to wait (slow page)

    @property
    def due(self) -> float:
        """When the session is next served: its next frame's time, or while a send waits
        for a slow page a frame from now."""
        if self.sending is not None and not self.sending.done():
            return time.perf_counter() + self.period
        return self.start + self.frame * self.period

    def over(self) -> bool:
        return self.stop.is_set() or (not self.loop and self.frame >= self.motion.n_frames)

    def serve(self) -> None:
        """The present frame: stepped and sent; the frames it overtook dropped.

        Frame k is due at start + k / fps; a session more than ``drop_late`` behind its
        clock drops the frames already overtaken by their successors (the partner told by
        drop(), which costs far less than a step, so catching up does not put the other
        sessions behind) and jumps to the present one, never sends a backlog."""
        motion = self.motion
        now = time.perf_counter() - self.start
        present = int(now * motion.fps)
        if not self.sent or now - self.frame * self.period <= self.drop_late:
            present = self.frame  # the clock has not started, or a jitter to catch up with
        elif not self.loop:
            present = min(present, motion.n_frames - 1)
        while self.frame < present:
            self.partner.drop()
            self.frame += 1
            self.skipped += 1
        i = self.frame % motion.n_frames
        t0 = time.perf_counter()
        # in the event loop's own thread: a step takes well under a millisecond, and a hop
        # to a worker thread per frame made the threads queue on the interpreter lock
        # (40 sessions: 54 ms median latency, real-time factor 0.32)
        pose_b = self.step(i)
        latency = 1000.0 * (time.perf_counter() - t0)
        b = "null" if pose_b is None else positions_json(pose_b)
        self.sending = _send_soon(
            self.ws,
            f'{{"type":"frame","i":{self.frame},"a":{self.poses_a[i]},"b":{b},'
            f'"latency_ms":{round(latency, 3)},"skipped":{self.skipped}}}',
        )
        self.sent += 1
        self.frame += 1
        if self.sent == 1:  # the clock starts with the first frame out (loading, compiling):
            # that frame's time is now, whichever frame it was
            self.start = time.perf_counter() - (self.frame - 1) * self.period


class _Resume:
    """Awaiting the rest of a coroutine already started by hand (:func:`_send_soon`) from
    the future it is waiting on."""

    def __init__(self, coro, waiting):
        self.coro, self.waiting = coro, waiting

    def __await__(self):
        waiting = self.waiting
        while True:
            try:
                value = yield waiting
            except BaseException as exc:  # noqa: BLE001 - thrown into the coroutine
                try:
                    waiting = self.coro.throw(exc)
                except StopIteration:
                    return
            else:
                try:
                    waiting = self.coro.send(value)
                except StopIteration:
                    return


async def _finish(resume: _Resume) -> None:
    await resume


def _send_soon(ws: WebSocket, text: str) -> asyncio.Future | None:
    """Send ``text`` now; None if it went without waiting (the transport took it, as it
    does unless the page reads too slowly), else the task that finishes the send. So one
    slow page never holds up the other sessions of the ticker; the ticker skips a session
    while its send waits (its frames are then dropped as late)."""
    coro = ws.send_text(text)
    try:
        waiting = coro.send(None)
    except StopIteration:
        return None
    return asyncio.ensure_future(_finish(_Resume(coro, waiting)))


class _Ticker:
    """The live sessions of one event loop (one worker), stepped by one task: it sleeps
    until the first session is due, then serves every session due within :data:`TICK`,
    in turn. Fewer wake-ups and timers than a task per session sleeping per frame; a
    session's failure ends that session only."""

    _by_loop: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def __init__(self) -> None:
        self.streams: list[_Stream] = []
        self.task: asyncio.Task | None = None

    @classmethod
    def of_this_loop(cls) -> _Ticker:
        loop = asyncio.get_running_loop()
        ticker = cls._by_loop.get(loop)
        if ticker is None:
            ticker = cls._by_loop[loop] = cls()
        return ticker

    async def run(self, stream: _Stream) -> None:
        """Serve ``stream`` until it is over or stopped (exceptions of its partner raised
        here, for its session)."""
        self.streams.append(stream)
        if self.task is None or self.task.done():
            self.task = asyncio.create_task(self._tick())
        stop = asyncio.ensure_future(stream.stop.wait())
        try:
            await asyncio.wait([stream.done, stop], return_when=asyncio.FIRST_COMPLETED)
        finally:
            stop.cancel()
            if stream in self.streams:
                self.streams.remove(stream)
        if stream.done.done():
            stream.done.result()

    async def _tick(self) -> None:
        while self.streams:
            began = time.perf_counter()
            soon = began + TICK
            for stream in list(self.streams):
                if stream in self.streams and stream.due <= soon:
                    self._serve(stream)
                    if time.perf_counter() - began > 2 * TICK:
                        # many sessions due at once: the pages' messages and new
                        # connections get in at least every 8 ms of stepping
                        await asyncio.sleep(0)
                        began = time.perf_counter()
            if not self.streams:
                break
            delay = min(s.due for s in self.streams) - time.perf_counter()
            # a plain sleep; behind, sleep(0) still lets the pages' messages in between
            await asyncio.sleep(max(delay, 0.0))

    def _serve(self, stream: _Stream) -> None:
        sending = stream.sending
        if sending is not None and not sending.done():
            return  # the page reads slowly: its frames wait (and are dropped as late)
        try:
            if sending is not None and (sending.cancelled() or sending.exception()):
                self._end(stream)  # the page went away while its frame waited
                return
            if stream.over():
                self._end(stream)
                return
            stream.serve()
        except (WebSocketDisconnect, RuntimeError, OSError):
            self._end(stream)  # the page went away
        except BaseException as exc:  # noqa: BLE001 - raised in the session's own task
            self.streams.remove(stream)
            if not stream.done.done():
                stream.done.set_exception(exc)

    def _end(self, stream: _Stream) -> None:
        self.streams.remove(stream)
        if not stream.done.done():
            stream.done.set_result(None)


async def live_session(
    ws: WebSocket,
    library: MotionLibrary,
    factory: PartnerFactory | None,
    drop_late: float = DROP_LATE,
) -> None:
    """Run one live-partner session on an accepted-to-be WebSocket (see the module protocol).

    ``drop_late``: how far (seconds) the session may fall behind its clock before it drops
    frames; ``math.inf`` never drops (every frame stepped and sent, however late)."""
    await ws.accept()
    try:
        msg = _start_request(_parse(await asyncio.wait_for(_receive_text(ws), START_TIMEOUT)))
        if factory is None:
            raise _Garbage("this server has no partner model: start it with --partner MODEL")
        motion, poses_a, partner, step = await asyncio.to_thread(_stream, msg, library, factory)
    except (_Garbage, MarkovMotionError, TimeoutError, RecursionError, MemoryError) as exc:
        if isinstance(exc, _Garbage | MarkovMotionError):
            message = library.public(str(exc))
        elif isinstance(exc, TimeoutError):
            message = "no request in time"
        else:
            message = "the motion cannot be read (too large or nested too deeply)"
        try:
            await _send(ws, {"type": "error", "message": message})
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        await _close(ws, getattr(exc, "code", 1008), message)
        return
    except (WebSocketDisconnect, RuntimeError):
        return
    stop = asyncio.Event()
    garbage: list[_Garbage] = []
    listener = asyncio.create_task(_listen(ws, stop, garbage))
    try:
        await _send(
            ws,
            {
                "type": "start",
                "fps": motion.fps,
                "frames": motion.n_frames,
                "parents_a": figure_parents(motion),
                "parents_b": list(partner.parents),
                "lag": int(partner.lag),
            },
        )
        loop = bool(msg.get("loop"))
        stream = _Stream(ws, motion, poses_a, partner, step, loop, drop_late, stop)
        await _Ticker.of_this_loop().run(stream)
        if not stop.is_set():
            await _send(ws, {"type": "end", "frames": stream.sent, "skipped": stream.skipped})
    except (WebSocketDisconnect, RuntimeError, OSError):
        pass
    finally:
        listener.cancel()
        if garbage:
            await _close(ws, garbage[0].code, str(garbage[0]))
        else:
            await _close(ws)

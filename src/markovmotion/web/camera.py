"""The live partner from a camera: the page's webcam frames in, the person and the partner out.

Protocol over the WebSocket ``/ws/camera``:

1. the page sends a JSON text message ``{"fov": 60}`` (the camera's horizontal field of
   view in degrees, :data:`FOV_RANGE`; optional: the tracker's default);
2. the server answers ``{"type": "start", "fps", "parents_a", "parents_b", "lag",
   "max_bytes", "max_side"}`` (``fps``: the partner's rate) or ``{"type": "error",
   "message"}`` and closes;
3. the page sends each camera frame as one binary message, a JPEG of at most
   :data:`MAX_FRAME_BYTES` bytes and :data:`MAX_SIDE` pixels a side; the server answers
   each with ``{"type": "frame", "i", "found", "a", "b", "pixels", "track_ms",
   "partner_ms"}``: A's 19 body points (mm, flat; ``null`` when no person is found),
   B's joints (``null`` until the partner's look-ahead fills), the 33 landmarks' pixels
   (flat x, y) for drawing over the video, and the time spent tracking and answering;
4. ``{"type": "stop"}`` (or closing the tab) ends the session. A frame too large, not a
   JPEG or of a size outside the bounds is ``{"type": "error", "message"}`` (one line)
   and the close codes 1009 (too big) or 1007 (not an image); any other text, 1008.

Frames arrive at the camera's rate, whatever the page and the network let through; the
partner needs A at its own rate (``fps``). Each frame is timed on arrival and the partner
is stepped once per tick of its rate that has passed, with A's body points interpolated
between the last frame and this one (:class:`TickResampler`); a gap of more than
:data:`MAX_GAP` seconds is told to the partner as frames missed (``skip``).

Frames are pipelined: the tracker has ``graphs`` MediaPipe graphs (two on two cores,
:data:`markovmotion.video.webcam.DEFAULT_GRAPHS`) and frame ``n`` is decoded and its
landmarks found on graph ``n % graphs`` in a worker thread (MediaPipe lets go of the GIL, so
the graphs run on both cores while the event loop goes on), each graph taking its frames
one at a time and in order; the landmarks are then placed, the partner stepped and the
answer sent in frame order, one frame after another. At most :data:`MAX_PENDING` frames
are received and not yet answered; every frame received is answered, also after
``{"type": "stop"}``. A tracker that raises ends the session with ``{"type": "error",
"message": "frame N: the tracker failed (...)"}`` and the close code 1011.

The tracker is given to the app (``create_app(camera=...)``, a :data:`TrackerFactory`):
``serve`` gives :class:`markovmotion.video.webcam.WebcamTracker` (the web layer does not
import the video layer).
"""

from __future__ import annotations

import asyncio
import functools
import json
import math
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np
from starlette.websockets import WebSocket, WebSocketDisconnect

from markovmotion.errors import MarkovMotionError
from markovmotion.features.body_points import BODY_POINTS, POINT_SKELETON, points_motion
from markovmotion.web.library import display_parents, flat_positions
from markovmotion.web.live import (
    START_TIMEOUT,
    LivePartner,
    PartnerFactory,
    _close,
    _Garbage,
    _parse,
    _receive_text,
    _send,
)

#: Largest JPEG frame accepted (bytes): 640x480 at quality 0.9 is about 60 kB.
MAX_FRAME_BYTES = 300_000
#: Largest and smallest image side accepted (pixels), read from the JPEG's header before
#: it is decoded (a small file may declare an enormous image).
MAX_SIDE = 1280
MIN_SIDE = 32
#: Camera sessions one server process runs at once (each runs its MediaPipe graphs).
MAX_SESSIONS = 2
#: Frames of a session received and not yet answered: the tracker's graphs work on as many
#: as they have, the others wait; further frames wait in the socket (the page sends a frame
#: only while fewer than its frames in flight await an answer, so none queue up).
MAX_PENDING = 4
#: Longest gap between frames (s) over which A is interpolated; longer is frames missed.
MAX_GAP = 0.5
#: Fields of view a page may give (degrees).
FOV_RANGE = (20.0, 120.0)


class TrackedFrame(Protocol):
    """A tracked camera frame: the 19 body points (mm, Y up) and the 33 landmarks' pixels."""

    points: np.ndarray
    pixels: np.ndarray


class FrameTracker(Protocol):
    """One camera's person, frame by frame (:class:`markovmotion.video.webcam.WebcamTracker`):
    ``landmarks(rgb, graph)`` (the slow part: ``graphs`` of them may run at once, in worker
    threads, each graph's frames in order) then ``place(found)`` of every frame in order."""

    @property
    def graphs(self) -> int: ...

    def landmarks(self, rgb: np.ndarray, graph: int) -> object: ...

    def place(self, found: object) -> TrackedFrame | None: ...

    def close(self) -> None: ...


TrackerFactory = Callable[..., FrameTracker]
"""Builds a session's tracker, with the field of view (degrees) as its argument if the page
gave one (raising a :class:`MarkovMotionError` if it cannot track, e.g. MediaPipe missing)."""

_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


class _BadFrame(_Garbage):
    """A frame that is not a JPEG image of an accepted size (closed with 1007)."""

    code = 1007


class _TooBig(_Garbage):
    """A frame over the size limits (closed with 1009, message too big)."""

    code = 1009


class TrackerFailed(RuntimeError):
    """The tracker raised on a frame (closed with 1011, internal error, with one line)."""


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) declared by a JPEG's frame header, or None if ``data`` is not a JPEG
    whose header can be found (the markers are walked, the image is not decoded)."""
    if data[:2] != b"\xff\xd8":
        return None
    i, n = 2, len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length
            i += 2
            continue
        length = int.from_bytes(data[i + 2 : i + 4], "big")
        if length < 2:
            return None
        if marker in _SOF:
            if i + 9 > n:
                return None
            height = int.from_bytes(data[i + 5 : i + 7], "big")
            width = int.from_bytes(data[i + 7 : i + 9], "big")
            return width, height
        if marker == 0xD9:
            return None
        i += 2 + length
    return None


def decode_frame(data: bytes, number: int) -> np.ndarray:
    """A camera frame's JPEG bytes -> RGB (H, W, 3) uint8, checked before decoding.

    Raises:
        _TooBig: more than :data:`MAX_FRAME_BYTES` bytes or :data:`MAX_SIDE` pixels a side.
        _BadFrame: not a JPEG, smaller than :data:`MIN_SIDE`, or it cannot be decoded.
    """
    import cv2

    if len(data) > MAX_FRAME_BYTES:
        raise _TooBig(f"frame {number}: {len(data)} bytes, more than {MAX_FRAME_BYTES} allowed")
    size = jpeg_size(data)
    if size is None:
        raise _BadFrame(f"frame {number}: not a JPEG image")
    if max(size) > MAX_SIDE:
        raise _TooBig(f"frame {number}: {size[0]}x{size[1]} pixels, more than {MAX_SIDE} a side")
    if min(size) < MIN_SIDE:
        raise _BadFrame(f"frame {number}: {size[0]}x{size[1]} pixels, less than {MIN_SIDE} a side")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None or img.shape[1::-1] != size:
        raise _BadFrame(f"frame {number}: the JPEG image cannot be decoded")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


class TickResampler:
    """A's frames at their arrival times in, the partner stepped at its own rate.

    ``feed(t, points)`` (points (19, 3) or None when no person was found) steps the
    partner once for every tick ``k / fps`` (from the first frame) up to ``t``, with A's
    points interpolated linearly between the last frame and this one; ticks before a gap
    longer than :data:`MAX_GAP`, or while no person is seen, are frames missed
    (``skip``). Returns B's latest pose (None until the partner's first answer)."""

    def __init__(self, partner: LivePartner, fps: float):
        self.partner = partner
        self.fps = float(fps)
        self.start: float | None = None
        self.ticks = 0
        self.last: tuple[float, np.ndarray] | None = None
        self.b: np.ndarray | None = None

    def feed(self, t: float, points: np.ndarray | None) -> np.ndarray | None:
        if self.start is None:
            self.start = t
        due = int(math.floor((t - self.start) * self.fps + 1e-9)) + 1
        last = self.last if points is not None else None
        if last is not None and t - last[0] > MAX_GAP:
            last = None
        for k in range(self.ticks, due):
            tick = self.start + k / self.fps
            if points is None:
                out = self._skip()
            elif last is None or tick >= t or t <= last[0]:
                out = self._step(points) if k == due - 1 else self._skip()
            else:
                w = (tick - last[0]) / (t - last[0])
                out = self._step(last[1] + max(w, 0.0) * (points - last[1]))
            if out is not None:
                self.b = np.asarray(out)
        self.ticks = max(self.ticks, due)
        if points is not None:
            self.last = (t, points)
        return self.b

    def _step(self, points: np.ndarray):
        return self.partner.step(points_motion(points[None], self.fps, "camera"))

    def _skip(self):
        skip = getattr(self.partner, "skip", None)
        return skip() if skip is not None else None


def _rest_points() -> np.ndarray:
    """The body points of :data:`POINT_SKELETON`'s rest pose (a first A for the partner's
    input check before any frame)."""
    from markovmotion.core.motion import Motion

    rest = np.tile([0.0, 0.0, 0.0, 1.0], (1, len(BODY_POINTS), 1))
    return Motion.from_rotations(POINT_SKELETON, rest).positions()[0]


def _start(msg: dict, factory: PartnerFactory, camera: TrackerFactory):
    """The session's tracker and partner (in a worker thread: MediaPipe takes a while)."""
    fov = msg.get("fov")
    if fov is not None and (
        isinstance(fov, bool)
        or not isinstance(fov, int | float)
        or not FOV_RANGE[0] <= fov <= FOV_RANGE[1]
    ):
        raise _Garbage(f"fov: a field of view in degrees from {FOV_RANGE[0]:g} to {FOV_RANGE[1]:g}")
    partner = factory(points_motion(_rest_points()[None], 30.0, "camera"))
    return (camera() if fov is None else camera(float(fov))), partner


def _failed(number: int, exc: Exception) -> TrackerFailed:
    message = " ".join(str(exc).split()) or type(exc).__name__
    return TrackerFailed(f"frame {number}: the tracker failed ({message})")


def _detect(tracker: FrameTracker, data: bytes, number: int, graph: int):
    """A frame's first stage (a worker thread, beside the other graphs'): decode, landmarks.
    Returns the image's (width, height), the tracker's landmarks and the seconds they took.

    Raises:
        _BadFrame, _TooBig: from :func:`decode_frame`.
        TrackerFailed: the tracker raised (one line naming the frame).
    """
    rgb = decode_frame(data, number)
    t0 = time.perf_counter()
    try:
        found = tracker.landmarks(rgb, graph)
    except Exception as exc:
        raise _failed(number, exc) from exc
    return rgb.shape[1], rgb.shape[0], found, time.perf_counter() - t0


async def _detect_after(
    before: asyncio.Future | None, tracker: FrameTracker, data: bytes, number: int, graph: int
):
    """:func:`_detect` once the graph's previous frame (``before``) is done, so that each
    graph takes its frames one at a time and in order (MediaPipe's video mode)."""
    if before is not None:
        await asyncio.wait([before])
    return await asyncio.to_thread(_detect, tracker, data, number, graph)


def _answer(
    tracker: FrameTracker, resampler: TickResampler, detected, number: int, arrived: float
) -> str:
    """One frame's answer (JSON text), in frame order (a worker thread): place the landmarks
    of :func:`_detect`, step the partner."""
    width, height, found, seconds = detected
    t0 = time.perf_counter()
    try:
        frame = tracker.place(found)
    except Exception as exc:
        raise _failed(number, exc) from exc
    t1 = time.perf_counter()
    b = resampler.feed(arrived, None if frame is None else frame.points)
    t2 = time.perf_counter()
    return json.dumps(
        {
            "type": "frame",
            "i": number,
            "found": frame is not None,
            "a": None if frame is None else flat_positions(frame.points),
            "b": None if b is None else flat_positions(b),
            "pixels": None if frame is None else flat_positions(frame.pixels),
            "width": width,
            "height": height,
            "track_ms": round(1000 * (seconds + t1 - t0), 2),
            "partner_ms": round(1000 * (t2 - t1), 2),
        },
        separators=(",", ":"),
    )


async def _receive_frames(
    ws: WebSocket, tracker: FrameTracker, pending: asyncio.Queue, running: set
) -> None:
    """The session's reader: each binary frame starts its :func:`_detect` on graph
    ``number % graphs`` (after that graph's previous frame) and joins ``pending`` in order
    (``(task, number, arrival time)``; None at the end); ``running``: the tasks not done."""
    graphs = max(1, int(tracker.graphs))
    last: list[asyncio.Future | None] = [None] * graphs
    number = 0
    while True:
        message = await ws.receive()
        if message["type"] == "websocket.disconnect":
            break
        data = message.get("bytes")
        if data is None:
            if _parse(message.get("text") or "").get("type") == "stop":
                break
            raise _Garbage("unexpected text message: send frames as binary JPEG messages")
        arrived = time.perf_counter()
        graph = number % graphs
        task = asyncio.ensure_future(_detect_after(last[graph], tracker, data, number, graph))
        last[graph] = task
        running.add(task)  # until done: the session's end waits for it
        task.add_done_callback(functools.partial(_done, running))
        await pending.put((task, number, arrived))
        number += 1
    await pending.put(None)


def _done(running: set, task: asyncio.Future) -> None:
    """A frame's task is done: out of ``running``; its error (if any) is the writer's to
    report, or nobody's once the session has ended (not logged as never retrieved)."""
    running.discard(task)
    if not task.cancelled():
        task.exception()


async def _answer_frames(
    ws: WebSocket, tracker: FrameTracker, resampler: TickResampler, pending: asyncio.Queue
) -> None:
    """The session's writer: each frame of ``pending``, in order, placed, answered, sent."""
    while (item := await pending.get()) is not None:
        task, number, arrived = item
        detected = await asyncio.shield(task)  # a cancelled session lets it finish
        answer = await asyncio.to_thread(_answer, tracker, resampler, detected, number, arrived)
        await ws.send_text(answer)


async def camera_session(
    ws: WebSocket,
    factory: PartnerFactory | None,
    camera: TrackerFactory | None,
    sessions: list,
) -> None:
    """Run one camera session (module protocol) on a WebSocket with the partners of
    ``factory`` and the trackers of ``camera``; ``sessions``: the server's running sessions
    (one entry each), at most :data:`MAX_SESSIONS`."""
    await ws.accept()
    tracker = None
    try:
        msg = _parse(await asyncio.wait_for(_receive_text(ws), START_TIMEOUT))
        if factory is None:
            raise _Garbage("this server has no partner model: start it with --partner MODEL")
        if camera is None:
            raise _Garbage("this server has no camera tracker (markovmotion serve has one)")
        if len(sessions) >= MAX_SESSIONS:
            raise _Garbage(
                f"the server is busy: {MAX_SESSIONS} camera sessions already, try again later"
            )
        sessions.append(ws)
        tracker, partner = await asyncio.to_thread(_start, msg, factory, camera)
    except (_Garbage, MarkovMotionError, TimeoutError) as exc:
        message = "no request in time" if isinstance(exc, TimeoutError) else str(exc)
        await _fail(ws, message, getattr(exc, "code", 1008))
        _leave(sessions, ws)
        return
    except (WebSocketDisconnect, RuntimeError):
        _leave(sessions, ws)
        return
    resampler = TickResampler(partner, partner.fps or 30.0)
    running: set[asyncio.Future] = set()
    error: tuple[str, int] | None = None
    ended = False  # the client stopped: close the socket once the graphs are released
    try:
        await _send(
            ws,
            {
                "type": "start",
                "fps": resampler.fps,
                "parents_a": display_parents(POINT_SKELETON),
                "parents_b": list(partner.parents),
                "lag": int(partner.lag),
                "max_bytes": MAX_FRAME_BYTES,
                "max_side": MAX_SIDE,
            },
        )
        pending: asyncio.Queue = asyncio.Queue(MAX_PENDING)
        async with asyncio.TaskGroup() as group:
            group.create_task(_receive_frames(ws, tracker, pending, running))
            group.create_task(_answer_frames(ws, tracker, resampler, pending))
        ended = True
    except* _Garbage as exc:
        first = exc.exceptions[0]
        error = (str(first), first.code)
    except* (TrackerFailed, MarkovMotionError) as exc:  # one line, internal error
        error = (str(exc.exceptions[0]), 1011)
    except* (WebSocketDisconnect, RuntimeError, OSError):
        pass
    finally:
        _leave(sessions, ws)
        # a graph's thread cannot be stopped: let every frame finish before closing them, and
        # close them before the socket, so that a session the client sees ended holds nothing
        await asyncio.gather(*running, return_exceptions=True)
        await asyncio.to_thread(tracker.close)
        if error is not None:
            await _fail(ws, *error)
        elif ended:
            await _close(ws)


async def _fail(ws: WebSocket, message: str, code: int) -> None:
    try:
        await _send(ws, {"type": "error", "message": message})
    except (WebSocketDisconnect, RuntimeError, OSError):
        pass
    await _close(ws, code, message)


def _leave(sessions: list, ws: WebSocket) -> None:
    if ws in sessions:
        sessions.remove(ws)

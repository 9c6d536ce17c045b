"""Frames to an MP4 file (H.264) through the ffmpeg binary of ``imageio-ffmpeg``.

One writer for every video the package makes: stick-figure animations
(:mod:`markovmotion.viz.animation`) and silhouette videos
(:mod:`markovmotion.video.render`). No matplotlib here, so video code can
import it cheaply.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from markovmotion.io.files import atomic_path, check_writable

#: ffmpeg's input pixel format by the number of channels of a frame.
PIXEL_FORMATS = {3: "rgb24", 4: "rgba"}


def write_mp4(
    frames: Iterable[np.ndarray],
    path: str | os.PathLike[str],
    fps: float,
    *,
    preset: str = "medium",
    crf: int = 15,
) -> Path:
    """Encode RGB or RGBA frames (H, W, 3|4) uint8 to ``path`` (atomically), H.264 yuv420p.

    ``crf`` is x264's constant quality (0 lossless ... 51 worst) and ``preset``
    its speed/size trade-off (``veryfast`` suits noisy frames, which are
    expensive to encode at the slower presets).
    """
    import imageio_ffmpeg

    path = Path(path)
    check_writable(path)  # one line naming it, not ffmpeg's lines and a broken pipe
    frames = iter(frames)
    first = next(frames)
    with atomic_path(path) as tmp:
        writer = imageio_ffmpeg.write_frames(
            str(tmp),
            (first.shape[1], first.shape[0]),
            fps=fps,
            codec="libx264",
            pix_fmt_in=PIXEL_FORMATS[first.shape[2]],
            pix_fmt_out="yuv420p",
            quality=None,
            output_params=["-preset", preset, "-crf", str(crf)],
            macro_block_size=2,
            ffmpeg_log_level="error",
        )
        try:
            writer.send(None)
            writer.send(np.ascontiguousarray(first))
            for f in frames:
                writer.send(np.ascontiguousarray(f))
        except BaseException as exc:  # an error or a signal: stop ffmpeg now, not when collected
            try:
                writer.throw(SystemExit(1))  # imageio-ffmpeg kills ffmpeg on SystemExit
            except BaseException:
                pass
            if isinstance(exc, OSError) and exc.filename is None:  # ffmpeg's pipe, many lines
                said = (str(exc).splitlines() or ["it stopped"])[0]
                raise OSError(
                    errno.EPIPE, f"ffmpeg could not write it ({said})", str(path)
                ) from None
            raise
        writer.close()
        if not tmp.exists():  # ffmpeg said why on stderr, and gave up
            raise OSError(errno.EIO, "ffmpeg wrote nothing", str(path))
    return path

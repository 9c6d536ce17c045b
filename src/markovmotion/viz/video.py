"""Frames to an MP4 file (H.264) through the ffmpeg binary of ``imageio-ffmpeg``.

One writer for every video the package makes: stick-figure animations
(:mod:`markovmotion.viz.animation`) and silhouette videos
(:mod:`markovmotion.video.render`). No matplotlib here, so video code can
import it cheaply.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from markovmotion.io.files import atomic_path

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
        except BaseException:  # an error or a signal: stop ffmpeg now, not when collected
            try:
                writer.throw(SystemExit(1))  # imageio-ffmpeg kills ffmpeg on SystemExit
            except BaseException:
                pass
            raise
        writer.close()
    return path

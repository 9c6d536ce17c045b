"""Virtual partner videos (interaction paper, §5, Figure 5): the partner as a black silhouette.

From a video of one real person, the partner's B-spline silhouette (placed by
the real person's position and height) is filled in black into every frame.
From motion capture of one person, both are rendered by the side camera, the
real person in colour and the partner in black.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.errors import ModelFormatError
from markovmotion.models.chain.partner import VirtualPartner
from markovmotion.video.bspline import evaluate_closed_bspline
from markovmotion.video.render import (
    PEOPLE_COLOURS,
    Canvas,
    read_frames,
    render_frames,
    side_camera,
    write_video,
)
from markovmotion.video.tracker import track_video

BLACK = (0, 0, 0)


def draw_silhouette(
    frame: np.ndarray, control: np.ndarray, colour: tuple[int, int, int] = BLACK
) -> np.ndarray:
    """``frame`` (H, W, 3) with the closed B-spline of ``control`` (n, 2) filled in ``colour``."""
    h, w = frame.shape[:2]
    canvas = Canvas(w, h)
    canvas.polygon(evaluate_closed_bspline(control, 256))
    alpha = canvas.coverage()[..., None].astype(np.float32) / 255.0
    out = frame * (1 - alpha) + np.asarray(colour, np.float32) * alpha
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def respond_video(
    model: VirtualPartner,
    video: str | os.PathLike[str],
    out: str | os.PathLike[str],
    **options,
) -> Path:
    """Track the one real person of ``video`` and write it with its virtual partner (black)."""
    if model.shape_step.n_dims_ != 2:
        raise ModelFormatError(video, "videos need a model trained on silhouettes")
    real = track_video(video, n_people=1).person(0)
    partner = model.respond_shapes(real, None, **options).partner
    frames = (
        draw_silhouette(f, partner.points[min(t, partner.n_frames - 1)])
        for t, f in enumerate(read_frames(video))
    )
    return write_video(frames, out, model.fps_)


def respond_motion_video(
    model: VirtualPartner,
    motion: Motion,
    out: str | os.PathLike[str],
    person: int = 0,
    **options,
) -> Path:
    """Render a captured person (colour) and its 3-D virtual partner (black) from the side."""
    real = model.person(motion)  # its shape joints by the model's names, as respond's
    partner = model.respond_shapes(real, person, **options).partner
    camera = side_camera([real, partner])
    frames = render_frames([real, partner], camera, colours=[PEOPLE_COLOURS[person], BLACK])
    return write_video(frames, out, motion.fps)

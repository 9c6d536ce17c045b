"""What the two partner demos (dual HMM, behaviour chain) write alike: B as BVH, and a GIF
of the real leader, the real partner and the virtual partner in one scene."""

from __future__ import annotations

from pathlib import Path

from markovmotion.core.motion import Motion
from markovmotion.io import write_motion
from markovmotion.viz import render


def partner_scene(
    a: Motion,
    b: Motion,
    virtual: Motion,
    bvh: Path,
    gif: Path,
    model_name: str,
    title: str,
    max_seconds: float,
) -> list[Path]:
    """Write ``virtual`` to ``bvh`` and the three people to ``gif``; returns both paths."""
    write_motion(virtual, bvh)
    a.name, b.name, virtual.name = "A (real leader)", "B (real partner)", f"B ({model_name})"
    render([a, b, virtual], gif, max_seconds=max_seconds, title=title)
    return [bvh, gif]

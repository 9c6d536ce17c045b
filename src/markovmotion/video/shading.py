"""Shaded bodies with depth: capsules rasterised into a z-buffer, lit from the upper left.

Used to render people for the multi-view videos (clothes of several colours,
so that a limb in front of the body shows an edge, as in real video) and to
draw the virtual partner into a video behind or in front of the real person
(depth test against the tracked body model, :func:`composite`).

Each capsule is a tapered cylinder with rounded ends; a pixel inside its
projection gets the depth of the capsule's surface there (the axis depth
minus the bulge of the round section) and a Lambertian shade of the section's
normal. Pixel centres are at integer coordinates; 2x supersampling and
averaging smooth the outline.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numba
import numpy as np

from markovmotion.video.render import BodyShape

if TYPE_CHECKING:
    from markovmotion.video.cameras import CalibratedCamera

LIGHT = np.array([-0.45, -0.6, -0.66])
AMBIENT = 0.4
#: Clothes per capsule kind (RGB): shirt, sleeves/skin, trousers, shoes, head and hands.
CLOTHES = {
    "a": {"torso": (60, 80, 160), "upper_arm": (60, 80, 160), "forearm": (185, 125, 95),
          "thigh": (55, 55, 70), "shin": (55, 55, 70), "foot": (35, 30, 30),
          "ball": (185, 125, 95)},
    "b": {"torso": (170, 60, 50), "upper_arm": (170, 60, 50), "forearm": (150, 100, 75),
          "thigh": (90, 80, 60), "shin": (90, 80, 60), "foot": (40, 35, 30),
          "ball": (150, 100, 75)},
}  # fmt: skip


@numba.njit(cache=True)
def _raster(
    pix, depth, rad, rad_mm, seg, colours, light, ambient, scale, zbuf, rgb, ident, who
):  # pragma: no cover
    h, w = zbuf.shape
    for s in range(seg.shape[0]):
        ax = pix[seg[s, 0], 0] * scale
        ay = pix[seg[s, 0], 1] * scale
        bx = pix[seg[s, 1], 0] * scale
        by = pix[seg[s, 1], 1] * scale
        ra = rad[s, 0] * scale
        rb = rad[s, 1] * scale
        za = depth[seg[s, 0]]
        zb = depth[seg[s, 1]]
        rmax = max(ra, rb)
        x0 = max(int(min(ax, bx) - rmax) - 1, 0)
        x1 = min(int(max(ax, bx) + rmax) + 2, w)
        y0 = max(int(min(ay, by) - rmax) - 1, 0)
        y1 = min(int(max(ay, by) + rmax) + 2, h)
        dx = bx - ax
        dy = by - ay
        l2 = dx * dx + dy * dy
        for y in range(y0, y1):
            for x in range(x0, x1):
                px = (x + 0.5) - 0.5 * scale  # fine pixel centre in coarse-pixel units x scale
                py = (y + 0.5) - 0.5 * scale
                t = 0.0
                if l2 > 1e-12:
                    t = min(max(((px - ax) * dx + (py - ay) * dy) / l2, 0.0), 1.0)
                ex = px - (ax + t * dx)
                ey = py - (ay + t * dy)
                r = ra + t * (rb - ra)
                d2 = ex * ex + ey * ey
                if r <= 0 or d2 > r * r:
                    continue
                nz = np.sqrt(max(1.0 - d2 / (r * r), 0.0))
                z = za + t * (zb - za) - nz * (rad_mm[s, 0] + t * (rad_mm[s, 1] - rad_mm[s, 0]))
                if z >= zbuf[y, x]:
                    continue
                zbuf[y, x] = z
                dot = -(ex / r * light[0] + ey / r * light[1] - nz * light[2])
                shade = ambient + (1.0 - ambient) * max(dot, 0.0)
                for c in range(3):
                    rgb[y, x, c] = colours[s, c] * shade
                ident[y, x] = who


def capsule_colours(shape: BodyShape, names: Sequence[str], clothes: dict) -> np.ndarray:
    """(S, 3) colour of each primitive of ``shape`` (points named by ``names``) from ``clothes``."""
    seg, _ = shape.segments()
    out = []
    for a, b in seg:
        if a == b:
            kind = "ball"
        else:
            na, nb = names[a], names[b]
            if "elbow" in na:
                kind = "forearm"
            elif "shoulder" in na and "elbow" in nb:
                kind = "upper_arm"
            elif "hip" in na and "knee" in nb:
                kind = "thigh"
            elif "knee" in na:
                kind = "shin"
            elif "ankle" in na:
                kind = "foot"
            elif "pelvis" in na and "hip" in nb:
                kind = "thigh"
            else:
                kind = "torso"
        out.append(clothes[kind])
    return np.array(out, dtype=np.float64)


class DepthCanvas:
    """A z-buffer and colour buffer of one camera at ``scale`` times its resolution."""

    def __init__(self, width: int, height: int, scale: int = 2):
        self.width, self.height, self.scale = width, height, scale
        self.zbuf = np.full((height * scale, width * scale), np.inf)
        self.rgb = np.zeros((height * scale, width * scale, 3))
        self.ident = np.full((height * scale, width * scale), -1, np.int8)

    def body(
        self,
        joints: np.ndarray,
        camera: CalibratedCamera,
        shape: BodyShape,
        colours: np.ndarray,
        who: int = 0,
    ) -> None:
        """Draw a body (joints (P, 3) mm) with ``colours`` (S, 3); ``who`` labels its pixels."""
        seg, radii = shape.segments()
        pix, depth = camera.project(shape.points(joints))
        rad = camera.focal * radii / depth[seg]
        _raster(
            pix, depth, rad, radii, seg, colours, LIGHT / np.linalg.norm(LIGHT), AMBIENT,
            float(self.scale), self.zbuf, self.rgb, self.ident, who,
        )  # fmt: skip

    def over(self, image: np.ndarray, only: int | None = None) -> np.ndarray:
        """``image`` (H, W, 3) uint8 with the drawn bodies (or only body ``only``) over it."""
        hit = (self.ident >= 0) if only is None else (self.ident == only)
        fine = np.where(hit[..., None], self.rgb, 0.0).astype(np.float32)
        alpha = cv2.resize(
            hit.astype(np.float32), (self.width, self.height), interpolation=cv2.INTER_AREA
        )
        colour = cv2.resize(fine, (self.width, self.height), interpolation=cv2.INTER_AREA)
        colour = colour / np.maximum(alpha[..., None], 1e-6)
        out = image.astype(np.float32)
        out += alpha[..., None] * (colour - out)
        return np.clip(out, 0, 255).round().astype(np.uint8)

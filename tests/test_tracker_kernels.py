"""The tracker's compiled kernels against plain NumPy references (brute force, small inputs)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from markovmotion.video.annealed_particle_filter import (
    COVER_SAMPLES,
    EDGE_CONTRAST,
    EDGE_WEIGHT,
    FG_HIGH,
    FG_LOW,
    ViewFeatures,
    joint_costs,
    project_model,
    survival_beta,
    view_features,
)
from markovmotion.video.body_model import BODY_SHAPE, _turned
from markovmotion.video.cameras import ring_of_cameras

_T = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
_ACROSS = np.array([-0.6, 0.0, 0.6])
_BALL = np.pi / 4 + np.arange(4) * np.pi / 2


def _lookup(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Nearest pixel (truncating x + 0.5 towards zero, as the kernel does), 0 outside."""
    xi = np.trunc(np.asarray(x) + 0.5).astype(int)
    yi = np.trunc(np.asarray(y) + 0.5).astype(int)
    inside = (xi >= 0) & (yi >= 0) & (yi < img.shape[0]) & (xi < img.shape[1])
    out = np.zeros(xi.shape)
    out[inside] = img[yi[inside], xi[inside]]
    return out


def _reference_costs(joints, cameras, feats) -> np.ndarray:
    """The weighting function's cost written out plainly: every sample against every capsule."""
    seg, _ = BODY_SHAPE.segments()
    pix, rad, _ = project_model(joints, cameras)
    out = np.zeros(len(joints))
    for m in range(len(joints)):
        total = 0.0
        for v in range(len(cameras)):
            fg, edge = feats.fg[v], feats.edge[v]
            inner, edges = [], []
            for s, (a, b) in enumerate(seg):
                pa, pb = pix[m, v, a], pix[m, v, b]
                ra, rb = rad[m, v, s]
                d = pb - pa
                if d @ d > 1e-12:
                    n = np.array([-d[1], d[0]]) / np.sqrt(d @ d)
                    for t in _T:
                        c, r = pa + t * d, ra + t * (rb - ra)
                        inner += [1 - _lookup(fg, *(c + o * r * n)) for o in _ACROSS]
                        edges += [1 - _lookup(edge, *(c + r * n)), 1 - _lookup(edge, *(c - r * n))]
                else:
                    inner.append(1 - _lookup(fg, *pa))
                    for ang in _BALL:
                        u = np.array([np.cos(ang), np.sin(ang)])
                        inner.append(1 - _lookup(fg, *(pa + 0.6 * ra * u)))
                        edges.append(1 - _lookup(edge, *(pa + ra * u)))
            k = feats.n_samples[v]
            covered = np.zeros(k, bool)
            for p_i, p in enumerate(feats.samples[v, :k]):
                for s, (a, b) in enumerate(seg):
                    pa, d = pix[m, v, a], pix[m, v, b] - pix[m, v, a]
                    t = 0.0 if d @ d <= 1e-12 else np.clip((p - pa) @ d / (d @ d), 0, 1)
                    r = rad[m, v, s, 0] + t * (rad[m, v, s, 1] - rad[m, v, s, 0])
                    covered[p_i] |= np.sum((pa + t * d - p) ** 2) <= r * r
            cover = 1 - covered.mean() if k else 0.0
            total += np.mean(inner) + cover + EDGE_WEIGHT * np.mean(edges)
        out[m] = total / (len(cameras) * (2 + EDGE_WEIGHT))
    return out


@pytest.fixture(scope="module")
def scene():
    """Three small cameras, random poses around a standing body and random feature maps."""
    rng = np.random.default_rng(3)
    cams = ring_of_cameras(np.zeros(3), 2000.0, 3, (64, 48))
    base = rng.normal(0, 300, (19, 3)) * [1, 2, 1] + [0, 900, 0]
    joints = base + rng.normal(0, 60, (12, 19, 3))
    fg = rng.uniform(0, 1, (3, 48, 64)).astype(np.float32)
    fg[rng.uniform(size=fg.shape) < 0.3] = 0
    edge = rng.uniform(0, 1, (3, 48, 64)).astype(np.float32)
    samples = np.zeros((3, COVER_SAMPLES, 2))
    n = np.array([COVER_SAMPLES, 17, 0])
    for v in range(3):
        samples[v, : n[v]] = rng.integers(0, [64, 48], (n[v], 2))
    return cams, joints, ViewFeatures(fg, edge, samples, n)


def test_costs_agree_with_the_plain_reference(scene):
    cams, joints, feats = scene
    assert np.allclose(joint_costs(joints, cams, feats), _reference_costs(joints, cams, feats))


def test_costs_do_not_depend_on_the_samples_order(scene):
    cams, joints, feats = scene
    shuffled = feats.samples.copy()
    shuffled[0] = shuffled[0, ::-1]
    again = ViewFeatures(feats.fg, feats.edge, shuffled, feats.n_samples)
    assert np.array_equal(joint_costs(joints, cams, again), joint_costs(joints, cams, feats))


def test_samples_must_be_whole_pixels(scene):
    _, _, feats = scene
    with pytest.raises(ValueError, match="whole pixels"):
        ViewFeatures(feats.fg, feats.edge, feats.samples + 0.5, feats.n_samples)


def test_projection_agrees_with_each_camera(scene):
    cams, joints, _ = scene
    pix, rad, depth = project_model(joints, cams)
    seg, radii = BODY_SHAPE.segments()
    pts = BODY_SHAPE.points(joints)
    for v, c in enumerate(cams):
        p, z = c.project(pts)
        assert np.allclose(pix[:, v], p) and np.allclose(depth[:, v], z)
        assert np.allclose(rad[:, v], c.focal * radii / z[:, seg])


@pytest.mark.parametrize("scale", [3.0, 1e-4, 0.0])
def test_heading_turn_agrees_with_scipy(scale):
    rng = np.random.default_rng(1)
    rv = rng.normal(size=(50, 3)) * scale
    yaw = rng.uniform(-7, 7, 50)
    want = (Rotation.from_euler("y", yaw[:, None]) * Rotation.from_rotvec(rv)).as_rotvec()
    assert np.allclose(_turned(yaw, rv), want, atol=1e-12)


def test_survival_beta_is_the_bisection_of_the_survival_rate():
    cost = np.random.default_rng(2).uniform(0.2, 0.6, 200)

    def rate(b):
        w = np.exp(-b * (cost - cost.min()))
        return w.sum() ** 2 / (len(w) * (w**2).sum())

    beta = survival_beta(cost, 0.5)
    assert rate(beta * 0.99) > 0.5 > rate(beta * 1.01)


def _reference_features(frame: np.ndarray, bg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foreground and edge maps in plain NumPy (np.hypot of the Sobel responses)."""

    def gradient(img, sigma):
        g = cv2.GaussianBlur(img, (0, 0), sigma)
        gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
        return np.hypot(gx, cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3))

    diff = np.abs(frame.astype(np.int16) - bg.astype(np.int16)).max(axis=2).astype(np.float32)
    f = np.clip((cv2.GaussianBlur(diff, (0, 0), 1.0) - FG_LOW) / (FG_HIGH - FG_LOW), 0, 1)
    f = cv2.morphologyEx(f, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    outline = np.clip(gradient(f, 2.0) / (8 * 0.15), 0, 1)
    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY).astype(np.float32)
    near = cv2.GaussianBlur(f, (0, 0), 2.0) > 0.05
    inner = np.clip(gradient(grey, 1.0) / EDGE_CONTRAST, 0, 1) * near
    return f, cv2.GaussianBlur(np.maximum(outline, inner), (0, 0), 1.0)


def test_view_features_agree_with_the_plain_reference():
    rng = np.random.default_rng(4)
    bg = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    frame = bg.copy()
    frame[10:40, 20:35] = rng.integers(0, 256, (30, 15, 3), dtype=np.uint8)
    feats = view_features([frame], [bg])
    f, edge = _reference_features(frame, bg)
    assert np.array_equal(feats.fg[0], f) and np.array_equal(feats.edge[0], edge)
    assert edge.max() > 0.5 and f.max() == 1.0
    ys, xs = np.nonzero(f > 0.5)
    picked = feats.samples[0, : feats.n_samples[0]]
    assert set(map(tuple, picked.astype(int))) <= set(zip(xs.tolist(), ys.tolist(), strict=True))
    assert np.all(np.diff(picked[:, 1]) >= 0)

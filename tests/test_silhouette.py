"""Interaction paper §2 and §5: silhouette rendering, tracker, B-spline outlines, partner video."""

from __future__ import annotations

import numpy as np
import pytest

from markovmotion.errors import MarkovMotionError, MotionFormatError
from markovmotion.features.joint_shape import TwoPeople
from markovmotion.models.chain.partner import VirtualPartner
from markovmotion.video.bspline import (
    basis_matrix,
    evaluate_closed_bspline,
    fit_closed_bspline,
    resample_closed,
)
from markovmotion.video.partner import draw_silhouette
from markovmotion.video.render import (
    Canvas,
    background,
    read_frames,
    render_frames,
    side_camera,
    write_video,
)
from markovmotion.video.render import empty_frames as scene_frames
from markovmotion.video.tracker import SilhouetteTrack, SilhouetteTracker, track_video

RNG = np.random.default_rng(7)
COLOUR = np.array([60.0, 50.0, 120.0])
BACKGROUND = background()


def ring(cx: float, cy: float, rx: float, ry: float, n: int = 32) -> np.ndarray:
    """Control points on an ellipse, the first at the top, clockwise on screen."""
    a = -np.pi / 2 + 2 * np.pi * np.arange(n) / n
    return np.column_stack([cx + rx * np.cos(a), cy + ry * np.sin(a)])


def frame_with(shapes: list[np.ndarray], noise: float = 4.0) -> np.ndarray:
    """A noisy frame with the closed B-splines of ``shapes`` filled over the background."""
    img = BACKGROUND.astype(float)
    for control in shapes:
        canvas = Canvas(640, 480)
        canvas.polygon(evaluate_closed_bspline(control, 2048))
        alpha = canvas.coverage()[..., None] / 255.0
        img = img * (1 - alpha) + COLOUR * alpha
    return np.clip(img + RNG.normal(0, noise, img.shape), 0, 255).astype(np.uint8)


def empty_frames(k: int = 8) -> list[np.ndarray]:
    """The scene without anyone (a short clip's median would keep people who hardly move)."""
    return [frame_with([]) for _ in range(k)]


def arc_length_truth(control: np.ndarray) -> np.ndarray:
    """The control points the tracker's definition gives a shape: fit to its curve resampled
    evenly in arc length from the top."""
    return fit_closed_bspline(resample_closed(evaluate_closed_bspline(control, 4096), 128), 32)


def test_bspline_fit_recovers_control_points_of_its_own_curve():
    control = RNG.normal(0, 50, (32, 2))
    samples = evaluate_closed_bspline(control, 128)
    np.testing.assert_allclose(fit_closed_bspline(samples, 32), control, atol=1e-9)
    np.testing.assert_allclose(basis_matrix(128, 32).sum(axis=1), 1.0)
    # the curve starts centred on control point 0
    np.testing.assert_allclose(samples[0], (control[-1] + 4 * control[0] + control[1]) / 6)


@pytest.mark.parametrize("shape", [(320.3, 240.2, 100.0, 100.0), (300.6, 250.4, 60.0, 120.0)])
def test_tracker_recovers_control_points_within_a_pixel(shape):
    control = ring(*shape)
    tracker = SilhouetteTracker(n_people=1).learn_background(empty_frames())
    found, merged = tracker.track_frame(frame_with([control]))
    o = found[0]
    assert not merged
    truth = arc_length_truth(control)
    assert np.linalg.norm(o.control - truth, axis=1).max() < 1.0
    top = evaluate_closed_bspline(control, 4096)[0]
    assert np.linalg.norm(o.reference - top) < 1.0
    assert o.height == pytest.approx(np.ptp(evaluate_closed_bspline(control, 4096)[:, 1]), abs=1.0)


def test_reference_point_is_the_top_of_the_head_not_a_raised_arm():
    body = ring(300.0, 260.0, 40.0, 120.0)
    arm = ring(370.0, 150.0, 12.0, 60.0)  # higher than the head, off the centre line
    tracker = SilhouetteTracker(n_people=1).learn_background(empty_frames())
    o = tracker.track_frame(frame_with([body, arm]))[0][0]
    # separate blobs: the body is the larger; its top is the reference
    assert np.linalg.norm(o.reference - evaluate_closed_bspline(body, 4096)[0]) < 1.0


def test_two_people_left_to_right_and_cut_apart_when_they_touch():
    left, right = ring(230.0, 250.0, 45.0, 110.0), ring(410.0, 250.0, 45.0, 110.0)
    tracker = SilhouetteTracker(n_people=2).learn_background(empty_frames())
    (a, b), merged = tracker.track_frame(frame_with([right, left]))
    assert not merged and a.reference[0] < b.reference[0]
    # now they lean together and touch: one blob, split by where each was
    touching = [left + [50.0, 0.0], right - [50.0, 0.0]]
    (a2, b2), merged = tracker.track_frame(frame_with(touching))
    assert merged
    for o, c in ((a2, touching[0]), (b2, touching[1])):
        assert np.linalg.norm(o.reference - evaluate_closed_bspline(c, 4096)[0]) < 1.5
        assert o.height == pytest.approx(220.0, abs=2.0)


def test_track_video_round_trip(tmp_path):
    frames = [frame_with([ring(120.0 + 30 * t, 240.0, 40.0, 100.0)]) for t in range(12)]
    frames += empty_frames(4)
    video = write_video(frames, tmp_path / "v.mp4", 25.0)
    back = list(read_frames(video))
    assert len(back) == 16 and np.abs(back[3].astype(int) - frames[3]).mean() < 5
    tr = track_video(video, n_people=1)
    assert tr.fps == pytest.approx(25.0) and tr.n_frames == 16
    assert tr.found[:12].all() and not tr.found[12:].any()
    np.testing.assert_allclose(np.diff(tr.reference[:12, 0, 0]), 30.0, atol=1.0)
    tr.save(tmp_path / "t.npz")
    again = SilhouetteTrack.load(tmp_path / "t.npz")
    np.testing.assert_array_equal(again.control, tr.control)
    filled = again.person(0)
    np.testing.assert_array_equal(filled.reference[12:], np.repeat(tr.reference[11:12, 0], 4, 0))
    with pytest.raises(MotionFormatError):
        list(read_frames(tmp_path / "missing.mp4"))


def test_track_video_learns_the_background_from_an_empty_scene(tmp_path):
    # someone standing still through a whole clip is the median of its frames, hence no one;
    # the empty scene's video gives the background instead (what contour clips use)
    still = ring(320.0, 240.0, 40.0, 100.0)
    video = write_video([frame_with([still]) for _ in range(10)], tmp_path / "v.mp4", 25.0)
    assert not track_video(video, n_people=1).found.any()
    plate = write_video(list(scene_frames(8, seed=0)), tmp_path / "empty.mp4", 25.0)
    tr = track_video(video, n_people=1, background=plate)
    assert tr.found.all()
    top = evaluate_closed_bspline(still, 4096)[0]
    assert np.abs(tr.reference[:, 0] - top).max() < 1.5


def test_partner_drawn_black_inside_its_outline():
    control = ring(320.0, 240.0, 50.0, 100.0)
    out = draw_silhouette(BACKGROUND, control)
    assert (out[240, 320] == 0).all() and (out[240, 380] == BACKGROUND[240, 380]).all()


# ---------------------------------------------------------------------- real data
@pytest.fixture(scope="session")
def salsa_frames(mocap):
    a, b = mocap.pairs(label="salsa")[0]
    take = TwoPeople.from_motions(*mocap.load_pair(a, b), fps=25.0).trim(200, 260)
    people = [take.person(0), take.person(1)]
    camera = side_camera(people)
    return take, camera, list(render_frames(people, camera))


def test_rendered_salsa_is_tracked_at_the_projected_heads(salsa_frames):
    take, camera, frames = salsa_frames
    tracker = SilhouetteTracker(n_people=2).learn_background(empty_frames())
    heads = np.stack([camera.project(take.points[:, i, 4])[0] for i in (0, 1)], axis=1)
    errors = []
    for t, f in enumerate(frames):
        found, merged = tracker.track_frame(f)
        if not merged and None not in found:
            for o in found:
                gaps = o.reference - heads[t]
                errors.append(gaps[np.argmin(np.linalg.norm(gaps, axis=1))])
    errors = np.array(errors)
    assert len(errors) >= 40
    # the head joint is at the base of the skull; the reference point is on its top
    assert np.mean((np.abs(errors[:, 0]) < 15) & (errors[:, 1] < 0) & (errors[:, 1] > -45)) > 0.9


def test_silhouette_model_places_partner_in_the_image(salsa_frames):
    _, _, frames = salsa_frames
    tracker = SilhouetteTracker(n_people=2).learn_background(empty_frames())
    rows = [tracker.track_frame(f)[0] for f in frames]
    rows = [r for r in rows if None not in r]
    take = TwoPeople(
        np.array([[o.control for o in r] for r in rows]),
        np.array([[o.reference for o in r] for r in rows]),
        np.array([[o.height for o in r] for r in rows]),
        np.zeros((len(rows), 2)),
        25.0,
    )
    model = VirtualPartner(n_state_prototypes=12, n_behaviour_prototypes=8, n_epochs=3).fit([take])
    resp = model.respond_shapes(take.person(0), None, n_hypotheses=30)
    assert model.source == "silhouette" and len(model.train_files_) == 1
    with pytest.raises(MarkovMotionError, match="3-D"):
        model.partner()  # online partners answer motion capture
    # the partner stands on the real person's floor line, at a plausible size
    feet = resp.partner.reference[:, 1] + resp.partner.height
    np.testing.assert_allclose(feet, take.reference[:, 0, 1] + take.height[:, 0], atol=1e-6)
    assert np.all((resp.partner.height > 100) & (resp.partner.height < 300))

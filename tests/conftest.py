"""Shared fixtures: the real motion-capture collection beside the project, small synthetic motions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data import MocapIndex


@pytest.fixture(scope="session")
def mocap() -> MocapIndex:
    """The shared motion capture (../shared/data/mocap); the tests need it."""
    return MocapIndex.load()


@pytest.fixture(scope="module")
def body(mocap):
    """The tracker's body model learnt from the collection's training handshake and pull takes."""
    from markovmotion.video.multiview import training_body_model

    return training_body_model(mocap.root)


@pytest.fixture(scope="module")
def take(mocap):
    """Person A of the held-out pull take at 30 fps, and its file."""
    from markovmotion.data.splits import held_out_pairs

    _, test = held_out_pairs(mocap.pairs(label=["handshake", "pull"], kind="skeleton"))
    entry = test[0][0]
    return mocap.load_motion(entry).resample(30.0), mocap.root / entry.file


def make_skeleton() -> Skeleton:
    """A small five-joint skeleton with mixed channel orders and an end site (offsets in mm)."""
    return Skeleton(
        names=("hips", "lleg", "rleg", "spine", "spine_end"),
        parents=np.array([-1, 0, 0, 0, 3]),
        offsets=np.array([[0, 0, 0], [100, -50, 0], [-100, -50, 0], [0, 200, 0], [0, 150, 0]]),
        channels=(
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
            ("Zrotation", "Xrotation", "Yrotation"),
            ("Xrotation", "Yrotation", "Zrotation"),
            ("Yrotation", "Xrotation"),
            (),
        ),
        end_site=np.array([False, False, False, False, True]),
    )


def make_motion(n_frames: int = 40, seed: int = 0, fps: float = 30.0) -> Motion:
    """A smooth random motion of :func:`make_skeleton`."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    sk = make_skeleton()
    t = np.arange(n_frames)[:, None]
    angles = np.sin(t / 7.0 + rng.uniform(0, 6, (1, sk.n_joints * 3))) * rng.uniform(5, 60)
    quats = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True).as_quat()
    quats = quats.reshape(n_frames, sk.n_joints, 4)
    quats[:, 3] = Rotation.from_euler("YX", angles[:, 9:11], degrees=True).as_quat()
    quats[:, 4] = [0, 0, 0, 1]
    root = np.column_stack([10 * t[:, 0], 900 + 5 * np.sin(t[:, 0] / 3), 20 * t[:, 0]])
    return Motion.from_rotations(sk, quats, root, fps=fps, name="synthetic")


# ---------------------------------------------------------------- browser
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def ensure_chromium() -> None:
    """Debian's Chromium for the browser tests, else one failure naming the command that
    installs it. The tests never install it themselves (the README's test command runs
    ``scripts/install-test-browser`` first), nor skip: these are the project's own
    end-to-end tests."""
    if not CHROMIUM.exists():
        pytest.fail(
            f"the browser tests need headless Chromium at {CHROMIUM}: run "
            "scripts/install-test-browser (Debian's package 'chromium'), then the tests again",
            pytrace=False,
        )


@pytest.fixture(scope="session")
def browser():
    ensure_chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture()
def page(browser):
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    pg = context.new_page()
    errors = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    yield pg
    context.close()
    assert not errors, errors


@pytest.fixture
def real_copy(tmp_path) -> Path:
    """The real 4-view video's folder for a test to edit: its camera file a COPY (never a
    link: an edit would write through into the shared data), its other files linked one by
    one by name."""
    import shutil

    from markovmotion.data.index import data_root

    src = data_root().parent / "video" / "pose2sim_balancing"
    out = tmp_path / "video"
    out.mkdir()
    for p in src.iterdir():
        if p.name == "cameras.json":
            shutil.copy(p, out / p.name)
        else:
            (out / p.name).symlink_to(p)
    return out


@pytest.fixture
def needs_mediapipe() -> None:
    """Fails (never skips) a camera test when MediaPipe is missing."""
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        pytest.fail("the camera tests need MediaPipe: run scripts/install-camera", pytrace=False)


def streamed(partner, a) -> np.ndarray:
    """The positions a dual HMM's ``partner`` streams fed ``a`` frame by frame, the frames
    still owed at the end included: what windowed ``respond`` gives, for the tests to say."""
    shown = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    shown = [s for s in shown if s is not None] + partner.finish()
    return np.concatenate([s.positions for s in shown])


def assert_seen_streams_as_stepped(model, a) -> None:
    """A dual HMM's partner fed ``a`` seen at once (:meth:`Partner.see`, the live page's
    path) gives, frame by frame, what stepping it frame by frame gives."""
    stepped, streamed = model.partner(), model.partner()
    seen = streamed.see(a)
    assert seen is not None
    for t in range(a.n_frames):
        one, other = stepped.step(a.trim(t, t + 1)), streamed.step_seen(seen, t)
        assert (one is None) == (other is None)
        if one is not None:
            np.testing.assert_allclose(other.positions, one.positions, atol=1e-9)


def empty_scene(folder: Path, frames: int) -> Path:
    """The real 4-view video's empty-scene plates as a video of ``frames`` frames per camera,
    with its cameras.json and plates, in ``folder``: a capture with no one in view."""
    import json
    import shutil

    import cv2

    from markovmotion.data.index import data_root
    from markovmotion.viz.video import write_mp4

    real = data_root().parent / "video" / "pose2sim_balancing"
    doc = json.loads((real / "cameras.json").read_text())
    for cam in doc["cameras"]:
        plate = cv2.cvtColor(cv2.imread(str(real / cam["background"])), cv2.COLOR_BGR2RGB)
        write_mp4([plate] * frames, folder / cam["video"], doc["fps"])
        shutil.copyfile(real / cam["background"], folder / cam["background"])
    (folder / "cameras.json").write_text(json.dumps(doc))
    return folder

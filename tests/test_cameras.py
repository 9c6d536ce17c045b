"""What a camera file that reads may still get wrong, said once per command and kept in every
tracker's JSON ``notes``: no ``fps``, a video's own rate, intrinsics of another image size."""

from __future__ import annotations

import itertools
import json

import cv2
import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.data.index import data_root
from markovmotion.errors import MotionFormatError
from markovmotion.progress import new_command
from markovmotion.video.cameras import load_cameras
from markovmotion.video.render import read_frames, write_video

REAL = data_root().parent / "video" / "pose2sim_balancing"


def _edit(folder, change) -> dict:
    doc = json.loads((folder / "cameras.json").read_text(encoding="utf-8"))
    change(doc)
    (folder / "cameras.json").write_text(json.dumps(doc), encoding="utf-8")
    return doc


def _triangulate_refused(folder, capsys) -> str:
    """``track --method triangulate`` on ``folder`` exits 2; its stderr, stripped."""
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(folder), "--method", "triangulate"])
    assert exc.value.code == 2
    return capsys.readouterr().err.strip()


def _replace(link, frames, fps: float) -> None:
    """A linked video replaced by a video of its own (the link removed first: never written
    through into the shared data)."""
    link.unlink()
    write_video(frames, link, fps)


def test_a_camera_file_without_fps_takes_the_rate_its_videos_agree_on(real_copy, capsys):
    """No ``fps`` had become 25 without a word (the real 60 fps video tracked and smoothed at
    25): the videos' own headers (all 60) give it, with a note; videos that disagree, or give
    no rate (a folder of images), are one line asking for "fps"."""
    _edit(real_copy, lambda d: d.pop("fps"))
    new_command()
    notes: list[str] = []
    _, doc = load_cameras(real_copy, notes)
    assert doc["fps"] == 60.0
    assert len(notes) == 1 and 'gives no "fps": 60 fps taken from the videos' in notes[0]
    assert capsys.readouterr().err.count('no "fps"') == 1
    main(["track", "--video", str(real_copy), "--method", "triangulate", "--max-frames", "3",
          "--json"])  # fmt: skip
    run = capsys.readouterr()
    summary = json.loads(run.out)
    assert summary["video_fps"] == 60.0
    assert [n for n in summary["notes"] if 'no "fps"' in n] == notes
    assert run.err.count('no "fps"') == 1, run.err  # said once, though read three times
    frames = list(itertools.islice(read_frames(REAL / "cam1.mp4"), 3))
    _replace(real_copy / "cam1.mp4", frames, 30.0)
    err = _triangulate_refused(real_copy, capsys)
    assert len(err.splitlines()) == 1 and "cameras.json" in err, err
    assert 'no "fps"' in err and "cam0.mp4 60, cam1.mp4 30" in err and 'add "fps"' in err
    for k in range(4):  # folders of images: no header, no rate
        (real_copy / f"cam{k}.mp4").unlink()
        folder = real_copy / f"frames{k}"
        folder.mkdir()
        cv2.imwrite(str(folder / "000.png"), cv2.cvtColor(frames[0], cv2.COLOR_RGB2BGR))
    _edit(real_copy, lambda d: [c.update(video=f"frames{k}") for k, c in enumerate(d["cameras"])])
    with pytest.raises(MotionFormatError, match='no video\'s header gives one: add "fps"'):
        load_cameras(real_copy)


def _half_size_with_full_size_k(folder, frames: int = 4) -> None:
    """The real cameras said to be 136x240, their K left at 272x480 (a video resized without
    its intrinsics); camera 0's video and background image resized."""
    _edit(folder, lambda d: [c.update(width=136, height=240) for c in d["cameras"]])
    small = [
        cv2.resize(f, (136, 240), interpolation=cv2.INTER_AREA)
        for f in itertools.islice(read_frames(REAL / "cam0.mp4"), frames)
    ]
    _replace(folder / "cam0.mp4", small, 60.0)
    plate = cv2.imread(str(REAL / "cam0_background.png"))
    (folder / "cam0_background.png").unlink()
    cv2.imwrite(str(folder / "cam0_background.png"), cv2.resize(plate, (136, 240)))


def test_intrinsics_of_another_image_size_are_said_once_by_every_command(real_copy, capsys):
    """Width and height halved, K not (a new user's trial: 973 mm from the reference, and
    the note blamed the videos): each camera's principal point, at the corner of its image,
    is named with the image's size, once per command though the file is read more than
    once, and in the JSON's notes of the particle filter and of --method monocular. The real
    cameras (principal points within 6 px of the middle) get no such note."""
    notes: list[str] = []
    load_cameras(real_copy, notes)
    assert notes == []
    _half_size_with_full_size_k(real_copy)
    new_command()
    load_cameras(real_copy, notes)
    assert len(notes) == 4 and notes[0].startswith("note: cam0's principal point (132.9, 236.7)")
    assert all("of its 136x240 image" in n and "another image size" in n for n in notes)
    capsys.readouterr()
    video = str(real_copy / "cam0.mp4")
    for extra in (["--method", "monocular"], ["--particles", "10", "--layers", "1",
                  "--guide", "none"]):  # fmt: skip
        main(["track", "--video", video, "--max-frames", "3", "--json", *extra])
        run = capsys.readouterr()
        summary = json.loads(run.out)
        assert [n for n in summary["notes"] if "principal point" in n] == notes, extra
        assert run.err.count("principal point") == 4, run.err


def test_rate_and_reference_notes_reach_the_json_of_every_method(real_copy, tmp_path, capsys):
    """A camera file saying 30 over videos whose headers say 60: the four notes went to
    stderr but not into the JSON's notes (empty for triangulate, no key for monocular); a
    reference of another length than the track was compared without a word. Now every note
    printed is in the JSON too, and printed once, by every method."""
    _edit(real_copy, lambda d: d.update(fps=30.0))
    lines = (REAL / "reference_mediapipe_triangulated_mm.csv").read_text().splitlines()
    reference = tmp_path / "short.csv"
    reference.write_text("\n".join(lines[:3]) + "\n", encoding="utf-8")  # 2 rows
    for extra in (["--method", "triangulate"], ["--method", "monocular"],
                  ["--particles", "10", "--layers", "1"]):  # fmt: skip
        main(["track", "--video", str(real_copy), "--max-frames", "3", "--json",
              "--reference", str(reference), *extra])  # fmt: skip
        run = capsys.readouterr()
        notes = json.loads(run.out)["notes"]
        said = [n for n in notes if "by its own header, the camera file says 30" in n]
        assert len(said) == 4 and "cam0.mp4 is 60 fps" in said[0], (extra, notes)
        assert run.err.count("the camera file says 30") == 4, run.err
        assert "note: the reference short.csv has 2 rows and the track 3 frames" in run.err
        printed = [line for line in run.err.splitlines() if line.startswith("note:")]
        assert printed and all(line in notes for line in printed), (extra, printed, notes)


def test_every_command_says_the_camera_files_notes_anew(capsys):
    """A note said in one command is said again by the next in the same process (the tests,
    a notebook): ``cli.main`` forgets what was said; a command that reads no camera file
    imports nothing for it."""
    from markovmotion import progress
    from markovmotion.cli import main

    progress.say(["note: a camera note"], None, "cameras.json")
    assert progress.said("note: a camera note")
    main(["data", "list", "--category", "exercise"])
    assert not progress.said("note: a camera note")
    capsys.readouterr()


def _cams(folder) -> list[dict]:
    return json.loads((folder / "cameras.json").read_text(encoding="utf-8"))["cameras"]


def test_up_to_six_cameras_are_read(real_copy, capsys):
    """A fifth and sixth camera had been refused ("1 to 4 cameras") though five views track
    fine; seven are refused, the number given said: beyond six, making left and right agree
    across the views takes minutes per second of video (defaults.MAX_CAMERAS)."""
    from markovmotion.defaults import MAX_CAMERAS

    first = _cams(real_copy)
    for n in (5, 6, 7):
        extra = [dict(first[k % 4], name=f"cam{k}", video=f"cam{k}.mp4") for k in range(4, n)]
        _edit(real_copy, lambda d, extra=extra: d.update(cameras=first + extra))
        if n <= MAX_CAMERAS:
            assert len(load_cameras(real_copy)[0]) == n
        else:
            with pytest.raises(MotionFormatError, match="1 to 6 cameras, not 7"):
                load_cameras(real_copy)
    with pytest.raises(SystemExit) as stop:
        main(["track", "--video", str(real_copy), "--views", "7"])
    assert stop.value.code == 2 and "--views" in capsys.readouterr().err
    # the copies above are one camera each with their originals: said (a trial's 6-camera
    # file with two pasted twice had no word; pasted with their videos too, they are refused)
    extra = [dict(first[k], name=f"cam{k + 4}", video=f"cam{k + 4}.mp4") for k in range(2)]
    _edit(real_copy, lambda d: d.update(cameras=first + extra))
    new_command()
    notes: list[str] = []
    load_cameras(real_copy, notes)
    assert any("cam0 and cam4; cam1 and cam5 are one camera" in n for n in notes)
    # more views asked for than the file has: said, not run on fewer silently
    _edit(real_copy, lambda d: d.update(cameras=first))
    new_command()
    main(["track", "--video", str(real_copy), "--views", "6", "--method", "triangulate",
          "--max-frames", "2", "--json"])  # fmt: skip
    assert "--views 6: the camera file has 4, all used" in capsys.readouterr().err


def _inverted(doc: dict, cameras=range(4)) -> None:
    """Each named camera's R and t turned into its pose in the world (camera to world)."""
    for k in cameras:
        c = doc["cameras"][k]
        r, t = np.array(c["R"]), np.array(c["t"])
        c["R"], c["t"] = r.T.tolist(), (-r.T @ t).tolist()


def test_cameras_given_as_their_poses_in_the_world_are_named(real_copy, capsys):
    """The real cameras with R and t camera to world had been "no person found" by
    triangulation and 2800 mm from the reference at exit 0 by the particle filter: now one
    line saying so (exit 2), for two cameras too; the real ones say nothing."""
    notes: list[str] = []
    load_cameras(real_copy, notes)
    assert notes == []
    saved = json.loads((real_copy / "cameras.json").read_text(encoding="utf-8"))
    _edit(real_copy, lambda d: _inverted(d))
    with pytest.raises(MotionFormatError, match="R and t look like camera-to-world") as exc:
        load_cameras(real_copy)
    assert "wants world-to-camera (x_cam = R x_world + t)" in str(exc.value)
    with pytest.raises(SystemExit) as stop:
        main(["track", "--video", str(real_copy), "--method", "triangulate"])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and len(err.splitlines()) == 1 and "camera-to-world" in err
    _edit(real_copy, lambda d: (d.update(saved), _inverted(d, (1, 2))))  # two of them
    _edit(real_copy, lambda d: d.update(cameras=d["cameras"][1:3]))
    with pytest.raises(MotionFormatError, match="R and t look like camera-to-world"):
        load_cameras(real_copy)


def test_the_camera_files_units_are_read(real_copy, capsys):
    """``"units": "m"`` had been ignored (t in metres read as mm: 1448 mm from the reference,
    no note); now m and cm are scaled to mm, anything else refused in one line, and cameras
    a few mm apart (t in m, no units) or below the floor get a note, as `video cameras`
    gives of a calibration."""
    truth, _ = load_cameras(real_copy)
    for units, scale in (("m", 1e-3), ("cm", 0.1)):
        _edit(real_copy, lambda d, u=units, s=scale: (
            d.update(units=u), [c.update(t=[x * s for x in c["t"]]) for c in d["cameras"]]
        ))  # fmt: skip
        got, doc = load_cameras(real_copy)
        assert all(np.allclose(a.t, b.t) for a, b in zip(truth, got, strict=True)), units
        _edit(real_copy, lambda d, s=scale: [
            c.update(t=[x / s for x in c["t"]]) for c in d["cameras"]
        ])  # fmt: skip
    _edit(real_copy, lambda d: d.update(units="inch"))
    with pytest.raises(MotionFormatError, match='\'units\' is "inch": give "mm"'):
        load_cameras(real_copy)
    _edit(real_copy, lambda d: (d.pop("units"), [
        c.update(t=[x / 1000 for x in c["t"]]) for c in d["cameras"]
    ]))  # fmt: skip
    notes: list[str] = []
    new_command()
    load_cameras(real_copy, notes)
    assert len(notes) == 1 and "the cameras stand at most 7 mm from one another" in notes[0]
    assert '(t read in mm: no "units")' in notes[0]
    _edit(real_copy, lambda d: [c.update(t=[x * 1000 for x in c["t"]]) for c in d["cameras"]])
    lowered = load_cameras(real_copy)[0][1]  # cam1 3 m lower, aimed alike
    _edit(real_copy, lambda d: d["cameras"][1].update(
        t=(lowered.t + lowered.R @ [0.0, 3000.0, 0.0]).tolist()
    ))  # fmt: skip
    notes.clear()
    load_cameras(real_copy, notes)
    assert any("cam1 below the floor (world Y = 0)" in n for n in notes), notes


def test_unknown_keys_of_a_camera_file_are_named(real_copy):
    """A lens under "distorsion", a plate under "backgroud" had been dropped without a word
    (the lens: 79.5 mm for 74.5): one note naming them, where, the key meant and the known
    ones."""
    _edit(real_copy, lambda d: (
        d["cameras"][2].update(distorsion=[0.1, 0, 0, 0]), d["cameras"][1].update(backgroud="x"),
        d.update(comment="mine"),
    ))  # fmt: skip
    notes: list[str] = []
    load_cameras(real_copy, notes)
    assert len(notes) == 1, notes
    assert '"distorsion" in cameras[2] (meant "distortion"?)' in notes[0]
    assert '"backgroud" in cameras[1] (meant "background"?)' in notes[0]
    assert '"comment" in top level' in notes[0]
    assert "per camera name, video, width, height, K, R, t, distortion" in notes[0]


def test_an_image_folders_frames_are_read_by_their_numbers(tmp_path):
    """Frames named frame_1 ... frame_12 (no leading zeros) had been read as frame_1,
    frame_10, frame_11, frame_12, frame_2 ... (106.9 mm from the reference for 79.5)."""
    for k in range(1, 13):
        cv2.imwrite(str(tmp_path / f"frame_{k}.png"), np.full((16, 16, 3), 10 * k, np.uint8))
    got = [int(f[0, 0, 0]) for f in read_frames(tmp_path)]
    assert got == [10 * k for k in range(1, 13)]


def test_a_calibration_given_as_the_camera_file_says_how_to_convert_it(tmp_path):
    """``--cameras Calib.toml`` had been a bare JSON error."""
    (tmp_path / "Calib.toml").write_text('[cam_01]\nname = "cam_01"\nmatrix = [[1, 0, 0]]\n')
    (tmp_path / "Calib.qca.txt").write_text('<?xml version="1.0"?><calibration/>')
    for name in ("Calib.toml", "Calib.qca.txt"):
        with pytest.raises(MotionFormatError) as exc:
            load_cameras(tmp_path / name)
        assert f"convert it with `markovmotion video cameras {name} VIDEO...`" in str(exc.value)
    (tmp_path / "c.json").write_text("{not json")
    with pytest.raises(MotionFormatError, match="not a JSON camera file"):
        load_cameras(tmp_path / "c.json")


def test_the_videos_are_looked_for_in_the_folder_given(real_copy, tmp_path):
    """``--video DIR --cameras OTHER/cameras.json`` had looked for the videos beside the
    camera file alone: now in DIR first, then there; the error names both places."""
    from markovmotion.video.cameras import camera_file, camera_videos

    other = tmp_path / "other"
    other.mkdir()
    (real_copy / "cameras.json").rename(other / "cameras.json")
    where = camera_file(real_copy, other / "cameras.json")
    cams, _ = load_cameras(where)
    assert camera_videos(where, cams) == [(real_copy / f"cam{k}.mp4").resolve() for k in range(4)]
    (other / "cam3.mp4").symlink_to(REAL / "cam3.mp4")  # beside the file: still DIR's first
    assert camera_videos(where, cams)[3] == (real_copy / "cam3.mp4").resolve()
    (real_copy / "cam2.mp4").unlink()
    with pytest.raises(MotionFormatError) as exc:
        camera_videos(where, cams)
    assert str(exc.value).startswith(f"{real_copy / 'cam2.mp4'}: no video for camera cam2")
    assert f"here nor beside the camera file ({other / 'cam2.mp4'})" in str(exc.value)


def test_a_size_written_as_a_float_is_read_and_a_missing_one_named(real_copy):
    """``"width": 272.0`` (as Pose2Sim writes sizes) and a missing width had both been
    "width and height must be 16 to 4096"."""
    _edit(real_copy, lambda d: [c.update(width=272.0, height=480.0) for c in d["cameras"]])
    assert load_cameras(real_copy)[0][0].width == 272
    _edit(real_copy, lambda d: d["cameras"][1].pop("height"))
    with pytest.raises(MotionFormatError, match=r"cameras\[1\] has no height"):
        load_cameras(real_copy)
    _edit(real_copy, lambda d: d["cameras"][1].update(height=480.5))
    with pytest.raises(MotionFormatError, match=r"cameras\[1\].height must be a whole number"):
        load_cameras(real_copy)


def test_two_cameras_naming_one_video_are_refused_and_renumbered_videos_said(real_copy, capsys):
    """cam3 naming cam2.mp4 (a camera copied, its video not edited) had been tracked, one
    view through two calibrations, with only a note on the view the others disagreed with:
    now one line naming both cameras and the video, exit 2. A camera file whose cameras and
    videos are numbered apart (camera cam1 dropped, the videos renumbered: cam2 with
    cam1.mp4) gets a note, as ``video cameras`` checks its videos' order; names numbered
    from 1 over videos from 0 (one shift for all) do not."""
    _edit(real_copy, lambda d: d["cameras"][3].update(video="cam2.mp4"))
    err = _triangulate_refused(real_copy, capsys)
    assert len(err.splitlines()) == 1, err
    assert "cameras cam2 and cam3 both name the video cam2.mp4" in err
    _edit(real_copy, lambda d: d["cameras"][3].update(video="./cam3.mp4"))
    _edit(real_copy, lambda d: d["cameras"][2].update(video="cam3.mp4"))  # the same file
    with pytest.raises(MotionFormatError, match="cameras cam2 and cam3 both name"):
        load_cameras(real_copy)

    def renumbered(doc: dict) -> None:
        doc["cameras"] = [c for c in doc["cameras"] if c["name"] != "cam1"]
        for k, c in enumerate(doc["cameras"]):
            c["video"] = f"cam{k}.mp4"

    _edit(real_copy, renumbered)
    new_command()
    notes: list[str] = []
    load_cameras(real_copy, notes)
    said = [n for n in notes if "numbers" in n]
    assert said == [
        "note: cameras.json: the cameras' numbers are not their videos' (cam2 with cam1.mp4, "
        "cam3 with cam2.mp4): is each video its camera's? (each camera is tracked with the "
        "video it names)"
    ]

    def from_one(doc: dict) -> None:
        for k, c in enumerate(doc["cameras"]):
            c["name"], c["video"] = f"int_cam0{k + 1}_img", f"cam{k}.mp4"

    _edit(real_copy, from_one)
    new_command()
    notes = []
    load_cameras(real_copy, notes)
    assert not [n for n in notes if "numbers" in n], notes


def test_a_gap_in_a_frame_folders_numbering_is_said(real_copy, capsys):
    """frame_50.png missing of frame_0 ... frame_99 had been read without a word, every
    frame after it shown one frame early: a note names the camera, the numbers missing and
    the numbering's range. Frames numbered by two, or whole, get none."""
    frames = real_copy / "frames1"
    frames.mkdir()
    image = np.zeros((16, 16, 3), np.uint8)
    for k in [*range(0, 50), *range(51, 60), *range(63, 100)]:
        cv2.imwrite(str(frames / f"frame_{k}.png"), image)
    _edit(real_copy, lambda d: d["cameras"][1].update(video="frames1"))
    new_command()
    notes: list[str] = []
    load_cameras(real_copy, notes)
    assert notes == [
        "note: cam1: frames 50, 60-62 missing from its numbering (0-99): the frames after "
        "are up to 4 early"
    ]
    assert capsys.readouterr().err.count("missing from its numbering") == 1
    for k in (50, 60, 61, 62):
        cv2.imwrite(str(frames / f"frame_{k}.png"), image)
    for k in range(1, 100, 2):  # every other frame: numbered by two, nothing missing
        (frames / f"frame_{k}.png").unlink()
    new_command()
    notes = []
    load_cameras(real_copy, notes)
    assert notes == []
    (frames / "frame_2.png").unlink()
    new_command()
    load_cameras(real_copy, notes)
    assert notes == [
        "note: cam1: frames 2 missing from its numbering (0-98): the frames after are one early"
    ]


def test_one_cameras_video_at_another_rate_than_the_others_is_refused(real_copy, capsys):
    """cam1 re-encoded at 30 fps among videos at 60 (the camera file saying 60) had been
    tracked with a note advising to "set its fps", which no rate of the file puts right for
    every view (they are paired frame by frame): one line naming the video and both rates,
    exit 2. Videos that agree with one another but not with the file keep their note. A
    command that reads one camera's video (``--method monocular`` on cam0) is not stopped by
    another camera's: that one is a note."""
    frames = list(itertools.islice(read_frames(REAL / "cam1.mp4"), 3))
    _replace(real_copy / "cam1.mp4", frames, 30.0)
    err = _triangulate_refused(real_copy, capsys)
    assert len(err.splitlines()) == 1, err
    assert "cam1.mp4 is 30 fps by its own header, the other views 60: resample it to 60" in err
    main(["track", "--video", str(real_copy / "cam0.mp4"), "--method", "monocular",
          "--max-frames", "3", "--json"])  # fmt: skip
    err = " ".join(capsys.readouterr().err.split())
    assert "cam1.mp4 is 30 fps by its own header, the camera file says 60" in err
    cams, _ = load_cameras(real_copy, paired=False)
    assert len(cams) == 4
    _edit(real_copy, lambda d: d.update(fps=30.0))  # the file agreeing with the odd one
    with pytest.raises(MotionFormatError, match="cam1.mp4 is 30 fps .* the other views 60"):
        load_cameras(real_copy)


def test_the_default_method_refuses_views_at_rates_of_their_own_in_one_line(real_copy, capsys):
    """``--method auto`` (the default) of ``track`` and ``dualhmm respond --video`` on cam1
    re-encoded at 30 fps among videos at 60: the one line of the tracker that reads every
    view, as with ``--method triangulate`` (the method's choice had read the camera file and
    said its note on cam1 first: two lines)."""
    frames = list(itertools.islice(read_frames(REAL / "cam1.mp4"), 3))
    _replace(real_copy / "cam1.mp4", frames, 30.0)
    for args in (
        ["track", "--video", str(real_copy)],
        ["dualhmm", "respond", "--model", str(real_copy / "partner.npz"), "--video",
         str(real_copy), "--out", str(real_copy / "composite.mp4")],
    ):  # fmt: skip
        new_command()
        with pytest.raises(SystemExit) as exc:
            main(args)
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and len(err.splitlines()) == 1, err
        assert "cam1.mp4 is 30 fps by its own header, the other views 60" in err


def test_one_view_of_the_particle_filter_notes_another_cameras_rate(real_copy, capsys):
    """cam1 re-encoded at 30 fps among videos at 60: the particle filter on cam0's video
    alone (a lone video, or --views 1) reads no other view, so cam1's rate is a note, as
    for --method monocular (it had been the refusal, after that note: two lines)."""
    frames = list(itertools.islice(read_frames(REAL / "cam1.mp4"), 3))
    _replace(real_copy / "cam1.mp4", frames, 30.0)
    small = ["--particles", "10", "--layers", "1", "--max-frames", "2", "--json"]
    for video, extra in ((real_copy / "cam0.mp4", []), (real_copy, ["--views", "1"])):
        new_command()
        main(["track", "--video", str(video), *extra, *small, "--out",
              str(real_copy / "a.bvh")])  # fmt: skip
        run = capsys.readouterr()
        said = "note: cam1.mp4 is 30 fps by its own header, the camera file says 60"
        assert json.loads(run.out)["views"] == 1 and run.err.count(said) == 1, run.err


def test_a_track_cut_by_a_short_video_offers_no_reference_rate(real_copy, capsys):
    """cam2 cut to 3 frames stops the particle filter there (said); the reference's note had
    then guessed "if both span the same time, the reference is at 2e+03 fps", a rate that
    is no one's: the rows and frames are given, the guess not, as when --max-frames cut it."""
    reference = REAL / "reference_mediapipe_triangulated_mm.csv"
    _replace(real_copy / "cam2.mp4", list(itertools.islice(read_frames(REAL / "cam2.mp4"), 3)), 60)
    main(["track", "--video", str(real_copy), "--particles", "10", "--layers", "1", "--guide",
          "none", "--reference", str(reference), "--json"])  # fmt: skip
    run = capsys.readouterr()
    assert "if both span the same time" not in run.err
    summary = json.loads(run.out)
    said = [n for n in summary["notes"] if "the reference" in n]
    assert len(said) == 1 and "has 100 rows and the track 3 frames" in said[0], said
    assert summary["frames"] == 3 and summary["ended_early"] == ["cam2.mp4"]


def test_a_damaged_frame_and_a_reflected_r_are_one_plain_line(real_copy, tmp_path, capfd):
    """A damaged PNG frame had its one line preceded by OpenCV's own "[ERROR:0@3.671] global
    grfmt_png.cpp ... IHDR chunk shall be first"; an R with determinant -1 was "not a
    rotation matrix" without saying why (it is orthonormal: a reflection)."""
    cv2.imwrite(str(tmp_path / "frame_0.png"), np.zeros((16, 16, 3), np.uint8))
    (tmp_path / "frame_1.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    with pytest.raises(MotionFormatError, match="frame_1.png: not an image"):
        list(read_frames(tmp_path))
    err = capfd.readouterr().err
    assert "grfmt_png" not in err and "[ERROR" not in err, err
    flip = np.diag([1.0, 1.0, -1.0])
    _edit(real_copy, lambda d: d["cameras"][2].update(R=(flip @ d["cameras"][2]["R"]).tolist()))
    with pytest.raises(MotionFormatError) as exc:
        load_cameras(real_copy)
    said = "cameras[2].R is not a rotation matrix (a reflection: determinant -1)"
    assert str(exc.value).endswith(said)

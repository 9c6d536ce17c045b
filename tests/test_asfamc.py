"""ASF/AMC reading: hand-computed kinematics, CMU files against the Acclaim formula, BVH round trips."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from markovmotion import MotionFormatError, read_motion, write_motion
from markovmotion.io.asfamc import read_amc, read_asf

INCH = 25.4

# A small figure exercising what CMU's files leave out: units of half inches and
# radians, a root animating a subset of channels, a bone without dof (s), a bone
# frame turned about Z (b), a dof order other than xyz (c), a non-unit direction,
# and a hierarchy listed child first.
ASF = """\
# test skeleton
:version 1.10
:name test
:units
  mass 1.0
  length 0.5
  angle rad
:documentation
  not used
:root
   order TX TY TZ RY
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name s
     direction 0 0 2
     length 1
     axis 0 0 0 XYZ
  end
  begin
     id 2
     name a
     direction 1 0 0
     length 2
     axis 0 0 0 XYZ
     dof rz
     limits (-3.2 3.2)
  end
  begin
     id 3
     name b
     direction 1 0 0
     length 1
     axis 0 0 1.5707963267948966 XYZ
     dof rx
  end
  begin
     id 4
     name c
     direction 1 0 0
     length 1
     axis 0 0 0 XYZ
     dof rz rx
     limits (-3.2 3.2)
            (-3.2 3.2)
  end
:hierarchy
  begin
    a b
    root s c
    s a
  end
"""

AMC = """\
# test motion
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0
s
a 90
b 90
c 90 90
2
root 0 0 0 90
a 0
b 0
c 0 0
"""

U = 2 * INCH  # mm per file unit (length 0.5)


@pytest.fixture
def small(tmp_path) -> Path:
    (tmp_path / "t.asf").write_text(ASF)
    (tmp_path / "t_01.amc").write_text(AMC)
    return tmp_path / "t_01.amc"


def test_an_amc_not_named_as_cmus_takes_the_only_asf_beside_it(small):
    """``walk.amc`` beside one ASF (``t.asf``) is read with it, as ``t_01.amc`` is; with
    two ASF files there, one line says it cannot tell which and how to name it."""
    other = small.with_name("forward walk.amc")
    other.write_text(small.read_text())
    np.testing.assert_array_equal(
        read_amc(other, fps=30).rotations, read_amc(small, fps=30).rotations
    )
    (small.parent / "u.asf").write_text((small.parent / "t.asf").read_text())
    with pytest.raises(MotionFormatError, match="not named SUBJECT_TRIAL.amc and 2 ASF files"):
        read_amc(other, fps=30)
    assert read_amc(small, fps=30).n_frames  # CMU's naming still finds t.asf


def test_small_figure_hand_computed(small):
    m = read_amc(small, fps=30)
    sk = m.skeleton
    assert sk.names == ("root", "a", "b", "b_end", "c", "c_end")  # s has no dof: no joint
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition") + (
        "Zrotation",
        "Xrotation",
        "Yrotation",
    )
    assert m.fps == 30 and m.n_frames == 2
    pos = {n: m.positions()[:, sk.index(n)] for n in sk.names}
    root = np.array([1, 2, 3]) * U
    # frame 1: s goes +Z one unit; a turns 90 deg about Z, so it points +Y (2 units);
    # b's frame is turned 90 deg about Z, so its rx is a turn about Y: its +X points
    # -Z, then a's turn leaves -Z alone; c turns about Z then X: +X -> +Y -> +Z.
    np.testing.assert_allclose(pos["root"][0], root, atol=1e-9)
    np.testing.assert_allclose(pos["a"][0], root + [0, 0, U], atol=1e-9)
    np.testing.assert_allclose(pos["b"][0], root + [0, 2 * U, U], atol=1e-9)
    np.testing.assert_allclose(pos["b_end"][0], root + [0, 2 * U, 0], atol=1e-9)
    np.testing.assert_allclose(pos["c_end"][0], root + [0, 0, U], atol=1e-9)
    # frame 2: only the root turns, 90 deg about Y (+Z -> +X, +X -> -Z)
    np.testing.assert_allclose(pos["a"][1], [U, 0, 0], atol=1e-9)
    np.testing.assert_allclose(pos["b"][1], [U, 0, -2 * U], atol=1e-9)
    np.testing.assert_allclose(pos["b_end"][1], [U, 0, -3 * U], atol=1e-9)
    np.testing.assert_allclose(pos["c_end"][1], [0, 0, -U], atol=1e-9)


def test_radians_in_the_amc(small):
    text = AMC.replace(":DEGREES", ":RADIANS").replace(" 90", f" {np.pi / 2!r}")
    small.write_text(text)
    radians = read_amc(small, asf=small.parent / "t.asf")
    small.write_text(AMC)
    np.testing.assert_allclose(read_amc(small).positions(), radians.positions(), atol=1e-9)


def test_small_figure_bvh_round_trip(small, tmp_path):
    m = read_amc(small)
    write_motion(m, tmp_path / "t.bvh")
    back = read_motion(tmp_path / "t.bvh", fps=m.fps)
    assert back.skeleton.names == m.skeleton.names
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)


# ---------------------------------------------------------------- CMU files
def acclaim_fk(asf: Path, amc: Path) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Bone starts and tips (F, 3) in mm by the Acclaim formula as CMU's viewer computes it.

    Written from the file text independently of the reader: C = Rz Ry Rx of the
    axis angles, M = Rz Ry Rx of the dof angles (CMU lists dof in x, y, z order),
    tip = parent tip + (G_parent C M C^-1) direction length (direction made unit:
    CMU's carry six digits).
    """
    scale = INCH / 0.45
    bones, children, block = {}, {}, None
    section = None
    for line in asf.read_text().splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0].startswith(":"):
            section = tok[0]
        elif section == ":bonedata" and tok[0] == "begin":
            block = {}
        elif section == ":bonedata" and tok[0] == "end":
            bones[block["name"]] = block
        elif section == ":bonedata" and tok[0] in ("name", "direction", "length", "axis", "dof"):
            block[tok[0]] = tok[1] if tok[0] == "name" else tok[1:]
        elif section == ":hierarchy" and tok[0] not in ("begin", "end"):
            children.setdefault(tok[0], []).extend(tok[1:])
    frames: list[dict[str, list[float]]] = []
    with gzip.open(amc, "rt") as fh:
        for line in fh:
            tok = line.split()
            if not tok or tok[0].startswith((":", "#")):
                continue
            if tok[0].isdigit():
                frames.append({})
            else:
                frames[-1][tok[0]] = [float(v) for v in tok[1:]]
    root = np.array([f["root"] for f in frames])
    tips = {"root": root[:, :3] * scale}
    starts = dict(tips)
    glob = {"root": Rotation.from_euler("xyz", root[:, 3:], degrees=True)}
    stack = ["root"]
    while stack:
        parent = stack.pop()
        for name in children.get(parent, []):
            b = bones[name]
            c = Rotation.from_euler("xyz", [float(v) for v in b["axis"][:3]], degrees=True)
            angles = np.zeros((len(frames), 3))
            for k, d in enumerate(b.get("dof", [])):
                angles[:, "xyz".index(d[1])] = [f[name][k] for f in frames]
            m = Rotation.from_euler("xyz", angles, degrees=True)
            glob[name] = glob[parent] * c * m * c.inv()
            direction = np.array([float(v) for v in b["direction"]])
            vector = direction / np.linalg.norm(direction) * float(b["length"][0]) * scale
            starts[name] = tips[parent]
            tips[name] = tips[parent] + glob[name].apply(vector)
            stack.append(name)
    return starts, tips


CMU = ["02/02_01", "02/02_05", "03/03_01"]


@pytest.fixture(scope="module")
def cmu(mocap):
    """(motion, (Acclaim starts, tips)) of a walk, a punching routine and an uneven-terrain walk."""
    out = {}
    for trial in CMU:
        amc = mocap.root / "cmu" / "asfamc" / f"{trial}.amc.gz"
        asf = amc.with_name(trial.split("/")[0] + ".asf")
        out[trial] = (read_amc(amc), acclaim_fk(asf, amc))
    return out


@pytest.mark.parametrize("trial", CMU)
def test_cmu_forward_kinematics_matches_acclaim_formula(cmu, trial):
    """Joints sit at their bone's start, end sites at their bone's tip."""
    motion, (starts, tips) = cmu[trial]
    sk = motion.skeleton
    pos = motion.positions()
    for j, name in enumerate(sk.names):
        expected = tips[name.removesuffix("_end")] if sk.end_site[j] else starts[name]
        np.testing.assert_allclose(pos[:, j], expected, atol=1e-4, err_msg=name)


@pytest.mark.parametrize("trial", CMU)
def test_cmu_bvh_round_trip_within_a_tenth_of_a_millimetre(cmu, trial, tmp_path):
    motion, _ = cmu[trial]
    write_motion(motion, tmp_path / "x.bvh")
    back = read_motion(tmp_path / "x.bvh", fps=120)
    assert back.n_frames == motion.n_frames
    assert back.skeleton.names == motion.skeleton.names
    assert np.abs(back.positions() - motion.positions()).max() < 0.1


def test_cmu_walk_is_an_upright_walk(cmu):
    motion, _ = cmu["02/02_01"]
    sk = motion.skeleton
    pos = motion.positions()
    y = pos[..., 1]
    ground = y.min()
    # the pelvis about 0.9-1.05 m up, the head over it in every frame
    assert 850 < np.median(y[:, 0] - ground) < 1050
    assert np.all(y[:, sk.index("head")] > y[:, 0] + 400)
    assert np.all(y[:, sk.index("thorax")] > y[:, 0])
    # each foot reaches the ground and swings clear of it
    for toe in ("ltoes", "rtoes"):
        assert y[:, sk.index(toe)].min() - ground < 40
        assert y[:, sk.index(toe)].max() - ground > 80
    # bones keep their length in every frame
    for j in range(1, sk.n_joints):
        length = np.linalg.norm(pos[:, j] - pos[:, sk.parents[j]], axis=1)
        np.testing.assert_allclose(length, np.linalg.norm(sk.offsets[j]), atol=1e-6)
    # the body faces where it walks
    travel = pos[-1, 0] - pos[0, 0]
    assert np.hypot(travel[0], travel[2]) > 2000
    heading = np.degrees(np.angle(np.exp(1j * motion.heading(pos)).mean()))
    assert abs(heading - np.degrees(np.arctan2(travel[0], travel[2]))) < 10


def test_cmu_knee_is_a_hinge_bending_backwards(cmu, mocap):
    """ltibia's one dof (rx) is the knee's flexion: the thigh-shin angle is 180 - rx."""
    motion, _ = cmu["02/02_01"]
    with gzip.open(mocap.root / "cmu" / "asfamc" / "02" / "02_01.amc.gz", "rt") as fh:
        rx = np.array([float(ln.split()[1]) for ln in fh if ln.startswith("ltibia ")])
    sk = motion.skeleton
    pos = motion.body_centred_positions()  # facing +Z
    hip, knee, ankle = (sk.index(n) for n in ("lfemur", "ltibia", "lfoot"))
    thigh, shin = pos[:, hip] - pos[:, knee], pos[:, ankle] - pos[:, knee]
    cos = (
        np.sum(thigh * shin, axis=1) / np.linalg.norm(thigh, axis=1) / np.linalg.norm(shin, axis=1)
    )
    np.testing.assert_allclose(np.degrees(np.arccos(cos)), 180 - rx, atol=0.01)
    bent = rx > 30
    assert bent.sum() > 50
    # the shin folds backwards: with the thigh up (+Y) and facing +Z, a shin towards
    # -Z gives thigh x shin along -X
    assert np.all(np.cross(thigh, shin)[bent, 0] < 0)


def test_cmu_units(mocap):
    sk = read_asf(mocap.root / "cmu" / "asfamc" / "02" / "02.asf")
    # ltibia sits at the tip of lfemur, 7.59371 units = 7.59371 / 0.45 inches long
    ltibia = sk.index("ltibia")
    assert np.linalg.norm(sk.offsets[ltibia]) == pytest.approx(7.59371 / 0.45 * INCH)
    assert sk.body_root == 0


# ------------------------------------------------------------ malformed input
def _line_of(text: str, line: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), 1) if ln.strip() == line)


BAD_AMC = {
    "unknown bone": (AMC.replace("a 90", "q 90"), "unknown bone 'q'", "q 90"),
    "too few values": (AMC.replace("c 90 90", "c 90"), "has 1 values", "c 90"),
    "too many values": (AMC.replace("b 90", "b 90 1"), "has 2 values", "b 90 1"),
    "non-numeric": (AMC.replace("b 90", "b x9"), "non-numeric", "b x9"),
    "nan": (AMC.replace("b 90", "b nan"), "NaN or infinite", "b nan"),
    "inf": (AMC.replace("a 0", "a -inf"), "NaN or infinite", "a -inf"),
    "missing frame": (AMC.replace("\n2\n", "\n3\n"), "frames missing", "3"),
    "truncated": (AMC[: AMC.index("c 0 0")], "lacks c", "2"),
    "bone twice": (AMC.replace("b 90", "b 90\nb 90"), "twice", None),
    "zero frames": (AMC[: AMC.index("1\n")], "zero frames", None),
    "empty": ("", "empty", None),
    "values before a frame": (AMC.replace(":DEGREES\n1\n", ":DEGREES\n"), "before the first", None),
}


@pytest.mark.parametrize("problem", sorted(BAD_AMC))
def test_malformed_amc(small, problem):
    text, message, line_text = BAD_AMC[problem]
    small.write_text(text)
    with pytest.raises(MotionFormatError, match=message) as info:
        read_motion(small)
    assert info.value.path == str(small)
    if line_text is not None:
        assert info.value.line == _line_of(text, line_text)


BAD_ASF = {
    "no hierarchy": (ASF[: ASF.index(":hierarchy")], "no ':hierarchy'"),
    "no bonedata": (ASF.replace(":bonedata", ":bones"), "no ':bonedata'"),
    "unknown bone in hierarchy": (ASF.replace("s a\n", "s z\n"), "unknown bone 'z'"),
    "two parents": (ASF.replace("root s c", "root s c b"), "two parents"),
    "orphan": (ASF.replace("root s c", "root s"), "not in the hierarchy: c"),
    "bad number": (ASF.replace("length 2", "length two"), "needs numbers"),
    "no end": (ASF.replace("     dof rx\n  end", "     dof rx\n"), "'begin' inside"),
    "unknown dof": (ASF.replace("dof rz rx", "dof rz rq"), "unknown dof 'rq'"),
    "bad axis order": (ASF.replace("1.5707963267948966 XYZ", "1.5 XXY"), "permutation"),
    "bad units": (ASF.replace("length 0.5", "length -1"), "positive"),
    "bad angle unit": (ASF.replace("angle rad", "angle grad"), "deg or rad"),
    "no length": (ASF.replace("     length 2\n", ""), "direction and a length"),
    "root order": (ASF.replace("TX TY TZ RY", "TX TY TQ"), "unknown root order"),
    "cycle": (ASF.replace("root s c", "root c\n    b s"), "not connected to the root"),
}


@pytest.mark.parametrize("problem", sorted(BAD_ASF))
def test_malformed_asf(small, problem):
    text, message = BAD_ASF[problem]
    asf = small.parent / "t.asf"
    asf.write_text(text)
    with pytest.raises(MotionFormatError, match=message) as info:
        read_motion(small)
    assert info.value.path == str(asf)


def test_missing_skeleton_is_named(tmp_path):
    amc = tmp_path / "07_01.amc"
    amc.write_text(AMC)
    with pytest.raises(MotionFormatError, match="07.asf"):
        read_motion(amc)
    with pytest.raises(MotionFormatError, match="SUBJECT_TRIAL"):
        read_amc(tmp_path / "walk.amc")

"""Acclaim ASF (skeleton) and AMC (motion) reading: CMU's native format.

Units: ``:units length L`` says that one ASF length unit is ``1 / L`` inches
(CMU writes ``length 0.45``: a file value ``v`` is ``v / 0.45`` inches, so
``v / 0.45 * 25.4`` mm). Root translations in the AMC use the same unit. Angles
are degrees or radians as ``:units angle`` says (the AMC's ``:DEGREES`` or
``:RADIANS`` line overrides it for the motion).

Rotations follow the Acclaim (and CMU viewer) convention. A bone's ``axis a b c
XYZ`` is its local frame C, built by rotating about the listed axes in the
listed order (``XYZ``: C = Rz(c) Ry(b) Rx(a)); the AMC angles of its ``dof``
build M in the same way in their listed order (``dof rx ry rz``: M = Rz Ry Rx).
The bone's rotation relative to its parent, in world-aligned axes, is the local
rotation L = C M C^-1; the root's C comes from its ``orientation`` in its
``axis`` order, its M from the rotations in ``order``.

Acclaim bones map to BVH-style joints as follows: the root is a joint at the
AMC root translation (its rest offset is the ASF root ``position``, which the
AMC values replace as BVH position channels do); each bone with a ``dof`` is a joint at the bone's start
(its parent bone's tip, or the root) rotating by L, whose children sit at
offset ``direction x length`` from it; a bone with no child bone ends in an end
site ``<bone>_end`` at its tip. A bone without ``dof`` never rotates, so it is
no joint: its vector is added to its children's offsets (CMU's ``lhipjoint``
and ``rhipjoint`` would otherwise be joints at the pelvis centre; this way the
femurs are the hip joints). Forward kinematics of the result puts every bone
tip where the Acclaim formula tip = start + (L_root ... L_bone) (direction x
length) does. Since C M C^-1 is in general no Euler product of the dof's own
axes, every rotating joint gets the three channels ``Zrotation Xrotation
Yrotation`` (the local quaternion is stored, so the BVH written from the motion
is exact).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.core.rotations import euler_to_quat, quat_multiply
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import MotionFormatError
from markovmotion.io.files import read_text
from markovmotion.limits import (
    MAX_FRAMES,
    MAX_JOINTS,
    MAX_VALUES,
    check_rate,
    exceeded,
    max_frames,
    max_joints,
    max_values,
)

CMU_FPS = 120.0
INCH_MM = 25.4
ROTATION_DOFS = ("rx", "ry", "rz")
ROOT_DOFS = ("tx", "ty", "tz") + ROTATION_DOFS
BVH_ROTATION = ("Zrotation", "Xrotation", "Yrotation")
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True)
class AsfSkeleton:
    """A parsed ASF: the BVH-style skeleton plus what reading an AMC needs.

    Attributes:
        skeleton: joints in depth-first order (root, bones, end sites).
        dofs: per joint, the AMC values in file order (``"tx"`` ... ``"rz"``);
            empty for end sites and bones without ``dof``.
        axes: (J, 4) quaternion of each joint's Acclaim frame C.
        static: bones without ``dof``, which are no joints (see the module
            docstring); AMC lines naming them carry no values.
        mm_per_unit: millimetres per ASF/AMC length unit.
        degrees: whether angles are in degrees (else radians).
    """

    skeleton: Skeleton
    dofs: tuple[tuple[str, ...], ...]
    axes: np.ndarray
    static: frozenset[str]
    mm_per_unit: float
    degrees: bool


@dataclass
class _Bone:
    name: str
    line: int
    direction: np.ndarray | None = None
    length: float | None = None
    axis: tuple[np.ndarray, str] = (np.zeros(3), "XYZ")
    dof: tuple[str, ...] = ()


class _AsfParser:
    """Section by section reading of one ASF file; errors name the file and line."""

    def __init__(self, path: str | os.PathLike[str]):
        self.path = str(path)
        self.sections: dict[str, list[tuple[int, list[str]]]] = {}
        current = None
        lines = _lines(path, read_text(path))
        for n, raw in enumerate(lines, start=1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            toks = line.split()
            if line.startswith(":"):
                current = toks[0][1:].lower()
                if current in self.sections:
                    raise self.error(f"section ':{current}' appears twice", n)
                self.sections[current] = [(n, toks[1:])] if len(toks) > 1 else []
            elif current is None:
                raise self.error(f"text before the first ':' section: {line[:40]!r}", n)
            else:
                self.sections[current].append((n, toks))
        for required in ("root", "bonedata", "hierarchy"):
            if required not in self.sections:
                if not any(ln.strip() for ln in lines):
                    raise self.error("the file is empty")
                raise self.error(f"no ':{required}' section (not an ASF file?)", len(lines))
        self.mm_per_unit, self.degrees = self._units()

    def error(self, problem: str, line: int | None = None) -> MotionFormatError:
        return MotionFormatError(self.path, problem, line)

    def numbers(self, toks: list[str], count: int, what: str, line: int) -> np.ndarray:
        if len(toks) < count:
            raise self.error(f"{what} needs {count} numbers, found {len(toks)}", line)
        try:
            values = np.array([float(t) for t in toks[:count]])
        except ValueError:
            raise self.error(f"{what} needs numbers, found {' '.join(toks)[:40]!r}", line) from None
        if not np.all(np.isfinite(values)):
            raise self.error(f"{what} is not finite", line)
        return values

    def _units(self) -> tuple[float, bool]:
        scale, degrees = INCH_MM, True
        for n, toks in self.sections.get("units", []):
            key = toks[0].lower()
            if key == "length":
                value = self.numbers(toks[1:], 1, "units length", n)[0]
                if value <= 0:
                    raise self.error(f"units length must be positive, found {value:g}", n)
                scale = INCH_MM / value
            elif key == "angle":
                unit = toks[1].lower() if len(toks) > 1 else ""
                if unit not in ("deg", "rad"):
                    raise self.error(f"units angle must be deg or rad, found {unit!r}", n)
                degrees = unit == "deg"
        return scale, degrees

    def axis_order(self, word: str, line: int) -> str:
        order = word.upper()
        if len(order) != 3 or sorted(order) != ["X", "Y", "Z"]:
            raise self.error(f"axis order must be a permutation of XYZ, found {word!r}", line)
        return order

    def frame(self, angles: np.ndarray, order: str) -> np.ndarray:
        """Quaternion of rotations about ``order``'s axes applied in that order."""
        return _extrinsic(order, angles, self.degrees)

    def root(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """The root's dof order, its frame C and its rest position (mm)."""
        dofs: list[str] = []
        order, orientation, position = "XYZ", np.zeros(3), np.zeros(3)
        for n, toks in self.sections["root"]:
            key, rest = toks[0].lower(), toks[1:]
            if key == "order":
                for word in rest:
                    dof = word.lower()
                    if dof not in ROOT_DOFS:
                        raise self.error(f"unknown root order channel {word!r}", n)
                    if dof in dofs:
                        raise self.error(f"root order channel {word!r} repeated", n)
                    dofs.append(dof)
            elif key == "axis":
                if not rest:
                    raise self.error("root axis needs an order such as XYZ", n)
                order = self.axis_order(rest[0], n)
            elif key == "orientation":
                orientation = self.numbers(rest, 3, "root orientation", n)
            elif key == "position":
                position = self.numbers(rest, 3, "root position", n) * self.mm_per_unit
        return tuple(dofs), self.frame(orientation, order), position

    def bones(self) -> dict[str, _Bone]:
        bones: dict[str, _Bone] = {}
        bone: _Bone | None = None
        last = 0
        for n, toks in self.sections["bonedata"]:
            key, rest = toks[0].lower(), toks[1:]
            last = n
            if key == "begin":
                if bone is not None:
                    raise self.error("'begin' inside a bone (missing 'end')", n)
                bone = _Bone(name="", line=n)
            elif bone is None:
                raise self.error(f"{toks[0]!r} outside a begin/end bone block", n)
            elif key == "end":
                bones[bone.name] = self._checked(bone, bones, n)
                bone = None
                if len(bones) >= max_joints():
                    raise self.error(f"the skeleton has {exceeded(MAX_JOINTS)}", n)
            elif key == "name":
                if not rest:
                    raise self.error("bone without a name", n)
                bone.name = rest[0]
            elif key == "direction":
                bone.direction = self.numbers(rest, 3, "direction", n)
            elif key == "length":
                bone.length = self.numbers(rest, 1, "length", n)[0] * self.mm_per_unit
            elif key == "axis":
                order = self.axis_order(rest[3], n) if len(rest) > 3 else "XYZ"
                bone.axis = (self.numbers(rest, 3, "axis", n), order)
            elif key == "dof":
                bone.dof = self._bone_dofs(rest, n)
        if bone is not None:
            raise self.error(f"bone block from line {bone.line} has no 'end'", last)
        if not bones:
            raise self.error("no bones in ':bonedata'")
        return bones

    def _bone_dofs(self, words: list[str], line: int) -> tuple[str, ...]:
        dofs = tuple(w.lower() for w in words)
        for dof in dofs:
            if dof in ("tx", "ty", "tz", "l"):
                raise self.error(f"dof {dof!r} on a bone is not supported (rotations only)", line)
            if dof not in ROTATION_DOFS:
                raise self.error(f"unknown dof {dof!r}", line)
        if len(set(dofs)) != len(dofs):
            raise self.error("dof repeated", line)
        return dofs

    def _checked(self, bone: _Bone, bones: dict[str, _Bone], line: int) -> _Bone:
        where = f"bone block from line {bone.line}"
        if not bone.name:
            raise self.error(f"{where} has no name", line)
        if bone.name == "root":
            raise self.error("a bone cannot be called 'root'", bone.line)
        if bone.name in bones:
            raise self.error(f"bone name {bone.name!r} used twice", bone.line)
        if bone.direction is None or bone.length is None:
            raise self.error(f"bone {bone.name!r} needs a direction and a length", line)
        norm = np.linalg.norm(bone.direction)
        if norm == 0 and bone.length != 0:
            raise self.error(f"bone {bone.name!r} has a zero direction", line)
        bone.direction = bone.direction / norm if norm > 0 else bone.direction
        return bone

    def hierarchy(self, bones: dict[str, _Bone]) -> dict[str, list[str]]:
        children: dict[str, list[str]] = {"root": []}
        parent_of: dict[str, str] = {}
        for n, toks in self.sections["hierarchy"]:
            if toks[0].lower() in ("begin", "end"):
                continue
            for name in toks:
                if name != "root" and name not in bones:
                    raise self.error(f"unknown bone {name!r} in the hierarchy", n)
            parent, kids = toks[0], toks[1:]
            for kid in kids:
                if kid == "root":
                    raise self.error("the root cannot be a child", n)
                if kid in parent_of:
                    raise self.error(f"bone {kid!r} has two parents", n)
                parent_of[kid] = parent
            children.setdefault(parent, []).extend(kids)
        orphans = [b for b in bones if b not in parent_of]
        if orphans:
            raise self.error(f"bones not in the hierarchy: {', '.join(orphans[:5])}")
        return children


def _extrinsic(order: str, angles: np.ndarray, degrees: bool) -> np.ndarray:
    """Quaternions of rotations about ``order``'s axes applied in that order (first listed first)."""
    angles = np.asarray(angles, dtype=float)
    return euler_to_quat(order[::-1].upper(), angles[..., ::-1], degrees=degrees)


def _parse_asf(path: str | os.PathLike[str]) -> AsfSkeleton:
    asf = _AsfParser(path)
    root_dofs, root_axis, root_position = asf.root()
    bones = asf.bones()
    children = asf.hierarchy(bones)
    joints: list[tuple] = []  # (name, parent, offset, channels, end site, dofs, axis)

    def add(name, parent, offset, channels=(), end=False, dofs=(), axis=IDENTITY) -> int:
        joints.append((name, parent, offset, channels, end, dofs, axis))
        return len(joints) - 1

    position_channels = tuple(
        f"{d[1].upper()}position" for d in ("tx", "ty", "tz") if d in root_dofs
    )
    rotates = any(d in ROTATION_DOFS for d in root_dofs)
    root_channels = position_channels + (BVH_ROTATION if rotates else ())
    add("root", -1, root_position, root_channels, False, root_dofs, root_axis)
    # (bone, parent joint, the bone's start as an offset from that joint)
    stack = [(kid, 0, np.zeros(3)) for kid in reversed(children["root"])]
    reached: set[str] = set()
    while stack:
        name, parent, start = stack.pop()
        bone = bones[name]
        vector = bone.direction * bone.length
        if bone.dof:
            parent = add(name, parent, start, BVH_ROTATION, False, bone.dof, asf.frame(*bone.axis))
            start = np.zeros(3)
        kids = children.get(name, [])
        if not kids:
            add(f"{name}_end", parent, start + vector, end=True)
        stack.extend((kid, parent, start + vector) for kid in reversed(kids))
        reached.add(name)
    if len(reached) < len(bones):
        cut_off = ", ".join(sorted(set(bones) - reached)[:5])
        raise asf.error(f"bones not connected to the root (a cycle?): {cut_off}")
    names, parents, offsets, channels, end_site, dofs, axes = zip(*joints, strict=True)
    skeleton = Skeleton(
        names=names,
        parents=np.array(parents),
        offsets=np.array(offsets),
        channels=channels,
        end_site=np.array(end_site),
    )
    static = frozenset(b for b, bone in bones.items() if not bone.dof)
    return AsfSkeleton(skeleton, dofs, np.array(axes), static, asf.mm_per_unit, asf.degrees)


def read_asf(path: str | os.PathLike[str]) -> Skeleton:
    """The skeleton of an ASF file, as BVH-style joints in mm (see the module docstring).

    Raises:
        MotionFormatError: for missing or malformed sections, unknown bones,
            bones outside the hierarchy, bad numbers.
    """
    return _parse_asf(path).skeleton


def _lines(path: str | os.PathLike[str], text: str) -> list[str]:
    """``text`` split in lines, refused first if there are more than the limits allow."""
    cap = max_values() // 3 + max_frames() + 10 * max_joints()
    if text.count("\n") > cap:
        raise MotionFormatError(path, f"more than {cap} lines (limit {MAX_VALUES.env})")
    return text.splitlines()


def asf_beside(amc: str | os.PathLike[str]) -> Path:
    """The ASF of an AMC file: CMU's naming (``NN_TT.amc[.gz]`` is animated with ``NN.asf``
    in the same folder), else the folder's only ASF (a user's ``walk.amc`` beside its
    ``me.asf``)."""
    amc = Path(amc)
    named = amc.with_name(amc.name.split("_", 1)[0] + ".asf") if "_" in amc.name else None
    if named is not None and named.is_file():
        return named
    alone = sorted(p for p in amc.parent.glob("*.asf") if p.is_file())
    if len(alone) == 1:
        return alone[0]
    why = f"no {named.name} beside it" if named is not None else "not named SUBJECT_TRIAL.amc"
    found = f"{len(alone)} ASF files there" if alone else "no ASF file there"
    raise MotionFormatError(
        amc,
        f"cannot tell its skeleton: {why} and {found} (name it SUBJECT_TRIAL.amc beside "
        "SUBJECT.asf, or keep one ASF in its folder)",
    )


def _parse_amc(path: str, text: str, asf: AsfSkeleton) -> tuple[np.ndarray, bool]:
    """Values (F, C) in the skeleton's dof layout, and whether they are degrees."""
    sk = asf.skeleton
    joint_of = {name: j for j, name in enumerate(sk.names) if not sk.end_site[j]}
    joint_of.update(dict.fromkeys(asf.static, sk.n_joints))  # a slot past the joints
    n_dof = np.array([len(d) for d in asf.dofs] + [0])
    col_start = np.concatenate([[0], np.cumsum(n_dof)[:-1]])
    n_cols = int(n_dof.sum())
    degrees = asf.degrees
    frame_lines: list[int] = []
    frame_number = 0
    line_frame: list[int] = []
    line_joint: list[int] = []
    line_no: list[int] = []
    tokens: list[str] = []
    lines = _lines(path, text)
    del text
    frame_cap, value_cap = max_frames(), max_values()
    for n, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith(":"):
            if frame_lines:
                raise MotionFormatError(path, f"keyword {line[:30]!r} after the first frame", n)
            key = line.split()[0].upper()
            if key in (":DEGREES", ":RADIANS"):
                degrees = key == ":DEGREES"
            continue
        parts = line.split()
        if len(parts) == 1 and parts[0].isascii() and parts[0].isdigit():
            number = int(parts[0])
            if frame_lines and number != frame_number + 1:
                raise MotionFormatError(
                    path, f"frame {number} follows frame {frame_number} (frames missing?)", n
                )
            frame_number = number
            frame_lines.append(n)
            if len(frame_lines) > frame_cap:
                raise MotionFormatError(path, exceeded(MAX_FRAMES), n)
            continue
        if not frame_lines:
            raise MotionFormatError(path, f"{parts[0][:30]!r} before the first frame number", n)
        j = joint_of.get(parts[0])
        if j is None:
            raise MotionFormatError(path, f"unknown bone {parts[0][:30]!r}", n)
        if len(parts) - 1 != n_dof[j]:
            raise MotionFormatError(
                path, f"bone {parts[0]!r} has {len(parts) - 1} values, its dof has {n_dof[j]}", n
            )
        line_frame.append(len(frame_lines) - 1)
        line_joint.append(j)
        line_no.append(n)
        tokens.extend(parts[1:])
        if len(tokens) > value_cap:
            raise MotionFormatError(path, exceeded(MAX_VALUES), n)
    if not frame_lines:
        if not any(ln.strip() for ln in lines):
            raise MotionFormatError(path, "the file is empty")
        raise MotionFormatError(path, "the file has zero frames", len(lines))
    n_frames = len(frame_lines)
    frames, joints = np.array(line_frame, dtype=np.intp), np.array(line_joint, dtype=np.intp)
    _check_coverage(path, sk.names, frames, joints, n_dof, frame_lines, np.array(line_no))

    counts = n_dof[joints]
    try:
        values = np.array(tokens, dtype=float)
    except ValueError:
        raise _bad_token(path, tokens, np.repeat(line_no, counts)) from None
    bad = ~np.isfinite(values)
    if bad.any():
        line = int(np.repeat(line_no, counts)[np.argmax(bad)])
        raise MotionFormatError(path, "NaN or infinite value", line)
    within = np.arange(len(values)) - np.repeat(np.cumsum(counts) - counts, counts)
    flat = np.empty(n_frames * n_cols)
    flat[np.repeat(frames * n_cols + col_start[joints], counts) + within] = values
    return flat.reshape(n_frames, n_cols), degrees


def _check_coverage(
    path: str,
    names: tuple[str, ...],
    frames: np.ndarray,
    joints: np.ndarray,
    n_dof: np.ndarray,
    frame_lines: list[int],
    line_no: np.ndarray,
) -> None:
    """Every animated bone exactly once in every frame."""
    seen = np.zeros((len(frame_lines), len(n_dof)), dtype=int)
    np.add.at(seen, (frames, joints), 1)
    twice = np.argwhere((seen > 1) & (n_dof > 0))
    if len(twice):
        f, j = twice[0]
        line = int(line_no[(frames == f) & (joints == j)][1])
        raise MotionFormatError(path, f"bone {names[j]!r} appears twice in one frame", line)
    missing = np.argwhere((seen == 0) & (n_dof > 0))
    if len(missing):
        f = missing[0, 0]
        lacking = [names[j] for j in missing[missing[:, 0] == f, 1]]
        raise MotionFormatError(
            path,
            f"the frame starting here lacks {', '.join(lacking[:4])}"
            f"{' ...' if len(lacking) > 4 else ''} (truncated file?)",
            frame_lines[f],
        )


def _bad_token(path: str, tokens: list[str], token_lines: np.ndarray) -> MotionFormatError:
    for tok, line in zip(tokens, token_lines, strict=True):
        try:
            float(tok)
        except ValueError:
            return MotionFormatError(path, f"non-numeric value {tok[:20]!r}", int(line))
    return MotionFormatError(path, "unreadable values")  # pragma: no cover


def _values_to_motion(
    asf: AsfSkeleton, values: np.ndarray, degrees: bool
) -> tuple[np.ndarray, np.ndarray]:
    """AMC values (F, C) -> local quaternions C M C^-1 (F, J, 4) and translations (F, J, 3) mm."""
    sk = asf.skeleton
    f = len(values)
    trans = np.broadcast_to(sk.offsets, (f, sk.n_joints, 3)).copy()
    quats = np.zeros((f, sk.n_joints, 4))
    quats[..., 3] = 1.0
    col = 0
    for j, dofs in enumerate(asf.dofs):
        block = values[:, col : col + len(dofs)]
        col += len(dofs)
        rot = [k for k, d in enumerate(dofs) if d in ROTATION_DOFS]
        for k, d in enumerate(dofs):
            if d not in ROTATION_DOFS:
                trans[:, j, "xyz".index(d[1])] = block[:, k] * asf.mm_per_unit
        if rot:
            order = "".join(dofs[k][1] for k in rot)
            m = _extrinsic(order, block[:, rot], degrees)
            c = asf.axes[j]
            c_inv = c * np.array([-1.0, -1.0, -1.0, 1.0])
            quats[:, j] = quat_multiply(quat_multiply(c, m), c_inv)
    return quats, trans


def read_amc(
    path: str | os.PathLike[str],
    asf: str | os.PathLike[str] | None = None,
    fps: float | None = None,
) -> Motion:
    """Read an AMC motion (``.amc`` or ``.amc.gz``) with its ASF skeleton into a :class:`Motion`.

    Args:
        path: the AMC file.
        asf: its ASF file; by default ``NN.asf`` beside ``NN_TT.amc`` (CMU's naming).
        fps: frame rate (AMC files carry none): CMU's 120 by default.

    Raises:
        MotionFormatError: naming the file and line, for unknown bones, a wrong
            number of values, non-numeric or non-finite values, missing or
            repeated frames, a truncated last frame, zero frames, or a bad ASF.
    """
    skeleton = _parse_asf(asf_beside(path) if asf is None else asf)
    values, degrees = _parse_amc(str(path), read_text(path), skeleton)
    with np.errstate(all="ignore"):  # overflow is reported below, not as a warning
        quats, trans = _values_to_motion(skeleton, values, degrees)
        usable = np.isfinite(quats).all() and np.isfinite(trans).all()
    if not usable:
        raise MotionFormatError(path, "values too large to convert to a motion")
    rate = check_rate(fps, "fps") if fps is not None else CMU_FPS
    return Motion(skeleton.skeleton, quats, trans, rate, name=os.path.basename(str(path)))

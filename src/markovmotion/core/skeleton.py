"""The skeleton: joint names, parent links, rest offsets and channel layout.

Lengths are held in millimetres whatever the file unit; each reader states its
conversion. The world is Y-up (BVH and Acclaim conventions); readers of Z-up
formats rotate into it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from markovmotion.core.words import bare_name
from markovmotion.errors import SkeletonMismatchError

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
VALID_CHANNELS = POSITION_CHANNELS + ROTATION_CHANNELS


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A kinematic tree in depth-first order (every parent precedes its children).

    Attributes:
        names: joint names; end sites are joints named ``<parent>_end``.
        parents: index of each joint's parent, -1 for the root.
        offsets: (J, 3) rest translation of each joint from its parent, in mm.
        channels: per joint, the animated channels in file order (BVH names:
            ``Xposition`` ... ``Zrotation``); empty for end sites.
        end_site: per joint, whether it is a BVH ``End Site`` (a leaf with no channels).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_site: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.intp)
        offsets = np.asarray(self.offsets, dtype=float).reshape(-1, 3)
        end_site = (
            np.zeros(len(self.names), dtype=bool)
            if self.end_site is None
            else np.asarray(self.end_site, dtype=bool)
        )
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "channels", tuple(tuple(c) for c in self.channels))
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_site", end_site)
        n = len(self.names)
        if not (len(parents) == len(offsets) == len(self.channels) == len(end_site) == n):
            raise ValueError("skeleton arrays disagree on the number of joints")
        if n == 0:
            raise ValueError("a skeleton needs at least one joint")
        if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
            raise ValueError("joints must be in depth-first order with the root first")
        for chans in self.channels:
            for c in chans:
                if c not in VALID_CHANNELS:
                    raise ValueError(f"unknown channel {c!r}")

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def n_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def index(self, name: str) -> int:
        """Index of the joint called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r}") from None

    def children(self, j: int) -> list[int]:
        return [int(k) for k in np.flatnonzero(self.parents == j)]

    @cached_property
    def body_root(self) -> int:
        """The pelvis: the first joint with two or more children.

        Some files put a static joint above the pelvis (Bandai's ``joint_Root``);
        heading and body-centred coordinates are taken at this joint instead.
        """
        counts = np.bincount(self.parents[1:], minlength=self.n_joints)
        branching = np.flatnonzero(counts >= 2)
        return int(branching[0]) if len(branching) else 0

    def rotation_order(self, j: int) -> str:
        """Intrinsic Euler order of joint ``j`` as SciPy spells it (``'ZXY'``), or ``''``."""
        return "".join(c[0] for c in self.channels[j] if c in ROTATION_CHANNELS)

    def bone_lengths(self) -> np.ndarray:
        return np.linalg.norm(self.offsets, axis=1)

    def same_topology(self, other: Skeleton) -> bool:
        """Whether ``other`` has the same joints in the same tree: the same names, or names
        that differ only by a namespace (Mixamo's ``mixamorig:Hips``, a character's
        ``Beta:Hips``, ``Hips``: the same rig exported twice) where that still names each
        joint apart, as marker labels' subject prefixes are matched."""
        if not np.array_equal(self.parents, other.parents):
            return False
        if self.names == other.names:
            return True
        ours = tuple(map(bare_name, self.names))
        return ours == tuple(map(bare_name, other.names)) and len(set(ours)) == len(ours)

    def difference(self, other: Skeleton, ours: str = "expected", theirs: str = "it") -> str | None:
        """What tells ``other`` from this skeleton, in a few words, each side named: ``ours``
        this skeleton's, ``theirs`` the other (``(27 joints, the model's 27; the model's joints
        Chest, Foot_L, ... (and 17 more) are not in the input, which has mixamorig:Spine2,
        ... instead)``; it had listed both sides' names as one "joints differ"), or None when
        it has the same joints in the same tree. End sites, named after their joint, are
        listed only when nothing else differs."""
        if self.same_topology(other):
            return None

        def only(a: Skeleton, b: Skeleton, end_sites: bool) -> list[str]:
            there = set(map(bare_name, b.names))  # a namespace is no difference
            return [
                n
                for j, n in enumerate(a.names)
                if bare_name(n) not in there and a.end_site[j] == end_sites
            ]

        missing, extra = only(self, other, False), only(other, self, False)
        if not missing and not extra:
            missing, extra = only(self, other, True), only(other, self, True)

        def listed(names: list[str]) -> str:
            more = f" (and {len(names) - 5} more)" if len(names) > 5 else ""
            return ", ".join(names[:5]) + more

        one = len(missing) == 1
        absent = f"{ours} joint{'' if one else 's'} {listed(missing)} {'is' if one else 'are'} not"
        if missing and extra:
            detail = f"{absent} in {theirs}, which has {listed(extra)} instead"
        elif missing:
            detail = f"{absent} in {theirs}"
        elif extra:
            detail = f"{theirs} also has {'joint' if len(extra) == 1 else 'joints'} {listed(extra)}"
        else:
            detail = "joint order differs"
        return f"({other.n_joints} joints, {ours} {self.n_joints}; {detail})"

    def check_compatible(self, other: Skeleton, what: str = "motion") -> None:
        """Raise :class:`SkeletonMismatchError` unless ``other`` has the same joints."""
        if (differs := self.difference(other)) is not None:
            raise SkeletonMismatchError(f"the {what}'s skeleton does not match {differs}")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description (saved in model headers)."""
        return {
            "names": list(self.names),
            "parents": self.parents.tolist(),
            "offsets": self.offsets.tolist(),
            "channels": [list(c) for c in self.channels],
            "end_site": self.end_site.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Skeleton:
        return cls(
            names=tuple(d["names"]),
            parents=np.asarray(d["parents"]),
            offsets=np.asarray(d["offsets"], dtype=float),
            channels=tuple(tuple(c) for c in d["channels"]),
            end_site=np.asarray(d["end_site"], dtype=bool),
        )

"""Which takes of a mixed collection a model can learn together: by kind, then by set.

An INDEX.csv may list skeleton takes (BVH, ASF/AMC) beside markers-only takes (C3D) under
one label (the collection's ``handshake`` holds CMU skeletons and Bütepage markers). A model
learns from one kind, and within it from one skeleton (the same joints) or one marker set
(the same marker names). Every command that loads takes by label or category goes through
the two choices here, in this order:

1. :func:`choose_kind` on the index entries, before any file is read: the kind the user
   asks for (``--kind skeleton|markers``), or else the kind with more takes;
2. :func:`largest_group` on the loaded takes: the largest group that shares one skeleton
   or marker set (:func:`same_set`).

Each says what it left out and why, in one line (:func:`markovmotion.progress.note`), and
returns it, so reports can list it too.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np

from markovmotion.core.markers import Markers, find_markers
from markovmotion.core.motion import Motion
from markovmotion.data.index import Entry
from markovmotion.errors import DataNotFoundError
from markovmotion.progress import note

T = TypeVar("T")

#: The kinds of take: a skeleton's motion (BVH, ASF/AMC) or named markers (C3D).
KINDS = ("skeleton", "markers")
#: Each kind in a sentence ("the 6 two-person takes of markers only").
KIND_WORDS = {"skeleton": "skeletons", "markers": "markers only"}
#: Files named in one line before "and N more".
SHOWN = 6


def names(files: Sequence[str]) -> str:
    """Files as one short line: the first :data:`SHOWN` names, then how many more."""
    short = [f.rsplit("/", 1)[-1].split(".")[0] for f in files]
    more = f" and {len(short) - SHOWN} more" if len(short) > SHOWN else ""
    return ", ".join(short[:SHOWN]) + more


def counted(n: int, plural: str) -> str:
    """``n`` and its noun, singular for one: ``counted(1, "two-person takes")`` is "1
    two-person take"."""
    return f"{n} {plural[:-1] if n == 1 and plural.endswith('s') else plural}"


def choose_kind(
    items: Sequence[T],
    kind: str | None = None,
    what: str = "takes",
    entry: Callable[[T], Entry] = lambda x: x,  # type: ignore[assignment,return-value]
    can: Sequence[str] = KINDS,
) -> tuple[list[T], list[T]]:
    """The items of one kind (:attr:`Entry.kind` of ``entry(item)``) and those left out.

    Args:
        items: index entries, or pairs of them (``entry=lambda p: p[0]``).
        kind: the kind asked for; None: the kind with more items (ties: skeleton),
            among those the model ``can`` learn.
        what: what the items are, for messages ("two-person takes").
        can: the kinds the model learns from (the behaviour chain: skeletons only).

    Prints one line (:func:`~markovmotion.progress.note`) naming what was left out and why.

    Raises:
        ValueError: ``kind`` is not one of :data:`KINDS`.
        DataNotFoundError: no item of the kind asked for (or of any kind the model learns).
    """
    if kind is not None and kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    by_kind = {k: [x for x in items if entry(x).kind == k] for k in KINDS}
    if kind is not None and kind not in can:
        raise DataNotFoundError(
            f"this model learns from {' or '.join(can)} takes, not {kind} (--kind {can[0]})"
        )
    usable = {k: v for k, v in by_kind.items() if k in can}
    asked = kind is not None
    if kind is None:
        kind = max(usable, key=lambda k: (len(usable[k]), k == "skeleton"))
    kept = by_kind[kind]
    left = [x for x in items if entry(x).kind != kind]
    if not items:
        raise DataNotFoundError(f"no {what} among those asked for")
    if not kept:
        found = ", ".join(f"{len(v)} {k}" for k, v in by_kind.items() if v)
        raise DataNotFoundError(f"no {kind} {what} among those asked for (found: {found})")
    if left:
        of = KIND_WORDS.get(kind, kind)
        if asked:
            why = f"using the {counted(len(kept), what)} of {of} (--kind {kind})"
        elif len(usable) > 1 and all(usable.values()):
            why = (
                f"{what} of both kinds: using the {counted(len(kept), what)} of {of} "
                "(the larger group; --kind to choose)"
            )
        else:
            why = f"using the {counted(len(kept), what)} of {of} (the model learns from {of})"
        left_of = " and ".join(KIND_WORDS.get(k, k) for k in sorted({entry(x).kind for x in left}))
        note(
            f"{why}; left out {counted(len(left), what)} of {left_of}: "
            f"{names([entry(x).file for x in left])}"
        )
    return kept, left


def same_set(a: Motion | Markers, b: Motion | Markers) -> bool:
    """Whether two takes can be learnt together: skeletons of one topology, or markers of
    the same names, as markers are matched (:func:`~markovmotion.core.markers.find_markers`:
    whatever their case, ``P1:R_HAND`` as ``P2:R_HAND``)."""
    if isinstance(a, Markers) or isinstance(b, Markers):
        if not (isinstance(a, Markers) and isinstance(b, Markers)):
            return False
        if len(a.names) != len(b.names):
            return False
        found, missing = find_markers(b.names, a.names)
        return not missing and len(set(found)) == len(found)
    return a.skeleton.same_topology(b.skeleton)


def describe_set(take: Motion | Markers) -> str:
    """A take's skeleton or marker set in a few words: "31 joints (Hips ...)", "8 markers"."""
    if isinstance(take, Markers):
        return f"{len(take.names)} markers ({', '.join(take.names[:3])} ...)"
    sk = take.skeleton
    return f"{sk.n_joints} joints ({sk.names[0]} ...)"


def largest_group(
    takes: Sequence[T],
    files: Sequence[str],
    what: str = "takes",
    key: Callable[[T], Motion | Markers] = lambda x: x,  # type: ignore[assignment,return-value]
) -> tuple[list[int], list[int]]:
    """Indices of the largest group of ``takes`` sharing one skeleton or marker set
    (:func:`same_set` of ``key(take)``; ties: the first group met), and of the others.

    Prints one line naming the takes left out (``files``) and their sets.
    """
    groups: list[list[int]] = []
    for i, t in enumerate(takes):
        for g in groups:
            if same_set(key(takes[g[0]]), key(t)):
                g.append(i)
                break
        else:
            groups.append([i])
    if not groups:
        return [], []
    best = max(groups, key=len)
    left = [i for i in range(len(takes)) if i not in best]
    if left:
        sets = "; ".join(
            f"{describe_set(key(takes[g[0]]))}: {names([files[i] for i in g])}"
            for g in groups
            if g is not best
        )
        note(
            f"{what} on {len(groups)} skeletons or marker sets: using the {len(best)} on "
            f"{describe_set(key(takes[best[0]]))} (the largest group); left out {sets}"
        )
    return best, left


def never_seen(pair: tuple[Entry, Entry], take: tuple[Motion | Markers, ...]) -> list[str]:
    """The files of a two-person take whose person is never seen (markers NaN throughout)."""
    return [
        e.file
        for e, m in zip(pair, take, strict=True)
        if isinstance(m, Markers) and not np.isfinite(m.positions).any()
    ]


def recorded(
    pairs: Sequence[tuple[Entry, Entry]], takes: Sequence[tuple[Motion | Markers, ...]]
) -> list[int]:
    """Indices of the two-person ``takes`` (of ``pairs``) in which each person has a sample
    recorded; the others, a person never seen (a C3D file whose markers are NaN in every
    frame), are named in one note. A learner refuses such a take (nothing of the person to
    learn), which had stopped a whole cross-validation in a traceback."""
    keep, gone = [], []
    for i, (pair, take) in enumerate(zip(pairs, takes, strict=True)):
        empty = never_seen(pair, take)
        gone += empty
        if not empty:
            keep.append(i)
    if gone:
        note(
            "left out the two-person takes of a person never seen (every sample NaN): "
            + names(gone)
        )
    return keep

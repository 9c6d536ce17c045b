"""Which takes of an INDEX.csv a model is evaluated on: any index, without leakage.

Every family's ``evaluate --test PATH/INDEX.csv`` goes through
:func:`test_takes`: the takes of that index that fit the model (a predicate
the family gives: category, labels, skeleton) are candidates; those whose
file content the model trained on (``train_files_``, compared by SHA-256, not
by path or name) are left out and listed. If nothing remains, one line says
so (:class:`~markovmotion.errors.DataNotFoundError`, exit 2 on the command
line). Every family's JSON carries :meth:`TestTakes.report`'s two lists.

Without ``--test``, each family evaluates on the takes its model held out, in the index it
was trained on (:func:`evaluation_index`, from the model file's :func:`index_record`), not
in the default collection: a model of a user's own collection is evaluated on it.
"""

from __future__ import annotations

import functools
import os
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from markovmotion.data.index import INDEX_NAME, Entry, MocapIndex, read_entry
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.models.base import (
    Model,
    file_sha256,
    motion_content,
    same_signature,
    training_hashes,
    training_keys,
    training_signatures,
)
from markovmotion.progress import note

T = TypeVar("T", Entry, tuple)


@dataclass
class TestTakes:
    """Takes to evaluate on, and the listed takes left out because the model trained on them.

    ``takes`` are entries, or (A, B) entry pairs for two-person models.
    """

    __test__ = False  # not a pytest class

    takes: list[Any]
    left_out: list[Any] = field(default_factory=list)
    #: Files of takes left out for being of another kind (markers, skeletons) than the model
    #: learnt, when the index holds both (:func:`markovmotion.evaluate.hmm.own_kind`).
    other_kind: list[str] = field(default_factory=list)

    @staticmethod
    def _files(items: Sequence[Any]) -> list[str]:
        out: list[str] = []
        for item in items:
            for e in item if isinstance(item, tuple) else (item,):
                out.append(e.file)
        return out

    def report(self) -> dict[str, list[str]]:
        """``test_files`` and ``left_out_training_files`` (INDEX.csv file names) for a JSON,
        and ``left_out_other_kind`` when some were."""
        out = {
            "test_files": self._files(self.takes),
            "left_out_training_files": self._files(self.left_out),
        }
        if self.other_kind:
            out["left_out_other_kind"] = list(self.other_kind)
        return out


def trained_on(model: Model, entry: Entry) -> bool:
    """Whether the file of ``entry`` has the content of one of the model's training files:
    the same bytes, the same take written another way (:func:`~markovmotion.models.base.
    motion_key`: another file format's line endings, rotation order, units or axes), or the
    same take at another frame rate (:func:`~markovmotion.models.base.motion_signature`)."""
    hashes = training_hashes(model)
    if not hashes or not entry.path.is_file():
        return False
    if file_sha256(entry.path) in hashes:
        return True
    keys, signatures = training_keys(model), training_signatures(model)
    if not keys and not signatures:
        return False
    content = _entry_content(entry)
    if content is None:
        return False
    key, signature = content
    return key in keys or any(same_signature(signature, s) for s in signatures)


def _entry_content(entry: Entry) -> tuple[str, list[float]] | None:
    """:func:`~markovmotion.models.base.motion_key` and :func:`~markovmotion.models.base.
    motion_signature` of the take ``entry`` (None if it cannot be read: said where it is
    read), once per file and rate in a command."""
    st = entry.path.stat()
    return _content_of(entry, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=1024)
def _content_of(entry: Entry, mtime_ns: int, size: int) -> tuple[str, list[float]] | None:
    try:
        return motion_content(read_entry(entry))
    except MarkovMotionError:
        return None


def test_takes(
    model: Model,
    index: MocapIndex,
    candidates: Sequence[T],
    what: str = "take",
) -> TestTakes:
    """``candidates`` (entries or entry pairs of ``index`` that fit the model) minus those the
    model trained on (a pair is left out if either person's file was a training file).

    Raises:
        DataNotFoundError: nothing fits the model, or every take that does is a training take.
    """
    where = index.root / "INDEX.csv"
    if not candidates:
        raise DataNotFoundError(f"no {what} in {where} fits the model")
    missing = [f for f in TestTakes._files(candidates) if not (index.root / f).is_file()]
    if missing:  # said before any take is evaluated, not after minutes of them
        raise DataNotFoundError(
            f"{where} lists {len(missing)} file(s) that are not there: {', '.join(missing[:5])}"
            + (" ..." if len(missing) > 5 else "")
        )
    keep: list[T] = []
    left: list[T] = []
    for item in candidates:
        people = item if isinstance(item, tuple) else (item,)
        (left if any(trained_on(model, e) for e in people) else keep).append(item)
    if not keep:
        names = ", ".join(TestTakes._files(left))
        raise DataNotFoundError(
            f"every {what} of {where} that fits the model is one it trained on: {names}"
        )
    return TestTakes(keep, left)


def people_trained_on(
    model: Model, index: MocapIndex, takes: Iterable[tuple[Entry, Entry]]
) -> list[str]:
    """The pairs of people (INDEX.csv's ``subject``) of two-person ``takes`` of whom ``model``
    learnt other takes (by content hash, among ``index``'s files): an evaluation of them is
    not one on people the model has never seen, which the aims for new people ask for."""
    people = {a.subject for a, _ in takes if a.subject}
    if not people or not training_hashes(model):
        return []
    return sorted(
        {
            e.subject
            for e in index
            if e.subject in people and e.path.is_file() and trained_on(model, e)
        }
    )


def take_names(pairs: Iterable[tuple[Entry, Entry]]) -> dict[tuple[Entry, Entry], str]:
    """Each two-person take's name in every family's reports (per-take rows, plots), ``A+B``
    by file stem; the label first when two takes share stems (the Bütepage handshakes and
    waves do), and the files (paths in the index) when label and stems together still do,
    so no take hides another."""
    pairs = list(pairs)
    plain = [f"{a.name}+{b.name}" for a, b in pairs]
    labelled = [f"{a.label} {n}" for (a, _), n in zip(pairs, plain, strict=True)]
    files = [f"{a.file}+{b.file}" for a, b in pairs]
    names = [
        n if plain.count(n) == 1 else lab if labelled.count(lab) == 1 else f
        for n, lab, f in zip(plain, labelled, files, strict=True)
    ]
    return dict(zip(pairs, names, strict=True))


def index_record(index: MocapIndex) -> dict[str, str]:
    """Where an index is and what its INDEX.csv holds (SHA-256), for a model file
    (``data_index``)."""
    path = index.root / INDEX_NAME
    return {"root": str(index.root.resolve()), "sha256": file_sha256(path)}


def evaluation_index(model: Any, test: str | os.PathLike[str] | None = None) -> MocapIndex:
    """The index ``model`` is evaluated on: ``test`` (an INDEX.csv or its folder) if given,
    else the one it was trained on (its ``data_index_``, :func:`index_record`) while that
    folder is there, else the default collection."""
    if test is not None:
        return MocapIndex.load(test)
    record = getattr(model, "data_index_", None)
    root = record.get("root") if isinstance(record, dict) else None
    if isinstance(root, str) and Path(root).is_dir():
        return MocapIndex.load(root)
    index = MocapIndex.load(None)
    if isinstance(root, str) and Path(root).resolve() != index.root.resolve():
        note(
            f"the index the model was trained on ({root}) is not here: its held-out takes are "
            f"looked for in {index.root / INDEX_NAME} (give --test INDEX for others)"
        )
    return index


def jump_sizes(points: np.ndarray) -> np.ndarray:
    """(F - 1,) how far the median body point moves between consecutive frames (mm), from
    positions (F, P, 3): a cut between two unrelated poses is a large step. Both partner
    families report how much their partner jumps by it, beside the real partner's."""
    steps = np.linalg.norm(np.diff(points, axis=0), axis=-1)
    with warnings.catch_warnings():  # points unseen (NaN) left out; none seen: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(steps, axis=1)


def jump_p90(steps: Sequence[np.ndarray]) -> float | None:
    """The 90th percentile (mm, to 0.1) of frame steps (arrays of :func:`jump_sizes`) pooled,
    None if there is none."""
    pooled = np.concatenate([np.ravel(s) for s in steps]) if len(steps) else np.zeros(0)
    return round(float(np.percentile(pooled, 90)), 1) if len(pooled) else None

"""Every train/test split of the library, in one place.

No split names a file or a trial: each is a rule over the takes an INDEX.csv
lists, so a user's own index (or more pairs added to ours) splits the same way.
A model records what it trained on (``train_files_``), and evaluation on any
index leaves those takes out by content hash (:mod:`markovmotion.evaluate.takes`),
so a split here only decides what a *new* model trains on.

- :func:`held_out_last`: single-person takes (VLMM): the last take of every
  label that has two or more.
- :func:`held_out_every`: walks (gait): every ``every``-th take of each label,
  by file name.
- :func:`held_out_pairs`: two-person takes (dual HMM, behaviour chain): the
  last quarter (rounded up) of each label's pairs, by trial, for labels with
  two or more pairs (on CMU salsa: trials 12, 13 and 15 of 11).
- :func:`select_pairs`: two-person takes of some labels, with or without the
  trials a user names (``dualhmm train/evaluate --test-trials``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from markovmotion.data.index import Entry, MocapIndex
from markovmotion.errors import DataNotFoundError

Pair = tuple[Entry, Entry]

#: Walks: every TEST_EVERY-th take of each style (sorted by file) is held out.
TEST_EVERY = 4
#: Two-person takes: 1 in PAIR_TEST_EVERY (rounded up) of each label is held out.
PAIR_TEST_EVERY = 4


def held_out_last(entries: Sequence[Entry]) -> tuple[list[Entry], list[Entry]]:
    """Hold out the last take (in INDEX.csv order) of every label that has two or more.

    Returns ``(train, test)``; a label with a single take stays in training.
    """
    last: dict[str, Entry] = {}
    counts: dict[str, int] = {}
    for e in entries:
        last[e.label] = e
        counts[e.label] = counts.get(e.label, 0) + 1
    test = [e for e in entries if counts[e.label] > 1 and last[e.label] is e]
    return [e for e in entries if e not in test], test


def validation_folds(
    entries: Sequence[Entry], n_folds: int
) -> list[tuple[list[Entry], list[Entry]]]:
    """Cross-validation folds inside a training set: fold f (1-based) holds out the f-th
    take from the end (in INDEX.csv order) of every label, as :func:`held_out_last` applied
    f times; labels that run out of takes stay in training. Returns (train, validation) pairs.
    """
    folds, rest = [], list(entries)
    for _ in range(n_folds):
        _, val = held_out_last(rest)
        if not val:
            break
        folds.append(([e for e in entries if e not in val], val))
        rest = [e for e in rest if e not in val]
    return folds


def held_out_every(
    entries: Sequence[Entry], every: int = TEST_EVERY
) -> tuple[list[Entry], list[Entry]]:
    """(training, held-out) takes: every ``every``-th take of each label (by file) is held out."""
    train, test = [], []
    for label in sorted({e.label for e in entries}):
        rows = sorted((e for e in entries if e.label == label), key=lambda e: e.file)
        for i, e in enumerate(rows):
            (test if i % every == every - 1 else train).append(e)
    return train, test


def _trial_key(pair: Pair) -> tuple[int, str]:
    trial = pair[0].trial
    return (int(trial), trial) if trial.isdigit() else (10**9, trial)


def held_out_pairs(
    pairs: Sequence[Pair], every: int = PAIR_TEST_EVERY
) -> tuple[list[Pair], list[Pair]]:
    """(training, held-out) two-person takes: of each label with two or more pairs, the last
    ``ceil(n / every)`` by trial are held out."""
    test: list[Pair] = []
    for label in sorted({a.label for a, _ in pairs}):
        rows = sorted((p for p in pairs if p[0].label == label), key=_trial_key)
        if len(rows) >= 2:
            test.extend(rows[len(rows) - math.ceil(len(rows) / every) :])
    held = {id(p) for p in test}
    return [p for p in pairs if id(p) not in held], [p for p in pairs if id(p) in held]


def select_pairs(
    index: MocapIndex,
    labels: Sequence[str] | None,
    trials: Sequence[str] | None,
    held_out: bool,
) -> list[Pair]:
    """Two-person takes of ``labels``: those of ``trials`` (``held_out``) or all the others.

    Raises:
        DataNotFoundError: one line naming a label of ``labels`` that no two-person take has
            (checked for training, ``held_out=False``: a misspelt label in a list would
            otherwise be left out silently), a trial no take has, or no take at all.
    """
    pairs = index.pairs(label=labels)
    if labels is not None and not held_out:
        have = {a.label for a, _ in pairs}
        wanted = [labels] if isinstance(labels, str) else labels
        missing = [lab for lab in dict.fromkeys(wanted) if lab not in have]
        if missing and pairs:  # none at all: the message below
            known = sorted({a.label for a, _ in index.pairs()})
            raise DataNotFoundError(
                f"no two-person take is labelled {', '.join(map(repr, missing))} in "
                f"{index.root / 'INDEX.csv'} (its labels: {', '.join(known)})"
            )
    if trials is not None:
        wanted = {t.lstrip("0") for t in trials}
        unknown = wanted - {p[0].trial.lstrip("0") for p in pairs}
        if unknown:  # a mistyped test trial would otherwise leak into training
            raise DataNotFoundError(
                f"no two-person take of labels={labels or 'any'} has trial "
                f"{', '.join(sorted(unknown))} in {index.root / 'INDEX.csv'}"
            )
        pairs = [p for p in pairs if (p[0].trial.lstrip("0") in wanted) == held_out]
    if not pairs:
        known = sorted({a.label for a, _ in index.pairs()})
        raise DataNotFoundError(
            f"no two-person takes in {index.root / 'INDEX.csv'} match "
            f"labels={labels or 'any'} trials={trials or 'any'} "
            f"(its two-person labels: {', '.join(known) or 'none'})"
        )
    return pairs


def people_out(
    index: MocapIndex, pairs: Sequence[Pair], people: Sequence[str] | None
) -> list[Pair]:
    """The takes of ``pairs`` whose pair of people is one of ``people``, held out of training.

    Raises:
        DataNotFoundError: a pair of people no take has, or no take left to learn from.
    """
    if not people:
        return []
    have = {a.subject for a, _ in pairs}
    unknown = [p for p in dict.fromkeys(people) if p not in have]
    if unknown:
        raise DataNotFoundError(
            f"--test-people: no two-person take of {', '.join(map(repr, unknown))} in "
            f"{index.root / 'INDEX.csv'} (its pairs of people: "
            f"{', '.join(sorted(have - {''})) or 'none: its subject column is empty'})"
        )
    away = [p for p in pairs if p[0].subject in set(people)]
    if len(away) == len(pairs):
        raise DataNotFoundError("--test-people leaves no two-person take to learn from")
    return away

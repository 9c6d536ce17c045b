"""Choosing a model's settings by leaving pairs of people out on its training takes alone.

One mechanism for every two-person model (the dual HMM, ``dualhmm train/crossval --choose``;
the behaviour chain, ``chain train/crossval --choose``):

- :func:`parse_grid`: the settings to choose among, ``"param=v1,v2;param=v1,v2"`` (every
  combination), each value typed as the model's default (``get_params()``), plus ``roles``
  (:data:`ROLES`); ``a+b=v1,v2`` gives two parameters the same values together;
- :func:`fold_groups`: what one fold leaves out, a pair of people (INDEX.csv's ``subject``)
  when the takes come from two or more, else one take;
- :func:`choose_settings`: leave-one-group-out over the takes it is given, generic over a fit
  and a scoring function, recording every setting's error. Given an outer fold's training
  takes, it is nested cross-validation: the held-out people never take part in the choice.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from markovmotion.progress import note

#: Which roles of each two-person take a model learns: as listed (A answered by B), or
#: ``"both"`` (also with A and B swapped, :func:`both_roles`).
ROLES = ("one", "both")

T = TypeVar("T")
M = TypeVar("M")


def both_roles(takes: Sequence[tuple]) -> list[tuple]:
    """Each take ``(name, label, ..., A, B)`` and the same take with the roles swapped (B as
    person A, A as the partner): twice the people to learn a partner from, for
    interactions whose roles are alike (a handshake, a wave; not a pull)."""
    return [*takes, *((f"{t[0]} (B as A)", *t[1:-2], t[-1], t[-2]) for t in takes)]


def learnt(takes: Sequence[tuple], groups: Sequence[T], roles: str) -> tuple[list, list[T]]:
    """The takes a model with ``roles`` learns, and their groups: as they are, or with
    ``roles="both"`` each also with its roles swapped (:func:`both_roles`)."""
    if roles not in ROLES:
        raise ValueError(f"roles must be one of {', '.join(ROLES)}, got {roles!r}")
    if roles == "both":
        return both_roles(takes), [*groups, *groups]
    return list(takes), list(groups)


def grid_defaults(model: Any) -> dict[str, Any]:
    """What a grid may set: ``model``'s parameters (``get_params()``) and ``roles``."""
    return {**model.get_params(), "roles": ROLES[0]}


def parse_grid(text: str, defaults: Mapping[str, Any]) -> list[dict]:
    """Settings to choose among from ``"param=v1,v2;param=v1,v2"``: every combination.

    ``param`` is one of ``defaults`` (:func:`grid_defaults`; ``-`` or ``_``), each value of
    its default's type (int where the default is None); ``a+b=v1,v2`` sets ``a`` and ``b``
    together to each value (the chain's ``n_state_prototypes+n_behaviour_prototypes``).

    Raises:
        ValueError: one line naming the part and parameter at fault.
    """
    axes = []
    for part in (p.strip() for p in text.split(";") if p.strip()):
        names, sep, values = part.partition("=")
        tied = [n.strip().replace("-", "_") for n in names.split("+")]
        unknown = [n for n in tied if n not in defaults]
        if not sep or unknown or not tied:
            raise ValueError(
                f"{part!r}: expected PARAM=V1,V2 with PARAM one of {', '.join(sorted(defaults))}"
            )
        axis = []
        for value in (v.strip() for v in values.split(",") if v.strip()):
            setting = {}
            for name in tied:
                kind = type(defaults[name]) if defaults[name] is not None else int
                try:
                    setting[name] = kind(value)
                except ValueError:
                    raise ValueError(f"{part!r}: {name} takes {kind.__name__} values") from None
                if name == "roles" and value not in ROLES:
                    raise ValueError(f"{part!r}: roles are {', '.join(ROLES)}")
            axis.append(setting)
        if not axis:
            raise ValueError(f"{part!r}: no values")
        axes.append(axis)
    if not axes:
        raise ValueError("no settings to choose among")
    return [{k: v for s in combo for k, v in s.items()} for combo in itertools.product(*axes)]


def setting_label(settings: Mapping[str, Any]) -> str:
    """A setting as ``param=value,...``: its key in a record of errors."""
    return ",".join(f"{k}={v}" for k, v in settings.items())


def model_params(settings: Mapping[str, Any]) -> dict[str, Any]:
    """A setting's model parameters (all but ``roles``)."""
    return {k: v for k, v in settings.items() if k != "roles"}


def fold_groups(
    people: Sequence[str] | None, names: Sequence[str], choosing: bool = False
) -> list[str]:
    """Per take, what its leave-one-out fold leaves out: its pair of people (``people``,
    INDEX.csv's ``subject``) when the takes come from two or more, else the take itself
    (``names``, which must then be unique). ``choosing`` (the folds that choose settings):
    takes of one pair of people say so once (:func:`~markovmotion.progress.note`), since each
    setting is then scored on the people it learnt from, which favours settings that fit them."""
    if people is not None and len(set(people)) >= 2:
        return list(people)
    if len(set(names)) < len(names):
        raise ValueError("the takes' names must be unique (one pair of people: one take a fold)")
    if not choosing and not any(people or ()) and len(names) > 1:
        _note_once(
            "INDEX.csv's subject names no people for these takes: one take is left out at a "
            "time, so a take's people may also be in the takes it is answered from"
        )
    if choosing and people is not None and len(names) > 1:
        _note_once(
            f"the settings are chosen by leaving one take out: the takes they are chosen on "
            f"are all of one pair of people ({people[0]}), so each setting is scored on people "
            "it learnt from (a choice for new people needs two pairs or more to choose on)"
        )
    return list(names)


@functools.lru_cache(maxsize=16)
def _note_once(message: str) -> None:
    note(message)


def choose_settings(
    grid: Sequence[Mapping[str, Any]],
    groups: Sequence[Hashable],
    fit: Callable[[Mapping[str, Any], list[int]], M],
    score: Callable[[M, Mapping[str, Any], list[int]], tuple[float, float]],
    generation_only: Iterable[str] = (),
) -> dict:
    """The setting of ``grid`` with the lowest error by leave-one-group-out over the takes
    whose groups (:func:`fold_groups`) are ``groups``: takes ``0..len(groups)-1``.

    For each group left out, ``fit(setting, training take indices)`` gives a model, once per
    distinct setting of all but ``generation_only`` parameters (a setting differing only in
    how it generates reuses the fit; ``score`` applies those), and ``score(model, setting,
    held-out take indices)`` its summed error and the frames it covers. The error of a
    setting is its summed error over every fold's held-out frames divided by those frames.

    Returns ``{"settings": pick, "inner_mm": {setting_label: error (0.01)}}``.
    """
    if not grid:
        raise ValueError("no settings to choose among")
    skip = set(generation_only)
    errors, frames = np.zeros(len(grid)), np.zeros(len(grid))
    for group in dict.fromkeys(groups):
        train = [i for i, g in enumerate(groups) if g != group]
        test = [i for i, g in enumerate(groups) if g == group]
        if not train:
            raise ValueError(f"only one group ({group}): nothing to choose settings on")
        fits: dict[str, M] = {}
        for k, settings in enumerate(grid):
            key = setting_label({p: v for p, v in settings.items() if p not in skip})
            if key not in fits:
                fits[key] = fit(settings, train)
            error, n = score(fits[key], settings, test)
            errors[k] += error
            frames[k] += n
    mean = errors / np.maximum(frames, 1)
    return {
        "settings": dict(grid[int(np.argmin(mean))]),
        "inner_mm": {setting_label(s): round(float(e), 2) for s, e in zip(grid, mean, strict=True)},
    }

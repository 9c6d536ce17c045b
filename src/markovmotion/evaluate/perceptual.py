"""The three perceptual tests of the gait paper (§6) and the analysis of their answers.

Pure functions over answered :class:`~markovmotion.evaluate.store.Item` rows,
shared by the results page of ``markovmotion serve`` and by
``markovmotion evaluation report``:

| figure of the paper | function |
|---|---|
| Fig. 5, naturalness ("real" / "synthetic" / "I don't know") | :func:`naturalness` |
| Table 2, style confusion matrix, original and synthesized | :func:`confusion` |
| Table 3, recognition rate static vs displacement | :func:`recognition_rates` |
| eq. 16, recognition efficiency | :func:`efficiency` |
| §6.3, Pearson correlation of per-style recognition | :func:`style_correlation` |
| Fig. 8, resemblance score and histogram | :func:`resemblance` |
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from markovmotion.evaluate.stimuli import AVERAGE, KINDS

if TYPE_CHECKING:
    from markovmotion.evaluate.store import Item

TESTS = ("naturalness", "recognition", "resemblance")
ITEMS_PER_TEST = 10
DONT_KNOW = "dont_know"
NATURALNESS = ("real", "synthetic", DONT_KNOW)
RESEMBLANCE = (
    "nothing in common",
    "very different",
    "different",
    "slightly different",
    "identical",
)
"""Resemblance levels; the score of a level is its index, 0 to 4 (paper §6.4)."""
LABELS = {
    "real": "real",
    "synthetic": "synthetic",
    DONT_KNOW: "I don't know",
    AVERAGE: "average walk",
}


def choices(test: str, styles: Sequence[str]) -> tuple[str, ...]:
    """The answers offered in ``test``; ``styles`` are the walk styles without the average."""
    if test == "naturalness":
        return NATURALNESS
    if test == "recognition":
        return (*styles, AVERAGE, DONT_KNOW)
    if test == "resemblance":
        return tuple(str(score) for score in range(len(RESEMBLANCE) - 1, -1, -1))
    raise ValueError(f"unknown test {test!r}")


def choice_labels(test: str, styles: Sequence[str]) -> list[tuple[str, str]]:
    """``(value, text shown)`` for each answer of ``test``."""
    if test == "resemblance":
        return [(c, RESEMBLANCE[int(c)]) for c in choices(test, styles)]
    return [(c, LABELS.get(c, c)) for c in choices(test, styles)]


def _of(items: Sequence[Item], test: str, **where: Any) -> list[Item]:
    return [
        i
        for i in items
        if i.test == test
        and i.answer is not None
        and all(getattr(i, k) == v for k, v in where.items())
    ]


def _percent(count: float, total: float) -> float:
    return 100.0 * count / total if total else float("nan")


def naturalness(items: Sequence[Item]) -> dict[str, dict[str, float]]:
    """Per kind of stimulus (real, synthetic): the number of answers ``n`` and the
    percentage of each answer (paper Fig. 5)."""
    out = {}
    for kind in KINDS:
        rows = _of(items, "naturalness", kind=kind)
        out[kind] = {"n": len(rows)}
        for c in NATURALNESS:
            out[kind][c] = _percent(sum(i.answer == c for i in rows), len(rows))
    return out


@dataclass(frozen=True)
class Confusion:
    """Counts of answers (columns) per actual style (rows) in the recognition test."""

    rows: list[str]
    columns: list[str]
    counts: np.ndarray

    @property
    def percent(self) -> np.ndarray:
        """Each row in percent of the videos of that style shown (paper Table 2)."""
        total = self.counts.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, 100.0 * self.counts / np.maximum(total, 1), np.nan)


def confusion(items: Sequence[Item], styles: Sequence[str], kind: str) -> Confusion:
    """Style confusion matrix of the ``kind`` (real or synthetic) stimuli (paper Table 2)."""
    columns = list(choices("recognition", styles))
    rows = _of(items, "recognition", kind=kind)
    actual = [s for s in (*styles, AVERAGE) if any(i.style == s for i in rows)]
    counts = np.zeros((len(actual), len(columns)), dtype=int)
    for i in rows:
        if i.style in actual and i.answer in columns:
            counts[actual.index(i.style), columns.index(i.answer)] += 1
    return Confusion(actual, columns, counts)


def _correct(rows: Sequence[Item]) -> float:
    return _percent(sum(i.answer == i.style for i in rows), len(rows))


def recognition_rates(items: Sequence[Item]) -> dict[str, dict[str, float]]:
    """Percentage of correctly recognised styles per kind, static / displacement / all (Table 3)."""
    out = {}
    for kind in KINDS:
        rows = _of(items, "recognition", kind=kind)
        out[kind] = {
            "static": _correct([i for i in rows if not i.displacement]),
            "displacement": _correct([i for i in rows if i.displacement]),
            "all": _correct(rows),
            "n": len(rows),
        }
    return out


def efficiency(rate: float, n_choices: int) -> float:
    """Recognition efficiency eq. (16): achieved rate over the rate of a random choice."""
    return rate / (100.0 / n_choices)


def per_style_recognition(items: Sequence[Item], styles: Sequence[str], kind: str) -> np.ndarray:
    """Recognition rate (%) of each style for one kind of stimulus (NaN where never shown)."""
    rows = _of(items, "recognition", kind=kind)
    return np.array([_correct([i for i in rows if i.style == s]) for s in styles])


def style_correlation(items: Sequence[Item], styles: Sequence[str]) -> float:
    """Pearson correlation between the per-style recognition rates of original and
    synthesized walks (§6.3), over the styles shown in both; NaN if undefined."""
    real = per_style_recognition(items, styles, "real")
    synth = per_style_recognition(items, styles, "synthetic")
    ok = ~(np.isnan(real) | np.isnan(synth))
    if ok.sum() < 2 or np.ptp(real[ok]) == 0 or np.ptp(synth[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(real[ok], synth[ok])[0, 1])


def resemblance(items: Sequence[Item]) -> tuple[float, np.ndarray]:
    """Mean resemblance score (0 = nothing in common ... 4 = identical) and the count of
    answers at each level 0..4 (paper Fig. 8)."""
    scores = np.array([int(i.answer) for i in _of(items, "resemblance")], dtype=int)
    hist = np.bincount(scores, minlength=len(RESEMBLANCE))
    return (float(scores.mean()) if scores.size else float("nan")), hist


@dataclass
class Report:
    """Every figure of the paper's §6 recomputed from the answers."""

    styles: list[str]
    evaluators: int
    answers: dict[str, int]
    naturalness: dict[str, dict[str, float]]
    confusion: dict[str, Confusion]
    recognition: dict[str, dict[str, float]]
    chance: float
    efficiency: dict[str, float]
    per_style: dict[str, list[float]]
    correlation: float
    resemblance_score: float
    resemblance_histogram: list[int]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN becomes ``None``)."""
        d = asdict(self)
        d["confusion"] = {
            kind: {
                "rows": c.rows,
                "columns": c.columns,
                "counts": c.counts.tolist(),
                "percent": c.percent.tolist(),
            }
            for kind, c in self.confusion.items()
        }
        d["labels"] = {c: LABELS.get(c, c) for c in choices("recognition", self.styles)}
        d["resemblance_levels"] = list(RESEMBLANCE)
        return _nan_to_none(d)


def _nan_to_none(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _nan_to_none(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_nan_to_none(v) for v in x]
    if isinstance(x, float) and np.isnan(x):
        return None
    return x


def summarise(items: Sequence[Item], styles: Sequence[str]) -> Report:
    """The full analysis of the answered items; ``styles`` are the styles offered (no average)."""
    styles = list(styles)
    rec = recognition_rates(items)
    n_choices = len(choices("recognition", styles))
    score, hist = resemblance(items)
    return Report(
        styles=styles,
        evaluators=len({i.token for i in items if i.answer is not None}),
        answers={t: len(_of(items, t)) for t in TESTS},
        naturalness=naturalness(items),
        confusion={k: confusion(items, styles, k) for k in KINDS},
        recognition=rec,
        chance=100.0 / n_choices,
        efficiency={k: efficiency(rec[k]["all"], n_choices) for k in KINDS},
        per_style={k: per_style_recognition(items, styles, k).tolist() for k in KINDS},
        correlation=style_correlation(items, styles),
        resemblance_score=score,
        resemblance_histogram=hist.tolist(),
    )


CSV_COLUMNS = (
    "token",
    "test",
    "position",
    "file",
    "style",
    "kind",
    "displacement",
    "file_b",
    "answer",
)


def answers_csv(items: Sequence[Item]) -> str:
    """The answered items as CSV, one row per answer (formula-like cells quoted: :func:`csv_safe`)."""
    from markovmotion.evaluate.store import csv_safe

    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for i in items:
        if i.answer is not None:
            row = [getattr(i, c) for c in CSV_COLUMNS]
            row[CSV_COLUMNS.index("displacement")] = "yes" if i.displacement else "no"
            writer.writerow(["" if v is None else csv_safe(v) for v in row])
    return out.getvalue()

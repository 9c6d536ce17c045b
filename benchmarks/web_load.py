"""Load test of ``markovmotion serve`` on loopback: evaluators and live-partner sessions.

Builds a temporary library from real Bandai Namco walks (three styles, an
original and another take labelled "synthetic" per style, plus a normal walk as
the average model; each with and without root displacement, as in the gait
paper §6.1), starts the app with uvicorn on 127.0.0.1 in this process and the
simulated clients in another, then:

1. ``--evaluators`` (50) simulated evaluators answer at random, concurrently,
   for ``--seconds`` (30): each registers, answers its 30 items one request at a
   time, and registers again. Every accepted answer must be in the SQLite
   database (count equal); answer latency p50/p99 is reported.
2. ``--sessions`` (40) concurrent live-partner WebSocket sessions stream
   person A in a loop for ``--seconds``: frames received against the frame
   rate, stalls (no frame for 250 ms), partner latency p99, gap between frames
   p99. Twice: with a stand-in partner (A mirrored, 3 frames late; a real walk
   at 30 fps), which measures the streaming alone, then with the dual HMM's
   windowed-Viterbi partner (``--partner MODEL``, or a small one trained here
   on two CMU salsa takes) answering a third salsa take's A, resampled to 30 fps,
   served by ``--workers`` (2) processes as ``serve --workers`` runs them.

``--load`` (1) other CPU-bound processes (a busy loop each) run from before the
first phase to the end, so the load the server meets is reproducible on top of
whatever else the machine runs (print ``uptime`` beside the numbers).
``--evaluators 0`` leaves out phase 1, ``--no-stand-in`` the stand-in sessions.

    python3 benchmarks/web_load.py [--seconds S] [--evaluators N] [--sessions N] [--partner M]
        [--workers W] [--load L] [--no-stand-in]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.evaluate.stimuli import write_stimuli
from markovmotion.evaluate.store import open_results
from markovmotion.io import write_motion
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.web import create_app
from markovmotion.web.loadtest import (
    STALL_SECONDS,
    MirrorPartner,
    simulate_evaluators,
    simulate_live,
)
from markovmotion.web.server import AppOptions, running, running_workers


def build_library(folder: Path, index: MocapIndex) -> str:
    """Real walks and stimuli in ``folder``; returns the walk the stand-in sessions stream."""
    walks = {}
    for style in ("active", "elderly", "exhausted", "normal"):
        entries = [e for e in index.query(label=style, source="bandai") if "dataset-2" in e.file]
        walks[style] = [entries[0].path, entries[1].path]
    shutil.copy(walks["active"][0], folder / "walk.bvh.gz")
    write_stimuli(
        folder / "stimuli",
        {s: w[0] for s, w in walks.items() if s != "normal"},
        {**{s: w[1] for s, w in walks.items() if s != "normal"}, "average": walks["normal"][0]},
    )
    return "walk.bvh.gz"


def dual_hmm(folder: Path, index: MocapIndex, model: Path | None) -> tuple[Path, str]:
    """The dual HMM (trained on two salsa takes if no file is given) and a third take's A."""
    pairs = index.pairs(label="salsa")
    if model is None:
        train = [index.load_pair(*p) for p in pairs[:2]]
        model = folder / "dual.npz"
        DualHMM(n_states=16, n_iter=10).fit(
            [(a.trim(0, 1200), b.trim(0, 1200)) for a, b in train]
        ).save(model)
    write_motion(index.load_motion(pairs[2][0]), folder / "lib" / "salsa_a.bvh")
    return model, "salsa_a.bvh"


def _busy(seconds: float) -> None:  # pragma: no cover - a child process
    """A CPU-bound loop for at most ``seconds`` (the parent stops it sooner)."""
    deadline = time.monotonic() + seconds
    x = 0
    while time.monotonic() < deadline:
        for _ in range(100_000):
            x += 1


@contextmanager
def cpu_load(processes: int, seconds: float = 3600.0) -> Iterator[None]:
    """``processes`` busy-loop processes running while in the block (each stops by itself
    after ``seconds`` should the block never end)."""
    spawn = multiprocessing.get_context("spawn")
    procs = [spawn.Process(target=_busy, args=(seconds,), daemon=True) for _ in range(processes)]
    for proc in procs:
        proc.start()
    try:
        yield
    finally:
        for proc in procs:
            proc.terminate()
            proc.join()


def _quantile_ms(values: list[float], q: float) -> str:
    return f"{np.quantile(values, q):.1f}" if values else "-"


def live_table(live, sessions: int, seconds: float, what: str) -> Table:
    """The live sessions' measures; '-' where no session received a frame (their failure
    causes are printed below the tables)."""
    rate = f"{live.fps:.0f} fps" if live.fps else "no session started"
    t = Table(title=f"{sessions} live sessions, {what}, {rate}, {seconds:g} s each")
    t.add_column("measure")
    t.add_column("value", justify="right")
    expected = live.fps * seconds
    frames = live.frames or [0]
    t.add_row("sessions ended cleanly", f"{live.sessions - len(live.errors)} / {sessions}")
    t.add_row("frames per session (min / mean)", f"{min(frames)} / {np.mean(frames):.0f}")
    t.add_row("frames expected at the frame rate", f"{expected:.0f}")
    factor = f"{min(frames) / expected:.2f}" if expected else "-"
    t.add_row("real-time factor (received / expected)", factor)
    skipped = getattr(live, "skipped", None) or [0]  # none from a version before drops
    t.add_row(
        "frames dropped by the server, behind its clock (total / max per session)",
        f"{sum(skipped)} / {max(skipped)}",
    )
    t.add_row(f"stalls (no frame for {1000 * STALL_SECONDS:.0f} ms)", str(live.stalls))
    t.add_row("partner latency p50 (ms)", _quantile_ms(live.latency_ms, 0.5))
    t.add_row("partner latency p99 (ms)", _quantile_ms(live.latency_ms, 0.99))
    t.add_row("frame late against the stream's clock p99 (ms)", _quantile_ms(live.late_ms, 0.99))
    t.add_row("gap between frames p99 (ms)", _quantile_ms(live.gap_ms, 0.99))
    t.add_row("gap between frames max (ms)", _quantile_ms(live.gap_ms, 1.0))
    return t


def _cpu_seconds(pids: list[int]) -> float:
    """User + system CPU seconds of processes ``pids`` so far (Linux /proc; 0 elsewhere)."""
    total = 0.0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min)"


def evaluator_table(ev, n: int, stored: int) -> Table:
    """The simulated evaluators' measures."""
    t = Table(title=f"{n} simulated evaluators, {ev.seconds:.1f} s, loopback")
    t.add_column("measure")
    t.add_column("value", justify="right")
    t.add_row("evaluators registered", str(ev.evaluators))
    t.add_row("answers accepted (HTTP 200)", str(ev.answers))
    t.add_row("answers in the database", str(stored))
    t.add_row("count equal", "yes" if stored == ev.answers else "NO")
    t.add_row("errors", str(len(ev.errors)))
    t.add_row("answers per second", f"{ev.answers / ev.seconds:.0f}" if ev.seconds else "-")
    t.add_row("answer latency p50 (ms)", _quantile_ms(ev.latency_ms, 0.5))
    t.add_row("answer latency p99 (ms)", _quantile_ms(ev.latency_ms, 0.99))
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--evaluators", type=int, default=50, help="0: no evaluator phase.")
    parser.add_argument("--sessions", type=int, default=40)
    parser.add_argument("--data", type=Path, default=None, help="Folder with INDEX.csv.")
    parser.add_argument("--partner", type=Path, default=None, help="A dual HMM model (.npz).")
    parser.add_argument(
        "--workers", type=int, default=2, help="Server processes for the dual-HMM sessions."
    )
    parser.add_argument(
        "--load", type=int, default=1, help="CPU-bound busy-loop processes run meanwhile."
    )
    parser.add_argument(
        "--stand-in",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="Also the stand-in partner's sessions.",
    )
    args = parser.parse_args()
    console = Console()
    ev = live = None
    phases = []  # (phase, load average at its end)
    with tempfile.TemporaryDirectory(prefix="markovmotion-load-") as tmp:
        lib = Path(tmp) / "lib"
        lib.mkdir()
        index = MocapIndex.load(args.data)
        walk = build_library(lib, index)
        model, salsa = dual_hmm(Path(tmp), index, args.partner)
        db = Path(tmp) / "results.sqlite"
        console.print(f"{args.load} busy-loop process(es) started; before: {_load()}")
        # the simulated clients run in another process, so that they do not
        # share the servers' interpreter lock
        spawn = multiprocessing.get_context("spawn")
        with cpu_load(args.load), ProcessPoolExecutor(1, mp_context=spawn) as pool:
            with running(create_app(lib, db, partner=MirrorPartner)) as url:
                if args.evaluators:
                    console.print(f"{args.evaluators} evaluators for {args.seconds:g} s ...")
                    ev = pool.submit(
                        simulate_evaluators, url, args.evaluators, args.seconds
                    ).result()
                    stored = open_results(db).count_answers()
                    phases.append(("evaluators", _load()))
                if args.stand_in:
                    console.print(f"{args.sessions} stand-in live sessions for {args.seconds:g} s")
                    live = pool.submit(
                        simulate_live, url, walk, args.sessions, args.seconds
                    ).result()
                    phases.append(("stand-in sessions", _load()))
            options = AppOptions(lib, Path(tmp) / "dual.sqlite", partner=model)
            before = {p.pid for p in multiprocessing.active_children()}
            with running_workers(options, args.workers) as url:
                workers = [p.pid for p in multiprocessing.active_children() if p.pid not in before]
                console.print(
                    f"{args.sessions} dual-HMM live sessions for {args.seconds:g} s, "
                    f"{args.workers} server processes ..."
                )
                cpu0, wall0 = _cpu_seconds(workers), time.monotonic()
                dual = pool.submit(simulate_live, url, salsa, args.sessions, args.seconds).result()
                cpu, wall = _cpu_seconds(workers) - cpu0, time.monotonic() - wall0
                phases.append(("dual-HMM sessions", _load()))

    groups = [("dual HMM", dual.errors)]
    if ev is not None:
        console.print(evaluator_table(ev, args.evaluators, stored))
        groups.append(("evaluators", ev.errors))
    if live is not None:
        console.print(live_table(live, args.sessions, args.seconds, "stand-in partner"))
        groups.append(("stand-in", live.errors))
    what = f"dual HMM partner, {args.workers} server processes"
    console.print(live_table(dual, args.sessions, args.seconds, what))
    handled = sum(dual.frames) + sum(getattr(dual, "skipped", []))
    console.print(
        f"server processes' CPU during the dual-HMM sessions: {cpu:.1f} s in {wall:.1f} s "
        f"({100 * cpu / wall:.0f} % of one core), "
        + (f"{1000 * cpu / handled:.2f} ms per frame sent or dropped" if handled else "no frame")
    )
    if live is not None and live.latency_ms and dual.latency_ms:
        # the peer here is the stand-in: the streaming alone, with no model behind it
        p99 = [float(np.quantile(x.latency_ms, 0.99)) for x in (dual, live)]
        console.print(
            f"ratio: the dual HMM partner's latency p99 {p99[0]:.1f} ms against the stand-in's "
            f"(streaming alone) {p99[1]:.1f} ms: {p99[0] / max(p99[1], 1e-9):.2f}x"
        )
    console.print(f"meanwhile {args.load} busy-loop process(es); at the end of each phase:")
    for phase, load in phases:
        console.print(f"  {phase}: {load}")
    for name, errors in groups:
        for cause, count in Counter(errors).most_common(5):  # every group's causes, counted
            console.print(f"[red]error[/] ({name}, {count}x): {cause}")


if __name__ == "__main__":
    main()

"""``chain``: interaction behaviour models and virtual partners (interaction paper).

Train the behaviour chain on two-person takes (3-D motion capture or tracked
silhouettes), answer a real person with a virtual partner, and evaluate it on
the held-out takes.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from markovmotion.cli.options import (
    choose_option,
    chosen_line,
    grid_of,
    kind_option,
    normalise_option,
    preset_option,
    ranged,
    roles_option,
    split_labels,
    stopped,
    with_preset,
)
from markovmotion.cli.tables import print_json, print_table, say_people_trained_on
from markovmotion.data import MocapIndex
from markovmotion.data.index import read_listed, read_listed_motion
from markovmotion.data.splits import held_out_pairs, people_out, select_pairs
from markovmotion.defaults import (
    CHAIN_PRESETS,
    DEFAULT_PLACE_WINDOW,
    DEFAULT_PROTOTYPES,
    DEFAULT_RESPONSE,
    DEFAULT_RESYNC,
    DEFAULT_SIGMA,
    RESPONSES,
    SOURCES,
)
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.io import write_motion
from markovmotion.io.files import base_suffix
from markovmotion.progress import err_console, track

SIGMA = typer.Option(DEFAULT_SIGMA, min=1e-6, help="Width of the likelihood, eq. 20 (paper: 0.05).")
RESYNC = typer.Option(
    DEFAULT_RESYNC,
    min=0.0,
    help="Single hypothesis: re-enter the chain afresh when that matches the real person "
    "better by this margin (eq. 18 error); inf: never (the paper's).",
)

PROTOTYPES = ranged("states", DEFAULT_PROTOTYPES, min=2, help="State prototypes u (paper: 300).")
BEHAVIOURS = ranged(
    "states", DEFAULT_PROTOTYPES, min=2, help="Behaviour prototypes v (paper: 300)."
)
GAMMA = typer.Option(0.995, min=0.0, max=1.0, help="Decay constant of eq. 10.")
LAM = typer.Option(10.0, min=0.0, help="Weight lambda of dC (paper: 10).")
EPOCHS = ranged("iterations", 5, min=1, help="Passes of each competitive learning.")
SEED = ranged("seed", 0, help="Random seed.")
HYPOTHESES = ranged("hypotheses", 200, min=2, help="Hypotheses N of the multiple-hypothesis run.")
CHOOSE = choose_option(
    "chain",
    "world plus body-centred error of the multiple hypotheses",
    "n_state_prototypes+n_behaviour_prototypes=20,40,80;roles=one,both",
)
NORMALISE = normalise_option(
    "each person's shape relative to their own running mean, on the training people's mean shape"
)
SHRINK = ranged(
    "weight",
    0.0,
    help="Pull the partner's shape this far toward the training people's mean shape (0: the "
    "paper's; for people the model has never seen, docs/chain.md).",
)
PRESET = preset_option(CHAIN_PRESETS, "docs/chain.md")
PLACE_WINDOW = ranged(
    "window",
    DEFAULT_PLACE_WINDOW,
    help="Average a 3-D partner's place in the world (where it stands and faces) over its "
    "last this many frames (1: not at all, the paper's; docs/chain.md).",
)
RESPONSE = typer.Option(
    DEFAULT_RESPONSE,
    help="The response of multiple hypotheses reported as multiple_hypotheses: ml (the "
    "paper's), map (eq. 21) or mean (likelihood-weighted mean).",
)


def _new_model(
    prototypes: int,
    behaviours: int,
    gamma: float,
    lam: float,
    epochs: int,
    seed: int,
    normalise: str = "none",
    shrink: float = 0.0,
    place_window: int = DEFAULT_PLACE_WINDOW,
):
    """An unfitted :class:`VirtualPartner` with the command line's settings."""
    from markovmotion.models.chain.partner import VirtualPartner

    return VirtualPartner(
        lam=lam,
        n_state_prototypes=prototypes,
        n_behaviour_prototypes=behaviours,
        gamma=gamma,
        n_epochs=epochs,
        random_state=seed,
        normalise=normalise,
        shrink=shrink,
        place_window=place_window,
    )


app = typer.Typer(
    help="Interaction behaviour models (interaction paper): behaviour chain over two people's "
    "joint shapes, virtual partner by single- or multiple-hypothesis (CONDENSATION) propagation.",
    no_args_is_help=True,
)


def _check_source(source: str) -> None:
    if source not in SOURCES:
        raise typer.BadParameter(f"source must be one of {', '.join(SOURCES)}")


def _check_response(response: str) -> None:
    if response not in RESPONSES:
        raise typer.BadParameter(f"response must be one of {', '.join(RESPONSES)}")


def _training_takes(
    data: Path | None,
    source: str,
    label: str | list[str],
    kind: str | None = None,
    test_trials: str | None = None,
    test_people: str | None = None,
):
    """Motion-capture takes ``(name, label, people, A, B)`` (names by
    :func:`~markovmotion.evaluate.takes.take_names`; skeletons:
    :func:`~markovmotion.data.kinds.choose_kind` says what it leaves out), or tracked
    silhouette takes. ``test_trials``: the trials held out (``"none"``: every take is
    learnt); by default the collection's split (:func:`held_out_pairs`). ``test_people``:
    pairs of people (INDEX.csv's ``subject``) whose takes are held out (then, without
    ``test_trials``, they alone)."""
    if source == "mocap":
        from markovmotion.data.kinds import choose_kind, recorded
        from markovmotion.evaluate.takes import index_record, take_names
        from markovmotion.models.chain.partner import KINDS

        index = MocapIndex.load(data)
        labels = [label] if isinstance(label, str) else label
        held = [t.strip() for t in (test_trials or "").split(",") if t.strip() not in ("", "none")]
        # select_pairs refuses a mistyped trial, which would otherwise leak into training
        listed = select_pairs(index, labels, held or None, held_out=False)
        people = [p.strip() for p in (test_people or "").split(",") if p.strip()]
        away = people_out(index, listed, people)  # before the kind's note counts the takes
        listed = [p for p in listed if p not in away]
        pairs, _ = choose_kind(listed, kind, "two-person takes", lambda p: p[0], KINDS)
        # held-out people replace the collection's split, as dualhmm train --test-people does
        # (both had held out other people's last takes too, and evaluate mixed them in)
        train = held_out_pairs(pairs)[0] if test_trials is None and not people else pairs
        if not train:
            raise DataNotFoundError(
                f"no two-person takes labelled {label!r} to train on in {index.root / 'INDEX.csv'}"
            )
        names = take_names(train)
        # what evaluate without --test answers: the takes of these labels and kind not learnt
        held = [
            e.file
            for a, b in index.pairs(label=labels, kind=train[0][0].kind)
            if (a, b) not in train
            for e in (a, b)
        ]
        record = {"data_index": index_record(index), "held_out_files": held}
        loaded = [index.load_pair(a, b) for a, b in track(train, "reading takes")]
        seen = recorded(train, loaded)  # a person never seen: said, left out
        if not seen:
            raise DataNotFoundError(
                f"no two-person take labelled {label!r} in {index.root / 'INDEX.csv'} records "
                "both people"
            )
        return [
            (names[train[i]], train[i][0].label, train[i][0].subject, *loaded[i]) for i in seen
        ], record
    from markovmotion.video.dataset import silhouette_takes

    return silhouette_takes(data, split="train"), {}


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = typer.Option(
        None,
        help="mocap: folder with INDEX.csv (default: see README); "
        "silhouette: folder written by 'silhouette render'.",
    ),
    source: str = typer.Option("mocap", help="mocap (3-D joints) or silhouette (tracked video)."),
    label: str = typer.Option(
        "salsa",
        "--label",
        "--labels",
        help="Label of the two-person takes (mocap; several comma-separated: one model of all, "
        "as dualhmm train --labels).",
    ),
    prototypes: int = PROTOTYPES,
    behaviours: int = BEHAVIOURS,
    gamma: float = GAMMA,
    lam: float = LAM,
    epochs: int = EPOCHS,
    seed: int = SEED,
    kind: str = kind_option(),
    roles: str = roles_option(),
    normalise: str = NORMALISE,
    shrink: float = SHRINK,
    place_window: int = PLACE_WINDOW,
    preset: str = PRESET,
    choose: str = CHOOSE,
    hypotheses: int = ranged(
        "hypotheses", 200, min=2, help="--choose: hypotheses N of the multiple-hypothesis runs."
    ),
    test_trials: str = typer.Option(
        None,
        help="mocap: comma-separated trials held out for testing (not learnt); 'none' learns "
        "every take (for a model evaluated on other people's INDEX.csv with evaluate --test). "
        "Default: the last take of each label, as the paper's salsa split.",
    ),
    test_people: str = typer.Option(
        None,
        help="mocap: comma-separated pairs of people (INDEX.csv's subject) held out for "
        "testing (not learnt; the other people's takes are all learnt unless --test-trials "
        "says otherwise), for evaluate on their takes.",
    ),
) -> None:
    """Learn a behaviour chain from the training takes (held-out trials excluded): 3-D
    skeletons or markers (C3D, picked by name), or tracked silhouettes."""
    _check_source(source)
    options = with_preset(locals(), CHAIN_PRESETS)
    roles, normalise, shrink = options["roles"], options["normalise"], options["shrink"]
    if source != "mocap" and (test_trials is not None or test_people is not None):
        raise typer.BadParameter(
            "--test-trials and --test-people pick motion capture's takes: --source mocap"
        )
    if source != "mocap" and (choose or roles != "one"):
        raise typer.BadParameter(
            "--choose and --roles both learn from motion capture's pairs of people: --source mocap"
        )
    grid = grid_of("chain", choose, options["preset_set"])
    labels = [x.strip() for x in label.split(",") if x.strip()] or [label]
    takes, record = _training_takes(
        data, source, labels if len(labels) > 1 else labels[0], kind, test_trials, test_people
    )
    model = _new_model(
        prototypes, behaviours, gamma, lam, epochs, seed, normalise, shrink, place_window
    )
    extras: dict = {}
    with err_console.status("learning prototypes and chain"):
        if source == "mocap":
            from markovmotion.evaluate.chain import fit_takes

            model, extras = fit_takes(model, takes, roles, grid, n_hypotheses=hypotheses, seed=seed)
        else:
            model.fit(takes)
    model.save(out, source=source, labels=labels if source == "mocap" else [], **extras, **record)
    if "chosen" in extras:
        err_console.print(
            chosen_line(
                extras["chosen"],
                "world + body-centred error of the multiple hypotheses on the folds left out",
            ),
            highlight=False,
        )
    ch = model.chain_
    seconds = sum(t[3].duration if isinstance(t, tuple) else t.n_frames / t.fps for t in takes)
    both = " in both roles" if extras.get("roles") == "both" else ""
    if test_people:
        both += f" (held out: {test_people})"
    err_console.print(
        f"wrote {out}: {len(takes)} take{'s' * (len(takes) != 1)}{both}, {seconds:.0f} s at "
        f"{model.fps_:g} fps, "
        f"{ch.state_prototypes_.shape} state prototypes, "
        f"{len(ch.behaviour_prototypes_) + 1}-state chain",
        highlight=False,
    )


@app.command()
def respond(
    model: Path = typer.Option(..., help="Model from 'chain train'."),
    input: Path = typer.Option(
        ..., help="The real person: BVH (skeleton model), C3D (marker model) or video."
    ),
    out: Path = typer.Option(
        ..., help="Output: .bvh (skeleton partner), .c3d (marker partner) or .mp4 (video)."
    ),
    hypotheses: int = ranged("hypotheses", 200, min=1, help="Hypotheses N (1: single hypothesis)."),
    response: str = typer.Option(
        DEFAULT_RESPONSE,
        help="Response of multiple hypotheses: ml (the paper's), map (eq. 21) or mean "
        "(likelihood-weighted mean, CONDENSATION's estimate).",
    ),
    sigma: float = SIGMA,
    resync: float = RESYNC,
    person: int = typer.Option(0, min=0, max=1, help="Mocap: the real person's half of the model."),
    fps: float = ranged(
        "fps",
        None,
        help="True frame rate of a BVH input (default: INDEX.csv's if it is listed there).",
    ),
    seed: int = ranged("seed", 0, help="Random seed."),
    realtime: bool = typer.Option(
        False,
        help="Mocap: replay the input as a stream at the model's frame rate through the online "
        "partner; report per-frame latency.",
    ),
) -> None:
    """Drive a virtual partner from a real person's motion or video."""
    from markovmotion.models.chain.partner import VirtualPartner

    _check_response(response)
    partner_model = VirtualPartner.load(model)
    source = partner_model.source
    options = {
        "n_hypotheses": hypotheses,
        "response": response,
        "sigma": sigma,
        "resync": resync,
        "rng": seed,
    }
    suffix = base_suffix(out)
    if partner_model.uses_markers:
        _respond_markers(partner_model, input, out, fps, person, realtime, options)
        return
    if suffix not in (".bvh", ".mp4"):
        raise MarkovMotionError(f"{out}: write the partner as .bvh (mocap) or .mp4")
    if realtime and (source != "mocap" or suffix != ".bvh"):
        raise typer.BadParameter("--realtime streams motion capture: a mocap model and a .bvh out")
    if source == "mocap":
        motion = read_listed_motion(input, fps)
        partner_model.check_input(motion)
        motion = motion.resample(partner_model.fps_)
        if realtime:
            from markovmotion.models.online import replay

            result = replay(lambda: partner_model.partner(person, **options), motion)
            err_console.print(
                f"streamed {result.streamed} frames at {motion.fps:g} fps: {result.summary()}",
                highlight=False,
            )
            write_motion(result.motion, out)
            if result.interrupted:
                stopped(result, motion.n_frames, out)
        elif suffix == ".bvh":
            write_motion(partner_model.respond(motion, person, **options), out)
        else:
            from markovmotion.video.partner import respond_motion_video

            respond_motion_video(partner_model, motion, out, person, **options)
    elif suffix == ".mp4":
        from markovmotion.video.partner import respond_video

        respond_video(partner_model, input, out, **options)
    else:
        raise MarkovMotionError(f"{out}: a silhouette model writes the partner into an .mp4")
    err_console.print(f"wrote {out}", highlight=False)


def _respond_markers(
    model, input: Path, out: Path, fps: float | None, person: int, realtime: bool, options: dict
) -> None:
    """``chain respond`` with a marker model: C3D in (a file of the collection at INDEX.csv's
    rate unless ``fps`` says), or a skeleton whose body points the markers name, the
    partner's markers to a C3D file."""
    from markovmotion.io.c3d import check_c3d_output, write_c3d

    if realtime:
        raise typer.BadParameter("--realtime streams skeletons: a marker model answers whole takes")
    if base_suffix(out) != ".c3d":
        raise MarkovMotionError(f"{out}: the model was trained on markers: it writes .c3d files")
    check_c3d_output(out)
    # a skeleton: its body points by the markers' names
    markers = read_listed(input, fps)
    model.check_input(markers)
    partner = model.respond(markers, person, **options)
    write_c3d(partner, out)
    # at the model's rate, which may not be the input's (said, as dualhmm respond says it)
    err_console.print(
        f"wrote {out} ({len(partner.positions)} frames at {partner.fps:g} fps; the input: "
        f"{markers.fps:g} fps)",
        highlight=False,
    )


@app.command()
def evaluate(
    model: Path = typer.Option(..., help="Model from 'chain train'."),
    test: Path = typer.Option(
        None,
        help="mocap: INDEX.csv or its folder; silhouette: folder written by 'silhouette render'.",
    ),
    hypotheses: int = HYPOTHESES,
    response: str = RESPONSE,
    sigma: float = SIGMA,
    resync: float = RESYNC,
    dual_hmm: Path = typer.Option(
        None,
        help="mocap: also a dual-HMM model ('dualhmm train') answering person A with B, "
        "measured the same way on the same takes.",
    ),
    label: list[str] = typer.Option(
        None,
        "--label",
        "--labels",
        help="Mocap: labels of the two-person takes (repeat, or comma-separated; default: the "
        "model's training labels).",
    ),
    seed: int = ranged("seed", 0, help="Random seed."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
) -> None:
    """Mask one partner of each test take, generate it, report the errors.

    With --test, the two-person takes of that INDEX.csv that fit the model, minus those it
    trained on (by content); without, the collection's held-out takes.
    """
    label = split_labels(label)
    from markovmotion.evaluate.chain import evaluate_model
    from markovmotion.models.chain.partner import VirtualPartner

    _check_response(response)
    partner_model = VirtualPartner.load(model)
    dual = None
    if dual_hmm is not None:
        if partner_model.source != "mocap":
            raise typer.BadParameter("--dual-hmm compares 3-D partners: give a mocap model")
        from markovmotion.models.hmm.dual import DualHMM

        dual = DualHMM.load(dual_hmm)
    takes = None
    if partner_model.source == "silhouette":
        from markovmotion.video.dataset import silhouette_takes

        takes = silhouette_takes(test, split="test")
    result = evaluate_model(
        partner_model, test, label, hypotheses, response, seed, sigma, resync, dual, takes
    )
    if as_json:
        print_json(result, indent=2)
        return
    title = f"virtual partner on {len(result['takes'])} test takes ({result['unit']})"
    _print_errors(result, f"{title}, each person masked in turn", response)
    if dual is not None:
        for person, part in enumerate(result["by_real_person"]):
            _print_errors(part, f"{title}, person {'AB'[person]} real", response)
    for who, part in result["per_people"].items():
        n = len(part["takes"])
        _print_errors(part, f"people {who}: {n} take{'s' * (n != 1)} ({part['unit']})", response)
    err_console.print(f"test takes: {', '.join(result['takes'])}", highlight=False)
    say_people_trained_on(result)
    left = result["left_out_training_files"]
    if left:
        err_console.print(f"left out (training takes): {', '.join(left)}", highlight=False)


@app.command()
def crossval(
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    labels: str = typer.Option(
        None,
        "--labels",
        "--label",
        help="Comma-separated labels of the two-person takes (default: every interaction).",
    ),
    prototypes: int = PROTOTYPES,
    behaviours: int = BEHAVIOURS,
    gamma: float = GAMMA,
    lam: float = LAM,
    epochs: int = EPOCHS,
    hypotheses: int = HYPOTHESES,
    response: str = RESPONSE,
    sigma: float = SIGMA,
    resync: float = RESYNC,
    roles: str = roles_option(),
    normalise: str = NORMALISE,
    shrink: float = SHRINK,
    place_window: int = PLACE_WINDOW,
    preset: str = PRESET,
    one_model: bool = typer.Option(
        False, "--one-model", help="One model of every label per fold (default: one per label)."
    ),
    choose: str = CHOOSE,
    choose_prototypes: str = typer.Option(
        None, hidden=True, help="Old spelling of --choose 'n_state_prototypes+...=N1,N2'."
    ),
    choose_roles: bool = typer.Option(
        False, "--choose-roles", hidden=True, help="Old spelling of --choose 'roles=one,both'."
    ),
    seed: int = SEED,
    kind: str = kind_option(),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
) -> None:
    """Leave one pair of people out at a time (INDEX.csv's subject; one take when all come
    from one pair): train on the other people's takes of each label, answer each person of
    the left-out takes; multiple hypotheses against one hypothesis, the mean shape and the
    nearest neighbour, world and body-centred (mm)."""
    from markovmotion.evaluate.chain import crossval_index

    _check_response(response)
    options = with_preset(locals(), CHAIN_PRESETS)
    roles, normalise, shrink = options["roles"], options["normalise"], options["shrink"]
    model = _new_model(
        prototypes, behaviours, gamma, lam, epochs, seed, normalise, shrink, place_window
    )
    wanted = [x.strip() for x in labels.split(",") if x.strip()] if labels else None
    parts = [choose] if choose else []  # and the old flags, as the grid they stand for
    if choose_prototypes:
        parts.append(f"n_state_prototypes+n_behaviour_prototypes={choose_prototypes}")
    if choose_roles:
        parts.append("roles=one,both")
    grid = grid_of("chain", ";".join(parts), options["preset_set"])
    report = crossval_index(
        model,
        data,
        wanted,
        kind,
        n_hypotheses=hypotheses,
        response=response,
        seed=seed,
        sigma=sigma,
        resync=resync,
        roles=roles,
        per_label=not one_model,
        grid=grid,
    )
    if as_json:
        print_json(report, indent=2)
        return
    rows = {
        "overall": report["overall"],
        **report["per_label"],
        **{f"people {p}": r for p, r in report["per_people"].items()},
        **report["per_pair"],
    }
    for part, what in (("world_mm", "world"), ("body_centred_mm", "body-centred")):
        table = Table(
            title=f"behaviour chain, {report['left_out']} left out: {what} error of the "
            "partner (mm)",
            caption=f"multiple_hypotheses: {hypotheses} hypotheses, {response} response; "
            "aim: below single_hypothesis (re-synchronised; aim met (5.1): the paper's, never "
            "re-synchronised) and mean_shape",
        )
        keys = list(report["overall"][part])
        for col in ("group", *keys, "aim met", "aim met (5.1)", "frames"):
            table.add_column(col)
        for name, r in rows.items():
            met = ["yes" if r[k][part] else "no" for k in ("aim_met", "aim_met_paper")]
            table.add_row(name, *(f"{r[part][k]:.1f}" for k in keys), *met, str(r["frames"]))
        print_table(table)
    table = Table(
        title=f"behaviour chain, {report['left_out']} left out: how much the partner jumps "
        "(p90 of frame steps, mm)",
        caption="the median point's step from frame to frame (the dual HMM's jump p90); "
        "real: the real partner's",
    )
    keys = list(report["overall"]["jump_p90_mm"])
    for col in ("group", *keys, "frames"):
        table.add_column(col)
    for name, r in rows.items():
        table.add_row(name, *(_mm(r["jump_p90_mm"][k]) for k in keys), str(r["frames"]))
    print_table(table)
    for fold in report["folds"]:
        if "chosen" in fold:
            err_console.print(
                f"{fold['label'] or 'all'}, {fold['left_out']} left out: chose "
                f"{fold['chosen']['settings']} (inner mm: {fold['chosen']['inner_mm']})",
                highlight=False,
            )


#: What each partner of an evaluation table is (docs/chain.md), said under the table.
ROWS_SAID = {
    "mean_shape": "the training people's mean shape, placed as the chain places its partner",
    "single_hypothesis": "one hypothesis that re-synchronises (--resync, ours)",
    "single_hypothesis_paper": "one hypothesis never re-synchronised (the paper's 5.1)",
}


def _print_errors(result: dict, title: str, response: str) -> None:
    """One table row per partner; ``*`` marks the response reported as multiple_hypotheses;
    the caption says what each row is (:data:`ROWS_SAID`)."""
    placement = result.get("placement_mm")
    said = [f"{k}: {v}" for k, v in ROWS_SAID.items() if k in result]
    caption = "; ".join([f"* multiple_hypotheses ({response} response)", *said])
    if placement:
        caption += (
            "; body-centred: each person about its own centroid, facing +Z; world: where the "
            "partner stands as well"
        )
    table = Table(title=title, caption=caption)
    fmt = ".1f" if result.get("unit") == "mm" else ".4g"  # mm to 0.1, as every table; fractions
    ms = result.get("per_frame_ms")
    jumps = result.get("jump_p90_mm")
    for col in (
        "partner",
        # mocap: each person in its own frame (crossval's body_centred_mm), and in the world
        "body-centred" if placement else "error",
        "world (mm)" if placement else "",
        # how much B moves from frame to frame (the dual HMM's jump p90), the real B's below
        "jump p90 (mm)" if jumps else "",
        "ms / frame" if ms else "",
    ):
        if col:
            table.add_column(col)
    for key, value in result.items():
        if not isinstance(value, float) or key in ("multiple_hypotheses", "sigma", "resync"):
            continue
        row = [f"{key} *" if key == f"multiple_hypotheses_{response}" else key, f"{value:{fmt}}"]
        if placement:
            row.append(f"{placement[key]:{fmt}}")
        if jumps:
            row.append(_mm(jumps.get(key)))
        if ms:
            row.append(f"{ms[key]:.2f}" if key in ms else "")
        table.add_row(*row)
    if jumps:
        table.add_row("real partner", "", "", _mm(jumps.get("real")), *([""] if ms else []))
    print_table(table)


def _mm(value: float | None) -> str:
    """A jump's millimetres for a table (none: a dash)."""
    return "-" if value is None else f"{value:.1f}"

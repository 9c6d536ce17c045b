"""A collection that mixes skeleton takes (BVH, ASF/AMC) and markers-only takes (C3D) under
one label: every family chooses takes it can learn, by kind and by set, and says in one
line what it left out (:mod:`markovmotion.data.kinds`)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import make_motion

from markovmotion import read_motion
from markovmotion.cli import main
from markovmotion.core.markers import Markers
from markovmotion.data.kinds import KIND_WORDS, choose_kind, counted, largest_group
from markovmotion.errors import DataNotFoundError
from markovmotion.io import describe_take
from markovmotion.models import Model
from markovmotion.models.hmm.dual import DualHMM

LABEL = "handshake"


@pytest.fixture(scope="module")
def both(mocap):
    """The collection's handshakes by kind (the label holds both; the test says so)."""
    pairs = mocap.pairs(label=LABEL)
    kinds = {k: [p for p in pairs if p[0].kind == k] for k in ("skeleton", "markers")}
    assert all(kinds.values()), "the collection's handshakes should hold both kinds"
    return kinds


def _notes(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("note:")]


def _run(args: list[str], capsys) -> tuple[int, str]:
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


# ------------------------------------------------------------------ choose_kind, largest_group
def _entries(mocap, kinds: str):
    """Index entries of the given kinds in order ("s": a skeleton take, "m": a markers one)."""
    skeleton = mocap.query(kind="skeleton")[0]
    markers = mocap.query(kind="markers")[0]
    return [replace(skeleton if k == "s" else markers, trial=str(i)) for i, k in enumerate(kinds)]


def test_choose_kind_takes_the_larger_group_and_says_so(mocap, capsys):
    entries = _entries(mocap, "smmsm")
    kept, left = choose_kind(entries)
    assert [e.kind for e in kept] == ["markers"] * 3 and [e.kind for e in left] == ["skeleton"] * 2
    (line,) = _notes(capsys.readouterr().err)
    assert "both kinds" in line and "larger group" in line and "--kind" in line
    assert "using the 3 takes of markers only" in line and "left out 2 takes of skeletons" in line


def test_choose_kind_tie_goes_to_skeletons_and_the_asked_kind_wins(mocap, capsys):
    entries = _entries(mocap, "smsm")
    assert {e.kind for e in choose_kind(entries)[0]} == {"skeleton"}
    capsys.readouterr()
    kept, left = choose_kind(entries, "markers")
    assert {e.kind for e in kept} == {"markers"} and len(left) == 2
    (line,) = _notes(capsys.readouterr().err)
    assert "--kind markers" in line and "left out 2 takes of skeletons" in line


def test_counted_says_one_take_not_one_takes():
    assert counted(1, "two-person takes") == "1 two-person take"
    assert counted(2, "two-person takes") == "2 two-person takes"
    assert counted(0, "findings") == "0 findings"


def test_choose_kind_one_kind_says_nothing(mocap, capsys):
    entries = _entries(mocap, "sss")
    assert choose_kind(entries) == (entries, [])
    assert capsys.readouterr().err == ""


def test_choose_kind_refuses_a_kind_absent_or_not_learnt(mocap):
    with pytest.raises(DataNotFoundError, match="no markers"):
        choose_kind(_entries(mocap, "ss"), "markers")
    with pytest.raises(DataNotFoundError, match="learns from skeleton"):
        choose_kind(_entries(mocap, "sm"), "markers", can=("skeleton",))
    with pytest.raises(ValueError, match="kind must be one of"):
        choose_kind(_entries(mocap, "s"), "points")


@pytest.mark.parametrize("family", ["dualhmm", "chain"])
@pytest.mark.parametrize("command", ["train", "crossval"])
def test_a_misspelt_label_in_a_list_is_one_line_not_left_out(family, command, tmp_path, capsys):
    """``--labels handshake,wav``: the label no take has is named (with the index's labels)
    before anything is learnt, instead of learning the handshakes alone."""
    argv = [family, command, "--labels", "handshake,wav", "--kind", "markers"]
    argv += ["--out", str(tmp_path / "m.npz")] if command == "train" else []
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "'wav'" in err and "wave" in err and "Traceback" not in err
    assert not (tmp_path / "m.npz").exists()


def test_largest_group_keeps_one_skeleton_or_marker_set(capsys):
    a, b = make_motion(10), make_motion(10, seed=1)
    other = a.copy()
    other.skeleton = replace(a.skeleton, names=("root", *a.skeleton.names[1:]))
    m8 = Markers(tuple("abcdefgh"), np.zeros((5, 8, 3)), 30.0)
    m3 = Markers(tuple("abc"), np.zeros((5, 3, 3)), 30.0)
    takes = [m8, a, other, b, m3, m8]
    keep, left = largest_group(takes, [f"t{i}.bvh" for i in range(6)])
    assert keep == [1, 3] or keep == [0, 5]
    assert sorted(keep + left) == list(range(6))
    (line,) = _notes(capsys.readouterr().err)
    assert "4 skeletons or marker sets" in line and "left out" in line


def test_dual_hmm_refuses_a_mix_of_motions_and_markers():
    m = make_motion(20)
    markers = Markers(tuple("abcdefgh"), np.random.default_rng(0).normal(size=(20, 8, 3)), 30.0)
    with pytest.raises(TypeError, match="all Motions or all Markers"):
        DualHMM(n_states=2).fit([(m, m), (markers, markers)])


# ------------------------------------------------------------------ every family, by the CLI
def test_dualhmm_trains_on_the_larger_kind_or_the_one_asked(tmp_path: Path, capsys, both):
    out = tmp_path / "m.npz"
    code, err = _run(
        [
            "dualhmm",
            "train",
            "--labels",
            LABEL,
            "--states",
            "4",
            "--n-iter",
            "3",
            "--out",
            str(out),
        ],
        capsys,
    )
    assert code == 0, err
    larger = max(both, key=lambda k: (len(both[k]), k == "skeleton"))
    other = "markers" if larger == "skeleton" else "skeleton"
    (line,) = _notes(err)
    left = f"left out {counted(len(both[other]), 'two-person takes')} of {KIND_WORDS[other]}"
    assert "both kinds" in line and left in line
    assert Model.load(out).uses_markers == (larger == "markers")
    for kind in ("skeleton", "markers"):
        code, err = _run(
            ["dualhmm", "train", "--labels", LABEL, "--states", "2", "--n-iter", "2"]
            + ["--kind", kind, "--out", str(out)],
            capsys,
        )
        assert code == 0, err
        (line,) = _notes(err)
        assert f"--kind {kind}" in line
        assert Model.load(out).uses_markers == (kind == "markers")


def test_chain_trains_on_the_larger_kind_or_the_one_asked(tmp_path: Path, capsys, both):
    from markovmotion.models.chain.partner import VirtualPartner

    out = tmp_path / "c.npz"
    small = ["--prototypes", "8", "--behaviours", "8", "--epochs", "1", "--out", str(out)]
    code, err = _run(["chain", "train", "--label", LABEL, *small], capsys)
    assert code == 0, err
    larger = max(both, key=lambda k: (len(both[k]), k == "skeleton"))
    other = "markers" if larger == "skeleton" else "skeleton"
    (line,) = _notes(err)
    left = f"left out {counted(len(both[other]), 'two-person takes')} of {KIND_WORDS[other]}"
    assert "both kinds" in line and left in line
    assert VirtualPartner.load(out).uses_markers == (larger == "markers")
    for kind in ("skeleton", "markers"):
        code, err = _run(["chain", "train", "--label", LABEL, "--kind", kind, *small], capsys)
        assert code == 0, err
        (line,) = _notes(err)
        assert f"--kind {kind}" in line
        model = VirtualPartner.load(out)
        assert model.uses_markers == (kind == "markers")
        assert (model.skeletons_ is None) == (kind == "markers")


def test_vlmm_learns_markers_or_skeletons_by_kind(tmp_path: Path, capsys, mocap):
    out = tmp_path / "v.npz"
    base = ["vlmm", "train", "--category", "interaction", "--label", LABEL, "--no-hold-out"]
    code, err = _run(
        [
            *base,
            "--source",
            "markers",
            "--prototypes",
            "12",
            "--kind",
            "markers",
            "--out",
            str(out),
        ],
        capsys,
    )
    assert code == 0, err
    (line,) = _notes(err)
    assert "--kind markers" in line and "left out" in line and "skeleton" in line
    assert Model.load(out).fits(mocap.load_take(mocap.query(label=LABEL, kind="markers")[0]))
    # skeleton positions cannot learn C3D markers: they are left out, or refused if asked for
    code, err = _run([*base, "--prototypes", "12", "--out", str(out)], capsys)
    assert code == 0, err
    (line,) = _notes(err)
    assert "learns from skeletons" in line and "markers" in line
    code, err = _run([*base, "--kind", "markers", "--out", str(out)], capsys)
    assert code == 2 and len([ln for ln in err.splitlines() if ln.strip()]) == 1


def test_data_list_shows_each_takes_kind(capsys, mocap):
    main(["data", "list", "--label", LABEL])
    shown = capsys.readouterr().out
    for e in mocap.query(label=LABEL):
        row = next(ln for ln in shown.splitlines() if e.file in ln)
        kind, count = describe_take(e.path)
        assert kind == e.kind
        assert f"{kind}, {count} {'points' if kind == 'markers' else 'joints'}" in row


def test_a_file_listed_in_an_index_above_it_is_read_as_that_index_says(mocap, tmp_path, capsys):
    """A user's own collection (an INDEX.csv in a folder above the file, not the default
    collection): ``info`` and the readers take its frame rate, as for the collection's files;
    a broken index above a file is passed over (the file read as it is)."""
    import shutil

    from markovmotion.cli import main
    from markovmotion.data.index import read_listed_motion

    walk = mocap.query(source="bandai")[0]
    (tmp_path / "own" / "takes").mkdir(parents=True)
    shutil.copyfile(walk.path, tmp_path / "own" / "takes" / "w.bvh.gz")
    (tmp_path / "own" / "INDEX.csv").write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
        f"takes/w.bvh.gz,mine,,,walk,active,,15,{walk.frames},listed at half its rate\n"
    )
    assert read_listed_motion(tmp_path / "own" / "takes" / "w.bvh.gz").fps == 15.0
    main(["info", str(tmp_path / "own" / "takes" / "w.bvh.gz")])
    assert "15 fps" in capsys.readouterr().out
    (tmp_path / "own" / "INDEX.csv").write_text(  # an edited index is read again
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
        f"takes/w.bvh.gz,mine,,,walk,active,,12.5,{walk.frames},listed at another rate\n"
    )
    assert read_listed_motion(tmp_path / "own" / "takes" / "w.bvh.gz").fps == 12.5
    (tmp_path / "own" / "INDEX.csv").write_text("not,an,index\n")
    assert read_listed_motion(tmp_path / "own" / "takes" / "w.bvh.gz").fps == pytest.approx(
        30.0, rel=1e-4
    )


def test_data_check_finds_what_is_wrong_with_a_users_index(mocap, tmp_path, capsys, caplog):
    """``data check`` reads every take whole and names, per row: a file not found, a
    truncated file, frames other than listed, a partner not listed or not naming this take
    back, a row listed twice (errors, exit 1); a pair of two lengths, two-person takes
    without subject, a frame rate the file states that INDEX.csv contradicts (notes). The
    collection itself has no error (exit 0); its only notes are the rates its index corrects
    (CMU's salsa conversions say 120 fps in their headers for 60)."""
    import dataclasses
    import gzip
    import shutil

    from markovmotion.cli import main

    main(["data", "check", "--json"])
    findings = json.loads(capsys.readouterr().out)["findings"]
    assert {f["level"] for f in findings} <= {"note"}
    assert all("fps, INDEX.csv" in f["problem"] for f in findings)
    assert {mocap.find(f["file"]).fps for f in findings} <= {60.0}

    pair = next(p for p in mocap.pairs("handshake", kind="markers"))
    walk = mocap.query(source="bandai")[0]
    own = tmp_path / "own"
    own.mkdir()
    for e in (*pair, walk):
        shutil.copyfile(e.path, own / Path(e.file).name)
    a, b, w = (Path(e.file).name for e in (*pair, walk))
    text = gzip.decompress((own / w).read_bytes()).decode().splitlines(keepends=True)
    (own / "cut.bvh").write_text("".join(text[:-5]))  # five frames short of its header
    shutil.copyfile(pair[0].path, own / "fast.c3d")  # a 30 fps capture listed at 120
    from markovmotion.io.bvh import read_bvh, write_bvh

    write_bvh(read_bvh(walk.path), own / "in_mm.bvh", length_unit="mm")  # read in cm: a note
    (own / "folder").mkdir()
    header = "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
    rows = [
        f"{a},mine,,1,interaction,handshake,{b},30,{pair[0].frames},",
        f"{b},mine,,1,interaction,handshake,gone.c3d,30,{pair[1].frames + 1},",
        f"{w},mine,,,style_walk,active,,30,{walk.frames},",
        f"{w},mine,,,style_walk,active,,30,{walk.frames},",
        f"cut.bvh,mine,,,style_walk,active,,30,{walk.frames},",
        "nowhere.bvh,mine,,,walk,normal,,30,10,",
        f"fast.c3d,mine,,,misc,misc,,120,{pair[0].frames},",
        f"in_mm.bvh,mine,,,style_walk,active,,30,{walk.frames},",
        "folder,mine,,,walk,normal,,30,10,",
    ]
    (own / "INDEX.csv").write_text(header + "\n".join(rows) + "\n")
    with pytest.raises(SystemExit) as exit_:
        main(["data", "check", "--data", str(own), "--json"])
    assert exit_.value.code == 1
    report = json.loads(capsys.readouterr().out)
    found = {(f["file"], f["level"], f["problem"].split(":")[0]) for f in report["findings"]}
    assert (w, "error", "listed 2 times") in found
    assert ("nowhere.bvh", "error", "file not found") in found
    assert ("cut.bvh", "error", "unreadable") in found
    assert (
        b,
        "error",
        f"{pair[1].frames} frames in the file, {pair[1].frames + 1} listed",
    ) in found
    assert (b, "error", "partner_file gone.c3d is not listed") in found
    assert (a, "error", f"its partner {b} names gone.c3d back") in found
    assert (a, "note", "no subject") in found
    assert ("fast.c3d", "note", "the file says 30 fps, INDEX.csv 120") in found
    assert ("folder", "error", "is a folder, not a motion file") in found
    unit = [f for f in report["findings"] if f["file"] == "in_mm.bvh"]
    assert [f["level"] for f in unit] == ["note"] and "spans" in unit[0]["problem"]
    from markovmotion.data.index import MocapIndex, read_listed

    with caplog.at_level("WARNING", logger="markovmotion"):
        assert read_listed(own / "fast.c3d").fps == 120.0  # by path, as every command reads it
        walk = MocapIndex.load(own).find(w)
        slow = dataclasses.replace(walk, fps=60.0)  # a BVH at 30 fps listed at 60
        assert slow.read().fps == 60.0 and walk.read().fps == 30.0
    said = " ".join(caplog.text.split())
    assert "fast.c3d: the file says 30 fps, INDEX.csv 120: read at INDEX.csv's rate" in said
    assert f"{w}: the file says 30 fps, INDEX.csv 60" in said and said.count(w) == 1
    assert read_listed(own / "fast.c3d", fps=25).fps == 25.0  # an fps given wins
    assert report["errors"] == sum(f["level"] == "error" for f in report["findings"]) == 7


def test_a_skeletons_difference_says_how_many_more_joints_differ(mocap):
    """Two skeletons that differ in many joints: five of each side's are named (end sites left
    out), then "and N more"."""
    import dataclasses

    walk = mocap.load_motion(mocap.query(source="bandai")[0])
    sk = walk.skeleton
    renamed = tuple(n.lower() for n in sk.names)
    other = dataclasses.replace(sk, names=renamed)
    side = [n for j, n in enumerate(sk.names) if n != renamed[j] and not sk.end_site[j]]
    text = sk.difference(other)
    more = f"(and {len(side) - 5} more)"
    assert f"expected joints {', '.join(side[:5])} {more} are not in it" in text
    assert f"which has {', '.join(n.lower() for n in side[:5])} {more} instead" in text


def test_markers_labelled_with_each_persons_subject_prefix_are_one_marker_set(
    mocap, tmp_path: Path, capsys
):
    """A Vicon lab labels each person's markers with the person's name (``Anna:R_HAND``,
    ``Ben:R_HAND``): the takes are one marker set (each person had been a set of their own,
    all but one pair left out, and then B refused as lacking A's markers), a marker some take
    never sees is left out of every person's labels, and each family learns them all."""
    from markovmotion.core.markers import find_markers
    from markovmotion.data.kinds import same_set
    from markovmotion.features.markers import seen_in_every
    from markovmotion.io.c3d import read_c3d, write_c3d

    assert find_markers(("Ben:HEAD", "Ben:R_HAND"), ["Anna:R_HAND", "anna:head"]) == ([1, 0], [])
    a = Markers(("Anna:HEAD", "Anna:R_HAND"), np.zeros((3, 2, 3)), 30.0, "a")
    b = Markers(("Ben:r_hand", "Ben:HEAD"), np.zeros((3, 2, 3)), 30.0, "b")
    b.positions[:, 0] = np.nan  # Ben's right hand never seen
    assert same_set(a, b) and not same_set(a, Markers(("Ben:HEAD",), np.zeros((3, 1, 3)), 30.0))
    assert [t.names for t in seen_in_every([a, b])] == [("Anna:HEAD",), ("Ben:HEAD",)]

    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames"]
    pairs = mocap.pairs(label=LABEL, kind="markers")[:3]
    for k, pair in enumerate(pairs):
        names = [f"take{k}_{p}.c3d" for p in "AB"]
        for person, (entry, name) in enumerate(zip(pair, names, strict=True)):
            m = read_c3d(entry.path)
            who = f"S{k}{'AB'[person]}"
            write_c3d(
                Markers(tuple(f"{who}:{n}" for n in m.names), m.positions, m.fps), tmp_path / name
            )
            partner = names[1 - person]
            rows.append(f"{name},lab,{entry.subject},{k},interaction,{LABEL},{partner},30,")
    (tmp_path / "INDEX.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "m.npz"
    args = ["--data", str(tmp_path), "--out", str(out)]
    code, err = _run(
        ["dualhmm", "train", "--labels", LABEL, "--states", "2", "--n-iter", "2", "--roles", "both"]
        + args,
        capsys,
    )
    assert code == 0, err
    assert "marker sets" not in err and len(Model.load(out).train_files_) == 2 * len(pairs)
    small = ["--prototypes", "4", "--behaviours", "4", "--epochs", "1", "--test-trials", "none"]
    code, err = _run(["chain", "train", "--label", LABEL, *small, *args], capsys)
    assert code == 0, err
    assert "marker sets" not in err and len(Model.load(out).train_files_) == 2 * len(pairs)


def test_data_check_compares_a_pair_at_two_rates_by_time_and_names_markers_never_seen(
    mocap, tmp_path, capsys
):
    """A user's pair captured at two rates (A at 60 fps, B at 30) is loaded with B brought
    to A's rate: ``data check`` compares their lengths so (it had noted "553 frames, its
    partner 277: the pair is cut to the shorter" for two takes of the same 9.2 s), and still
    notes a pair that does differ. A C3D take whose person is never seen is an error, one
    whose marker is never seen a note naming it."""
    from markovmotion.data.index import MocapIndex
    from markovmotion.io import read_c3d, write_c3d

    a_entry, b_entry = mocap.pairs("handshake", kind="markers")[0]
    a, b = read_c3d(a_entry.path), read_c3d(b_entry.path)
    fast = a.resample(60.0)
    write_c3d(fast, tmp_path / "a60.c3d")
    write_c3d(b, tmp_path / "b30.c3d")
    write_c3d(b.trim(0, b.n_frames - 10), tmp_path / "short30.c3d")
    blind = a.copy()
    blind.positions[:, a.names.index("R_HAND")] = np.nan
    write_c3d(blind, tmp_path / "blind.c3d")
    write_c3d(Markers(a.names, np.full_like(a.positions, np.nan), 30.0), tmp_path / "none.c3d")
    header = "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
    rows = [
        f"a60.c3d,mine,p,1,interaction,handshake,b30.c3d,60,{fast.n_frames},",
        f"b30.c3d,mine,p,1,interaction,handshake,a60.c3d,30,{b.n_frames},",
        f"a60.c3d,mine,p,2,interaction,handshake,short30.c3d,60,{fast.n_frames},",
        f"short30.c3d,mine,p,2,interaction,handshake,a60.c3d,30,{b.n_frames - 10},",
        f"blind.c3d,mine,p,3,interaction,handshake,none.c3d,30,{a.n_frames},",
        f"none.c3d,mine,p,3,interaction,handshake,blind.c3d,30,{a.n_frames},",
    ]
    (tmp_path / "INDEX.csv").write_text(header + "\n".join(rows[:2]) + "\n")
    main(["data", "check", "--data", str(tmp_path), "--json"])
    assert json.loads(capsys.readouterr().out)["findings"] == []
    pair = MocapIndex.load(tmp_path).pairs()[0]
    loaded = MocapIndex.load(tmp_path).load_pair(*pair)
    assert loaded[0].n_frames == loaded[1].n_frames == fast.n_frames  # nothing cut
    (tmp_path / "INDEX.csv").write_text(header + "\n".join(rows[2:]) + "\n")
    with pytest.raises(SystemExit) as exit_:
        main(["data", "check", "--data", str(tmp_path), "--json"])
    assert exit_.value.code == 1
    findings = json.loads(capsys.readouterr().out)["findings"]
    found = {(f["file"], f["level"], f["problem"]) for f in findings}
    brought = 2 * (b.n_frames - 10) - 1
    assert found == {
        ("a60.c3d", "note", f"{fast.n_frames} frames at 60 fps, its partner short30.c3d "
         f"{b.n_frames - 10} at 30 ({brought} at 60): the pair is cut to the shorter"),
        ("blind.c3d", "note", "marker R_HAND never seen: a model trained on this take leaves "
         "it out; one that uses it cannot answer it"),
        ("none.c3d", "error", "no marker is seen in any frame: nothing recorded"),
    }  # fmt: skip


def _renamed(motion, prefix: str, seed: int):
    """``motion``'s rig with every joint name given ``prefix`` (a namespace), and motion of
    its own (``seed``)."""
    m = make_motion(n_frames=motion.n_frames, seed=seed)
    sk = replace(m.skeleton, names=tuple(prefix + n for n in m.skeleton.names))
    return replace(m, skeleton=sk, name=f"{prefix or 'plain'}{seed}")


def test_one_rig_under_another_namespace_is_the_same_skeleton(tmp_path: Path, capsys):
    """A rig exported twice differs by a namespace alone (Mixamo's ``mixamorig:Hips``, a
    character's ``Beta:Hips``, ``Hips``): the VLMM (and every model that needs the skeleton it
    learnt) trains on them together and answers each, by name; it had called them another
    skeleton. A rig whose names still differ is left out naming the joints that do."""
    from markovmotion.io import write_motion

    base = make_motion(n_frames=150)
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    takes = [("Beta:", 1), ("", 2), ("mixamorig:", 3), ("Beta:", 4)]
    for i, (prefix, seed) in enumerate(takes):
        write_motion(_renamed(base, prefix, seed), tmp_path / f"t{i}.bvh")
        rows.append(f"t{i}.bvh,mine,,{i},dance,beta,,30,,")
    (tmp_path / "INDEX.csv").write_text("\n".join(rows) + "\n")
    test = tmp_path / "test"
    test.mkdir()
    write_motion(_renamed(base, "mixamorig:", 5), test / "new.bvh")
    other = _renamed(base, "", 6)
    other = replace(other, skeleton=replace(other.skeleton, names=("hips", "lleg", "rleg",
                                                                   "chest", "chest_end")))  # fmt: skip
    write_motion(other, test / "other.bvh")
    (test / "INDEX.csv").write_text(
        rows[0] + "\nnew.bvh,mine,,1,dance,beta,,30,,\nother.bvh,mine,,2,dance,beta,,30,,\n"
    )
    model = tmp_path / "v.npz"
    train = ["vlmm", "train", "--data", str(tmp_path), "--category", "dance"]
    code, err = _run([*train, "--prototypes", "6", "--out", str(model)], capsys)
    assert code == 0, err
    assert not _notes(err)  # no take left out as another skeleton
    assert Model.load(model).held_out_files_ == ["t3.bvh"]
    for test_index, tested, other_skeleton in ((None, ["t3.bvh"], []),
                                               (test, ["new.bvh"], ["other.bvh"])):  # fmt: skip
        main(["vlmm", "evaluate", "--model", str(model), "--json"]
             + (["--test", str(test_index)] if test_index else []))  # fmt: skip
        report = json.loads(capsys.readouterr().out)
        assert report["test_files"] == tested
        assert report.get("left_out_other_skeleton", []) == other_skeleton
    sk = read_motion(tmp_path / "t0.bvh").skeleton
    assert sk.difference(read_motion(tmp_path / "t2.bvh").skeleton) is None
    differs = sk.difference(read_motion(test / "other.bvh").skeleton, "the model's")
    assert "the model's joint Beta:spine is not in it, which has chest instead" in differs

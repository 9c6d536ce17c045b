"""``data fetch`` against a local HTTP server laid out like the CMU site and the Bandai repository.

No test touches the internet: a threaded ``http.server`` on 127.0.0.1 serves
small generated files, honours Range requests, can drop a connection half-way
through a file once, and records every request it sees.
"""

from __future__ import annotations

import importlib.util
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
from conftest import make_motion

from markovmotion.cli import main
from markovmotion.data import MocapIndex
from markovmotion.data.fetch import DownloadError, download, fetch
from markovmotion.io.bvh import bvh_text
from markovmotion.io.files import read_text

needs_amc = pytest.mark.skipif(
    importlib.util.find_spec("markovmotion.io.asfamc") is None,
    reason="markovmotion.io.asfamc (the ASF/AMC reader) is not written yet",
)

BANDAI = "/gh/dataset"
CMU = "/cmu/subjects"

ASF = """\
# AST/ASF file: a small CMU-like skeleton for the fetch tests
:version 1.10
:name VICON
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
   six bones of CMU's layout
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name lhipjoint
     direction 0.655637 -0.713449 0.247245
     length 2.52691
     axis 0 0 0  XYZ
  end
  begin
     id 2
     name lfemur
     direction 0.34202 -0.939693 0
     length 7.59371
     axis 0 0 20  XYZ
    dof rx ry rz
    limits (-160.0 20.0)
           (-70.0 70.0)
           (-60.0 70.0)
  end
  begin
     id 3
     name rhipjoint
     direction -0.655637 -0.713449 0.247245
     length 2.52691
     axis 0 0 0  XYZ
  end
  begin
     id 4
     name rfemur
     direction -0.34202 -0.939693 0
     length 7.59371
     axis 0 0 -20  XYZ
    dof rx ry rz
    limits (-160.0 20.0)
           (-70.0 70.0)
           (-70.0 60.0)
  end
  begin
     id 5
     name lowerback
     direction 0.000114 0.999201 -0.039968
     length 2.04
     axis 0 0 0  XYZ
    dof rx ry rz
    limits (-20.0 45.0)
           (-30.0 30.0)
           (-30.0 30.0)
  end
  begin
     id 6
     name upperback
     direction -0.00573 0.99993 0.01017
     length 2.07
     axis 0 0 0  XYZ
    dof rx ry rz
    limits (-20.0 45.0)
           (-30.0 30.0)
           (-30.0 30.0)
  end
:hierarchy
  begin
    root lhipjoint rhipjoint lowerback
    lhipjoint lfemur
    rhipjoint rfemur
    lowerback upperback
  end
"""


def amc_text(n_frames: int, seed: int) -> str:
    """An AMC motion of :data:`ASF`: smooth sines, root in ASF units, angles in degrees."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None]
    root = np.hstack(
        [t * 0.5, 16 + np.sin(t / 5), -30 + t * 0.2, 10 * np.sin(t / 9 + rng.uniform(0, 6, 3))]
    )
    lines = ["#!OML:ASF test.asf", ":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(n_frames):
        lines.append(str(f + 1))
        lines.append("root " + " ".join(f"{v:.5f}" for v in root[f]))
        for k, bone in enumerate(("lowerback", "upperback", "rfemur", "lfemur")):
            angles = 20 * np.sin(f / 7 + k + rng.uniform(0, 0.01, 3))
            lines.append(f"{bone} " + " ".join(f"{v:.5f}" for v in angles))
    return "\n".join(lines) + "\n"


def bvh_bytes(seed: int, n_frames: int = 40) -> bytes:
    return bvh_text(make_motion(n_frames=n_frames, seed=seed)).encode()


class Site:
    """What the server serves (path -> bytes), what it should misbehave on, what it saw."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.drop_once: set[str] = set()
        self.soft_404 = False  # answer unknown paths with a 200 "not found" page
        self.ignore_range = False  # always send the whole file, as plain servers do
        self.seen: list[tuple[str, str | None, int]] = []  # (path, Range header, status)
        self.lock = threading.Lock()
        self.url = ""

    def add_bandai(self, dataset: int, style: str, take: int, body: bytes | None = None) -> bytes:
        body = bvh_bytes(seed=100 * dataset + take) if body is None else body
        name = f"dataset-{dataset}_walk_{style}_{take:03d}.bvh"
        self.files[f"{BANDAI}/Bandai-Namco-Research-Motiondataset-{dataset}/data/{name}"] = body
        return body

    def add_cmu(self, subject: int, trials: list[int], n_frames: int = 30) -> None:
        self.files[f"{CMU}/{subject:02d}/{subject:02d}.asf"] = ASF.encode()
        for t in trials:
            amc = amc_text(n_frames + t, seed=subject * 100 + t).encode()
            self.files[f"{CMU}/{subject:02d}/{subject:02d}_{t:02d}.amc"] = amc

    def requested(self, part_of_path: str) -> list[tuple[str, str | None, int]]:
        with self.lock:
            return [r for r in self.seen if part_of_path in r[0]]

    def fetch(self, dest, **kwargs):
        kwargs.setdefault("subjects", ())
        return fetch(
            dest,
            cmu_base_url=self.url + CMU,
            bandai_base_url=self.url + BANDAI,
            backoff=0.0,
            timeout=10.0,
            **kwargs,
        )


def make_handler(site: Site) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args) -> None:  # keep pytest output clean
            pass

        def reply(self, status: int, body: bytes = b"", headers: dict[str, str] | None = None):
            with site.lock:
                site.seen.append((self.path, self.headers.get("Range"), status))
            self.send_response(status)
            for k, v in {"Content-Length": str(len(body)), **(headers or {})}.items():
                self.send_header(k, v)
            self.end_headers()
            return body

        def do_GET(self) -> None:
            data = site.files.get(self.path)
            if data is None:
                page = b"<html><body>Not Found</body></html>"
                self.wfile.write(self.reply(200 if site.soft_404 else 404, page))
                return
            rng = None if site.ignore_range else self.headers.get("Range")
            start = int(rng.removeprefix("bytes=").split("-")[0]) if rng else 0
            if start >= len(data) and rng:
                self.reply(416, headers={"Content-Range": f"bytes */{len(data)}"})
                return
            body = data[start:]
            headers = {"Content-Length": str(len(body))}
            if rng:
                headers["Content-Range"] = f"bytes {start}-{len(data) - 1}/{len(data)}"
            self.reply(206 if rng else 200, headers=headers)
            with site.lock:
                drop = self.path in site.drop_once
                site.drop_once.discard(self.path)
            if drop:  # half the body, then hang up
                self.wfile.write(body[: len(body) // 2])
                self.wfile.flush()
                self.close_connection = True
                return
            self.wfile.write(body)

    return Handler


@pytest.fixture
def site():
    site = Site()
    server = ThreadingHTTPServer(("127.0.0.1", 0), make_handler(site))
    site.url = f"http://127.0.0.1:{server.server_address[1]}"
    thread = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    yield site
    server.shutdown()
    server.server_close()
    thread.join()


def bandai_site(site: Site) -> Site:
    """Two datasets: dataset-1 starts at take 002 (as its 'normal' walk does), dataset-2 has a gap."""
    site.add_bandai(1, "normal", 2)
    site.add_bandai(1, "happy", 1)
    for take in (1, 2, 4):
        site.add_bandai(2, "normal", take)
    site.add_bandai(2, "elderly", 1)
    return site


def test_bandai_fetch_writes_files_and_index(site, tmp_path):
    bandai_site(site)
    report = site.fetch(tmp_path)
    expected = {
        "bandai/dataset-1/walk_normal_002.bvh",
        "bandai/dataset-1/walk_happy_001.bvh",
        "bandai/dataset-2/walk_normal_001.bvh",
        "bandai/dataset-2/walk_normal_002.bvh",
        "bandai/dataset-2/walk_normal_004.bvh",
        "bandai/dataset-2/walk_elderly_001.bvh",
    }
    assert set(report.indexed) == expected and not report.rejected and report.total == 6
    index = MocapIndex.load(tmp_path)
    assert {e.file for e in index} == expected
    happy = index.find("bandai/dataset-1/walk_happy_001.bvh")
    assert (happy.source, happy.category, happy.label, happy.trial) == (
        "bandai",
        "style_walk",
        "happy",
        "1-001",
    )
    assert happy.fps == 30 and happy.frames == 40
    assert {e.file for e in index.query(category="walk")} == {f for f in expected if "normal" in f}
    for e in index:  # the bytes served, and a motion that reads at 30 fps
        assert (
            e.path.read_bytes()
            == site.files[
                f"{BANDAI}/Bandai-Namco-Research-Motiondataset-{e.trial[0]}/data/"
                f"dataset-{e.trial[0]}_{e.path.name}"
            ]
        )
        assert index.load_motion(e).fps == 30
    assert not list(tmp_path.rglob("*.part"))


def test_missing_files_end_the_probing(site, tmp_path):
    bandai_site(site)
    site.fetch(tmp_path / "strict", max_missing=1)
    normal = [path.rsplit("_", 1)[1] for path, _, _ in site.requested("dataset-2_walk_normal")]
    assert normal == ["001.bvh", "002.bvh", "003.bvh"]  # the 404 of 003 ended it
    assert not (tmp_path / "strict/bandai/dataset-2/walk_normal_004.bvh").exists()
    assert not (tmp_path / "strict/bandai/dataset-1/walk_normal_002.bvh").exists()

    site.seen.clear()
    site.fetch(tmp_path / "tolerant")  # default: three missing in a row
    normal = [path.rsplit("_", 1)[1] for path, _, _ in site.requested("dataset-2_walk_normal")]
    assert normal == [f"{k:03d}.bvh" for k in range(1, 8)]
    assert (tmp_path / "tolerant/bandai/dataset-2/walk_normal_004.bvh").is_file()


def test_pages_that_are_not_motions_end_the_probing_too(site, tmp_path):
    bandai_site(site).soft_404 = True
    report = site.fetch(tmp_path)
    assert len(report.indexed) == 6
    n_styles = 15 + 7  # three in a row end each style; plus the gaps before 1-002 and 2-004
    assert len(report.rejected) == 3 * n_styles + 2
    assert len(MocapIndex.load(tmp_path)) == 6


def test_dropped_connection_resumes_with_range(site, tmp_path):
    body = site.add_bandai(1, "happy", 1, bvh_bytes(seed=5, n_frames=300))
    path = f"{BANDAI}/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_happy_001.bvh"
    site.drop_once.add(path)
    report = site.fetch(tmp_path)
    assert report.indexed == ["bandai/dataset-1/walk_happy_001.bvh"]
    first, second = site.requested(path)
    assert first == (path, None, 200)
    assert second == (path, f"bytes={len(body) // 2}-", 206)
    assert (tmp_path / "bandai/dataset-1/walk_happy_001.bvh").read_bytes() == body


def test_partial_file_from_an_earlier_run_is_resumed(site, tmp_path):
    body = site.add_bandai(2, "elderly", 3, bvh_bytes(seed=6, n_frames=200))
    part = tmp_path / "bandai/dataset-2/walk_elderly_003.bvh.part"
    part.parent.mkdir(parents=True)
    part.write_bytes(body[:1000])
    site.fetch(tmp_path)
    (request,) = site.requested("dataset-2_walk_elderly_003")
    assert request[1:] == ("bytes=1000-", 206)
    assert (tmp_path / "bandai/dataset-2/walk_elderly_003.bvh").read_bytes() == body
    assert not part.exists()


def test_server_without_range_support_restarts_the_file(site, tmp_path):
    site.ignore_range = True
    site.files["/plain"] = bytes(range(256)) * 20
    (tmp_path / "plain.part").write_bytes(b"stale bytes")
    assert download(site.url + "/plain", tmp_path / "plain", backoff=0.0)
    assert (tmp_path / "plain").read_bytes() == site.files["/plain"]


def test_download_retries_then_gives_up(site, tmp_path):
    site.files["/flaky"] = b"x" * 1000
    site.drop_once.add("/flaky")
    assert download(site.url + "/flaky", tmp_path / "flaky", backoff=0.0)
    assert (tmp_path / "flaky").read_bytes() == b"x" * 1000
    assert not download(site.url + "/nothing", tmp_path / "nothing", backoff=0.0)
    with socket.socket() as probe:  # a port that nothing listens on once closed
        probe.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{probe.getsockname()[1]}"
    with pytest.raises(DownloadError, match="gave up after 2 retries"):
        download(dead + "/x", tmp_path / "x", retries=2, backoff=0.0, timeout=2.0)


def test_corrupt_file_is_reported_and_not_indexed(site, tmp_path):
    bandai_site(site)
    site.add_bandai(1, "sad", 1, b"HIERARCHY\nROOT hips\n{\n  OFFSET 0 0\n")
    report = site.fetch(tmp_path)
    assert [f for f, _ in report.rejected] == ["bandai/dataset-1/walk_sad_001.bvh"]
    assert "walk_sad_001.bvh" in report.rejected[0][1]
    index = MocapIndex.load(tmp_path)
    assert len(index) == 6 and not index.query(label="sad")
    assert (tmp_path / "bandai/dataset-1/walk_sad_001.bvh.bad").is_file()
    assert not (tmp_path / "bandai/dataset-1/walk_sad_001.bvh").exists()


def test_rerun_is_idempotent(site, tmp_path):
    bandai_site(site)
    first = site.fetch(tmp_path)
    text = (tmp_path / "INDEX.csv").read_text()
    site.seen.clear()
    second = site.fetch(tmp_path)
    assert (tmp_path / "INDEX.csv").read_text() == text
    assert sorted(second.kept) == sorted(first.indexed) and not second.indexed
    assert {status for _, _, status in site.seen} == {404}  # only the probes past the end


def test_merges_with_an_existing_index(site, tmp_path):
    bandai_site(site)
    (tmp_path / "INDEX.csv").write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description,note\n"
        "mine/walk.bvh,own,,,walk,normal,,60,10,my own take,keep me\n"
    )
    report = site.fetch(tmp_path)
    lines = (tmp_path / "INDEX.csv").read_text().splitlines()
    assert lines[0].endswith(",note") and lines[1] == (
        "mine/walk.bvh,own,,,walk,normal,,60,10,my own take,keep me"
    )
    assert report.total == len(lines) - 1 == 7


@needs_amc
def test_full_fetch_pairs_cmu_subjects(site, tmp_path):
    bandai_site(site)
    site.add_cmu(18, [1, 2, 3])
    site.add_cmu(19, [1, 2])
    site.add_cmu(20, [1])  # 21 is not on the site
    site.files[f"{CMU}/20/20_02.amc"] = (
        b":FULLY-SPECIFIED\n:DEGREES\n1\nroot 1 2 3 0 0 0\nlfemur oops\n"
    )
    report = site.fetch(tmp_path, subjects=(18, 19, 20, 21))
    assert [f for f, _ in report.rejected] == ["cmu/asfamc/20/20_02.amc"]
    assert report.missing == [f"CMU subject 21: no skeleton at {site.url}{CMU}/21/21.asf"]
    index = MocapIndex.load(tmp_path)
    assert len(index.query(source="cmu")) == 6 and len(index.query(source="bandai")) == 6
    pairs = index.pairs()
    assert [(a.file, b.file) for a, b in pairs] == [
        ("cmu/asfamc/18/18_01.amc", "cmu/asfamc/19/19_01.amc"),
        ("cmu/asfamc/18/18_02.amc", "cmu/asfamc/19/19_02.amc"),
    ]
    assert [a.label for a, _ in pairs] == ["handshake", "handshake"]
    pull = index.find("cmu/asfamc/18/18_03.amc")
    assert (pull.category, pull.label, pull.partner_file) == ("interaction", "pull", "")
    assert index.find("cmu/asfamc/20/20_01.amc").label == "chicken_dance"
    a = index.find("cmu/asfamc/18/18_02.amc")
    assert (a.fps, a.frames, a.subject, a.trial) == (120, 32, "18", "02")
    ma, mb = index.load_pair(*pairs[0])
    assert ma.n_frames == mb.n_frames == 31 and ma.fps == 120
    # a 404 trial ends the probing of the subject (here after the default three)
    trials = [p.rsplit("/", 1)[1] for p, _, _ in site.requested(f"{CMU}/19/")]
    assert trials == ["19.asf", "19_01.amc", "19_02.amc", "19_03.amc", "19_04.amc", "19_05.amc"]
    site.seen.clear()
    again = site.fetch(tmp_path, subjects=(18, 19, 20, 21))
    assert len(MocapIndex.load(tmp_path)) == 12 and not again.indexed
    # only the file rejected before is asked for again (and rejected again)
    assert [p for p, _, status in site.seen if status != 404] == [f"{CMU}/20/20_02.amc"]
    assert [f for f, _ in again.rejected] == ["cmu/asfamc/20/20_02.amc"]


@needs_amc
def test_real_files_index_like_the_shared_collection(site, tmp_path, mocap):
    """Real CMU ASF/AMC and Bandai BVH served as their sites do: same frames as the shared INDEX."""
    shared = {
        f"{CMU}/02/02.asf": mocap.root / "cmu/asfamc/02/02.asf",
        **{
            f"{CMU}/02/{e.name}.amc": e.path
            for e in mocap.query(source="cmu", subject="02")
            if e.trial in ("01", "03", "04")
        },
        **{
            f"{BANDAI}/Bandai-Namco-Research-Motiondataset-{k}/data/dataset-{k}_{name}.bvh": (
                mocap.root / f"bandai/dataset-{k}/{name}.bvh.gz"
            )
            for k, name in ((1, "walk_happy_001"), (2, "walk_elderly_001"))
        },
    }
    for url_path, path in shared.items():
        site.files[url_path] = read_text(path).encode()
    report = site.fetch(tmp_path, subjects=(2,))
    assert not report.rejected and len(report.indexed) == 5  # 02_02 is skipped over
    for e in MocapIndex.load(tmp_path):
        original = mocap.find(e.file + ".gz")
        assert (e.frames, e.fps) == (original.frames, original.fps)
        if e.source == "bandai":
            assert (e.category, e.label) == (original.category, original.label)
        else:  # subject 02 is not in the built-in table of two-person trials
            assert (e.category, e.label) == ("activity", "unknown")


def test_cli_fetch_and_bad_dest(site, tmp_path, capsys):
    bandai_site(site)
    dest = tmp_path / "data"
    main(
        [
            "data",
            "fetch",
            "--dest",
            str(dest),
            "--subjects",
            "",
            "--base-url-bandai",
            site.url + BANDAI,
        ]
    )
    assert "6 new" in capsys.readouterr().err
    assert len(MocapIndex.load(dest)) == 6

    not_a_folder = tmp_path / "file.txt"
    not_a_folder.write_text("x")
    with pytest.raises(SystemExit) as exc:
        main(["data", "fetch", "--dest", str(not_a_folder), "--subjects", "18"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not a folder" in err and str(not_a_folder) in err

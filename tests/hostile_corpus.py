"""Generators of hostile inputs (motion files, model files, option values) and a runner of
the command line that measures what a run costs.

Nothing here is a corpus of files: every hostile input is made in a temporary
folder by a test. The runner starts the real console entry point in a child
process and reports its exit code, stderr lines, CPU and wall time and peak
memory (``os.wait4``'s ``ru_maxrss`` of that one child).
"""

from __future__ import annotations

import atexit
import gzip
import json
import os
import subprocess
import sys
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CLI = [sys.executable, "-c", "from markovmotion.cli import main; main()"]
GIB = 1 << 30
# safety net only (virtual memory, far above the 1 GB of peak resident memory asserted)
ADDRESS_SPACE_CAP = 6 * GIB
# the counts of hostile runs of this session, reported by the tests' summary
COUNTS = {"tried": 0, "clean": 0, "failed": 0}


@atexit.register
def _report() -> None:  # pragma: no cover - printed after the session
    if COUNTS["tried"]:
        print(f"hostile runs: {COUNTS}", file=sys.stderr)


@dataclass
class Run:
    code: int
    stdout: str
    stderr: str
    cpu_s: float
    wall_s: float
    max_rss_bytes: int

    @property
    def lines(self) -> list[str]:
        return [ln for ln in self.stderr.splitlines() if ln.strip()]


#: Runs the command line as its own child and writes that child's exit status, CPU time and
#: peak resident memory to the file ``argv[1]``. Measured in a grandchild because Linux counts
#: in a process's peak the memory it had before ``exec``: a child forked straight from this
#: test process would start at the test process's size (a gigabyte late in the suite).
LAUNCHER = """
import json, os, resource, sys
report, cap = sys.argv[1], int(sys.argv[2])
pid = os.fork()
if pid == 0:
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    cli = "from markovmotion.cli import main; main()"
    os.execv(sys.executable, [sys.executable, "-c", cli, *sys.argv[3:]])
_, status, usage = os.wait4(pid, 0)
with open(report, "w") as f:
    json.dump({"status": status, "cpu": usage.ru_utime + usage.ru_stime,
               "rss": usage.ru_maxrss * 1024}, f)
code = os.waitstatus_to_exitcode(status)
sys.exit(code if code >= 0 else 128 - code)
"""


def run_cli(args: list[str], env: dict[str, str] | None = None, timeout: float = 120) -> Run:
    """Run ``markovmotion ARGS`` in a child process (:data:`LAUNCHER`); kill it after
    ``timeout`` wall seconds."""
    import signal
    import tempfile

    full_env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    full_env.update(env or {})
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "usage.json"
        proc = subprocess.Popen(
            [sys.executable, "-c", LAUNCHER, str(report), str(ADDRESS_SPACE_CAP), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            env=full_env,
            start_new_session=True,  # the launcher and the command line, killed together
        )
        out: dict[str, bytes] = {}
        readers = [
            threading.Thread(target=lambda k=k, s=s: out.__setitem__(k, s.read()))
            for k, s in (("out", proc.stdout), ("err", proc.stderr))
        ]
        for t in readers:
            t.start()
        killer = threading.Timer(timeout, lambda: os.killpg(proc.pid, signal.SIGKILL))
        killer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            killer.cancel()
        for t in readers:
            t.join()
        for pipe in (proc.stdout, proc.stderr):  # read to the end; closed now
            pipe.close()
        if report.exists():  # the command line's own status and cost
            got = json.loads(report.read_text())
            status, cpu, rss = got["status"], got["cpu"], got["rss"]
        else:  # the launcher was killed (timeout)
            cpu, rss = usage.ru_utime + usage.ru_stime, usage.ru_maxrss * 1024
    proc.returncode = os.waitstatus_to_exitcode(status)
    return Run(
        code=proc.returncode,
        stdout=out.get("out", b"").decode("utf-8", "replace"),
        stderr=out.get("err", b"").decode("utf-8", "replace"),
        cpu_s=cpu,
        wall_s=time.perf_counter() - start,
        max_rss_bytes=rss,
    )


def check_clean(run: Run, *names: str, cpu_s: float = 10.0, rss: int = GIB) -> None:
    """Exit 2, exactly one stderr line naming ``names``, no traceback or warning, bounded cost."""
    COUNTS["tried"] += 1
    try:
        assert run.code == 2, (run.code, run.stderr[-2000:])
        assert len(run.lines) == 1, run.stderr[-2000:]
        assert "Traceback" not in run.stderr and "Warning" not in run.stderr, run.stderr
        for name in names:
            assert name in run.lines[0], (name, run.lines[0])
        assert run.cpu_s < cpu_s, f"{run.cpu_s:.1f} s of CPU: {run.lines}"
        assert run.max_rss_bytes < rss, f"{run.max_rss_bytes / 1e6:.0f} MB peak: {run.lines}"
    except AssertionError:
        COUNTS["failed"] += 1
        raise
    COUNTS["clean"] += 1


# ---------------------------------------------------------------- motion files
def bvh(hierarchy: str, frames: list[str], frame_time: str = "0.033333") -> str:
    return f"{hierarchy}MOTION\nFrames: {len(frames)}\nFrame Time: {frame_time}\n" + "".join(
        f"{f}\n" for f in frames
    )


SMALL_HIERARCHY = (
    "HIERARCHY\nROOT hips\n{\n OFFSET 0 0 0\n"
    " CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    " JOINT spine\n {\n  OFFSET 0 10 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n"
    "  End Site\n  {\n   OFFSET 0 10 0\n  }\n }\n}\n"
)
SMALL_CHANNELS = 9


def small_bvh(n_frames: int = 3, value: str = "0", frame_time: str = "0.033333") -> str:
    return bvh(SMALL_HIERARCHY, [" ".join([value] * SMALL_CHANNELS)] * n_frames, frame_time)


def nested_bvh(depth: int) -> str:
    """``depth`` JOINTs each inside the previous one (a recursive parser overflows)."""
    head = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    for i in range(1, depth):
        head += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 0"]
    head += ["}"] * depth
    return bvh("\n".join(head) + "\n", ["0 0 0"] * 2)


def sibling_bvh(n: int) -> str:
    """``n`` JOINTs side by side under the root (a quadratic name check is slow)."""
    head = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0", "CHANNELS 0"]
    for i in range(n):
        head.append(f"JOINT s{i} {{ OFFSET 0 1 0 CHANNELS 0 }}")
    head.append("}")
    return bvh("\n".join(head) + "\n", [""] * 2)


def gzip_bomb(path: Path, megabytes: int, prefix: bytes = b"") -> Path:
    """A ``.gz`` that decompresses to ``prefix`` + ``megabytes`` MB of spaces (small on disk)."""
    block = b" " * (1 << 20)
    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(prefix)
        for _ in range(megabytes):
            fh.write(block)
    return path


def amc_pair(folder: Path, frames: list[str]) -> Path:
    """``01.asf`` + ``01_01.amc`` (root only) with the given frame bodies."""
    (folder / "01.asf").write_text(
        ":version 1.10\n:name t\n:units\n  mass 1.0\n  length 1.0\n  angle deg\n"
        ":root\n  order TX TY TZ RX RY RZ\n  axis XYZ\n  position 0 0 0\n"
        "  orientation 0 0 0\n:bonedata\n  begin\n    id 1\n    name lfemur\n"
        "    direction 0 -1 0\n    length 10\n    axis 0 0 0 XYZ\n    dof rx ry rz\n"
        "  end\n:hierarchy\n  begin\n    root lfemur\n  end\n"
    )
    amc = folder / "01_01.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n" + "".join(frames))
    return amc


# ---------------------------------------------------------------- model files
def write_npz(path: Path, header, arrays: dict[str, np.ndarray], raw_header: bytes | None = None):
    """An ``.npz`` written as ``persist.save_npz`` would, with any header (even a non-object)."""
    blob = raw_header if raw_header is not None else json.dumps(header).encode("utf-8")
    np.savez(path, __header__=np.frombuffer(blob, dtype=np.uint8), **arrays)
    return path


def zip_bomb_model(path: Path, megabytes: int) -> Path:
    """A model file whose one array decompresses to ``megabytes`` MB (a few hundred KB on disk)."""
    header = {"format": "markovmotion-model", "format_version": 1, "kind": "gait-hsmm"}
    blob = json.dumps(header).encode()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        buf = __import__("io").BytesIO()
        np.save(buf, np.frombuffer(blob, dtype=np.uint8))
        zf.writestr("__header__.npy", buf.getvalue())
        n = megabytes * (1 << 20) // 8
        head = __import__("io").BytesIO()
        np.lib.format.write_array_header_1_0(
            head, {"descr": "<f8", "fortran_order": False, "shape": (n,)}
        )
        with zf.open("model/means_.npy", "w", force_zip64=True) as member:
            member.write(head.getvalue())
            zeros = bytes(1 << 20)
            for _ in range(megabytes):
                member.write(zeros)
    return path

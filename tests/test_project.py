"""Project checks that CI runs through the README's one test command.

Lint and formatting (ruff), the import layers of ``[tool.importlinter]`` in
pyproject.toml (import-linter), and the documentation site (``mkdocs build
--strict``, API reference from the docstrings). Each runs as a subprocess from
the project root, with the interpreter running the tests, and prints its
output when it fails.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CODE = ["src", "tests", "benchmarks"]
LINT_IMPORTS = (
    "import sys; from importlinter.cli import lint_imports_command; "
    "sys.exit(lint_imports_command(prog_name='lint-imports'))"
)


def run(args: list[str], timeout: float = 600) -> None:
    """Run ``args`` in the project root; fail with its output unless it exits 0."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # mkdocs-material's banner, not a warning
    proc = subprocess.run(
        args, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout, check=False
    )
    if proc.returncode != 0:
        pytest.fail(
            f"{' '.join(args)} exited {proc.returncode}\n"
            f"--- stdout ---\n{proc.stdout}\n--- stderr ---\n{proc.stderr}",
            pytrace=False,
        )


def test_ruff_check() -> None:
    run([sys.executable, "-m", "ruff", "check", *CODE])


def test_ruff_format() -> None:
    run([sys.executable, "-m", "ruff", "format", "--check", *CODE])


def test_import_layers() -> None:
    """cli > web | video > demo > evaluate > models > features > algorithms > io > core."""
    run([sys.executable, "-c", LINT_IMPORTS])


def test_docs_build_strict(tmp_path: Path) -> None:
    """The mkdocs site builds with no warning (broken links, missing API objects)."""
    run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")])


@pytest.mark.parametrize("script", sorted((ROOT / "benchmarks").glob("*.py")), ids=lambda p: p.name)
def test_benchmarks_import_what_exists(script: Path) -> None:
    """Every ``from markovmotion... import name`` of a benchmark names something that exists
    (the benchmarks need the ``bench`` extra's peers to run, so they are not imported whole)."""
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("markovmotion"):
            module = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(module, alias.name) or importlib.util.find_spec(
                    f"{node.module}.{alias.name}"
                ), f"{script.name}: {node.module} has no {alias.name}"


def test_the_windowed_steps_target_is_the_same_in_the_docs_and_its_benchmark() -> None:
    """docs/speed.md's target for the windowed step against hmmlearn is the one
    benchmarks/dualhmm_bench.py prints (it had printed ">= 10x" beside the docs' 150x)."""
    script = ast.parse((ROOT / "benchmarks" / "dualhmm_bench.py").read_text(encoding="utf-8"))
    target = next(
        ast.literal_eval(node.value)
        for node in script.body
        if isinstance(node, ast.Assign) and ast.unparse(node.targets[0]) == "STEP_TARGET"
    )
    speed = (ROOT / "docs" / "speed.md").read_text(encoding="utf-8")
    row = next(line for line in speed.splitlines() if line.startswith("| windowed step ("))
    assert row.split(" | ")[4] == f">= {target:g}x", row


def test_ci_runs_exactly_the_readme_test_command() -> None:
    """.ci/run is the README's test command (its browser step included), and the suite itself
    installs nothing: no package manager is called from the tests (issue 22)."""
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)\n```", readme, flags=re.S)
    (command,) = [b for b in blocks if "pytest" in b]
    ci = [ln for ln in (ROOT / ".ci/run").read_text().splitlines() if ln and ln[0] != "#"]
    assert ci == ["set -euo pipefail", 'cd "$(dirname "$0")/.."', command]
    assert command.startswith("scripts/install-test-browser && ")
    conftest = (ROOT / "tests/conftest.py").read_text()
    assert "apt-get install" not in conftest and "subprocess" not in conftest


HEAVY = ("sklearn", "scipy.stats", "numba")
START_UP = (
    "import sys, contextlib, io\n"
    "import markovmotion.cli as cli\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    cli.main(['--help'])\n"
    "    cli.main(['chain', 'train', '--help'])\n"
    "print(' '.join(m for m in {heavy!r} if m in sys.modules))\n"
)


def test_command_line_starts_without_heavy_imports() -> None:
    """``markovmotion --help`` (every command registered, its help printed) imports neither
    scikit-learn, scipy.stats nor numba: the commands import them when they run."""
    code = START_UP.format(heavy=HEAVY)
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert proc.stdout.split() == [], f"imported at start-up: {proc.stdout.strip()}"
    probe = f"import markovmotion.cli.chain, sys\n{code.splitlines()[-1]}"  # the probe can fail
    code_with_model = "import markovmotion.models\n" + probe
    proc = subprocess.run(
        [sys.executable, "-c", code_with_model], cwd=ROOT, capture_output=True, text=True
    )
    assert "sklearn" in proc.stdout.split(), proc.stderr


def test_every_numba_function_is_cached() -> None:
    """Every ``numba.njit`` / ``jit`` / ``vectorize`` in the package and benchmarks says
    ``cache=True``: numba compiles once per machine, not once per run."""
    missing, seen = [], 0
    for path in [*(ROOT / "src").rglob("*.py"), *(ROOT / "benchmarks").glob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.FunctionDef):
                continue
            for dec in node.decorator_list:
                call = dec if isinstance(dec, ast.Call) else None
                func = call.func if call is not None else dec
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if name not in ("njit", "jit", "vectorize", "guvectorize"):
                    continue
                seen += 1
                cached = call is not None and any(
                    k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True
                    for k in call.keywords
                )
                if not cached:
                    missing.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert seen > 10  # the scan finds the compiled recursions
    assert not missing, "numba functions without cache=True: " + ", ".join(missing)


def _documented_commands() -> list[tuple[str, list[str]]]:
    """Every ``markovmotion ...`` command line of the README's and docs/' shell blocks, as
    (file, arguments): continuation lines joined, what follows ``&&``, ``|``, ``;`` or a
    redirection dropped, ``[optional parts]`` and ``...`` left out, ``$VARIABLES`` kept as
    words (a value is a value to the parser)."""
    import shlex

    out = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = doc.read_text()
        for lang, block in re.findall(r"^\s*```(\w*)\n(.*?)^\s*```", text, re.S | re.M):
            if lang not in ("", "bash", "sh", "console", "shell"):
                continue
            for line in re.sub(r"\\\n\s*", " ", block).splitlines():
                found = re.search(r"(?:^|[;&|(]\s*|\$ )markovmotion\s+(.*)", line.strip())
                if not found or line.strip().startswith("#"):
                    continue
                words = re.split(r"\s(?:&&|\|\||\||;|>|2>)\s", found.group(1))[0]
                words = re.sub(r"\[[^\]]*\]", "", words)
                args = [w for w in shlex.split(words, comments=True) if w != "..."]
                out.append((f"{doc.relative_to(ROOT)}: markovmotion {words.strip()}", args))
    return out


def test_every_documented_command_parses() -> None:
    """The commands the README and docs/ show name commands and options that exist, with
    values of the right types and choices: the parser alone, nothing run (an option renamed
    in the code and not in the docs fails here)."""
    from typer.main import get_command

    from markovmotion.cli import _register, app

    _register()

    def parse(command, args: list[str], parent=None, name: str = "markovmotion") -> None:
        ctx = command.make_context(name, list(args), parent=parent)
        if hasattr(command, "resolve_command"):  # a group: its subcommand in turn
            rest = [*getattr(ctx, "_protected_args", []), *ctx.args]
            if rest:
                sub_name, sub, rest = command.resolve_command(ctx, rest)
                parse(sub, rest, ctx, sub_name)

    root = get_command(app)
    commands = _documented_commands()
    assert len(commands) >= 50, f"only {len(commands)} documented commands found"
    wrong = []
    for where, args in commands:
        try:
            parse(root, args)
        except Exception as exc:  # typer's own click: its errors have format_message
            if type(exc).__name__ == "Exit":  # --help and the like
                continue
            message = exc.format_message() if hasattr(exc, "format_message") else repr(exc)
            wrong.append(f"{where}\n    {message}")
    assert not wrong, "\n".join(wrong)
    bad = [["dualhmm", "train", "--no-such-option"], ["dualhmm", "tran"]]
    for args in bad:  # the check itself can fail
        with pytest.raises(Exception, match="No such"):
            parse(root, args)


def _python_blocks() -> list[tuple[str, str]]:
    """Every ``python`` block of the README and docs/, as (``file#n``, code)."""
    out = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        blocks = re.findall(r"^\s*```python\n(.*?)^\s*```", doc.read_text(), re.S | re.M)
        out += [(f"{doc.relative_to(ROOT)}#{i}", code) for i, code in enumerate(blocks)]
    return out


#: The blocks that continue an example the page gives in prose or elsewhere (they read
#: names no block before them on the page defines), and why none is run. A page's other
#: blocks run in order, each on from the ones before it, as a reader would paste them.
FRAGMENTS = {
    "docs/contract.md#0": "saving and loading a model fitted before",
    "docs/contract.md#1": "the online loop of a model and take given before",
    "docs/speed.md#0": "a Dask cluster and the data of the section before",
}


def _pages() -> dict[str, list[tuple[str, str]]]:
    """Each page's blocks that run, in order (:data:`FRAGMENTS` left out)."""
    pages: dict[str, list[tuple[str, str]]] = {}
    for where, code in _python_blocks():
        if where not in FRAGMENTS:
            pages.setdefault(where.split("#")[0], []).append((where, code))
    return pages


def test_the_fragments_are_blocks_of_the_docs() -> None:
    """Every block :data:`FRAGMENTS` leaves out is still in the docs (the list cannot
    outlive them); any other block that does not run alone fails the next test."""
    assert set(FRAGMENTS) <= {where for where, _ in _python_blocks()}


@pytest.mark.parametrize("page", sorted(_pages()))
def test_every_documented_python_example_runs_as_written(page, tmp_path, monkeypatch):
    """Each page's whole examples (README and docs/) run as written, in order, in a folder
    of their own (what they write goes there), on the shared collection: a new user's trial
    found the online examples failing (A not at the partner's rate) while every command
    line parsed."""
    from markovmotion.data.index import data_root

    monkeypatch.setenv("MARKOVMOTION_DATA", str(data_root()))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__doc_example__"}
    for where, code in _pages()[page]:
        exec(compile(code, where, "exec"), namespace)

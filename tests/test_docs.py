"""The documentation's code runs: every Python block of README.md and docs/*.md and every
docs/examples/*.py is executed (from a folder that sees the repository's sample_data); every
``diegocal`` command of their shell blocks is parsed by the command's own parser (its options and
arguments exist and take those values). Running every shell block end to end takes minutes: it
is the slow case, left to ``make bench``."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import typer

from diegocal.causes import CAUSES
from diegocal.cli import app
from diegocal.errors import DiegocalError

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
EXAMPLES = sorted((ROOT / "docs" / "examples").glob("*.py"))


def blocks(language: str) -> list[tuple[str, int, str]]:
    """(file, line, text) of every fenced block of ``language`` in the docs."""
    out = []
    for path in DOCS:
        text = path.read_text()
        for m in re.finditer(rf"^```{language}\n(.*?)^```", text, flags=re.M | re.S):
            out.append((path.name, text[: m.start()].count("\n") + 1, m.group(1)))
    return out


def commands(block: str) -> list[list[str]]:
    """The ``diegocal`` command lines of a shell block (continuations joined, comments dropped,
    shell variables set in the block substituted)."""
    joined = block.replace("\\\n", " ")
    env, out = {}, []
    for line in joined.splitlines():
        words = shlex.split(line, comments=True)
        if not words:
            continue
        if len(words) == 1 and re.fullmatch(r"\w+=\S+", words[0]):
            key, value = words[0].split("=", 1)
            env[key] = value
            continue
        words = [re.sub(r"\$(\w+)", lambda m: env.get(m.group(1), m.group(0)), w) for w in words]
        command: list[str] = []
        for w in [*words, "&&"]:  # a && b: two commands
            if w in ("&&", ";", "||", "|"):
                if command and command[0] in ("diegocal", ".venv/bin/diegocal"):
                    out.append(command[1:])
                command = []
            else:
                command.append(w)
    return out


def _workdir(tmp_path: Path) -> Path:
    """A folder where the docs' relative paths resolve: robots and docs linked in, sample_data's
    folders made and its files linked (a command's default output beside its log, ``sgp-fit
    sample_data/real/tx40.h5``, lands here, not in the repository)."""
    for name in ("robots", "docs"):
        (tmp_path / name).symlink_to(ROOT / name)
    for path in (ROOT / "sample_data").rglob("*"):
        if path.is_file():
            link = tmp_path / path.relative_to(ROOT)
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(path)
    (tmp_path / "out").mkdir()
    return tmp_path


SHELL = [(f, line, c) for f, line, block in blocks("sh") for c in commands(block)]


@pytest.mark.parametrize("where, line, argv", SHELL, ids=[f"{f}:{n}:{a[0]}" for f, n, a in SHELL])
def test_every_documented_command_parses(where, line, argv):
    if "--help" in argv:
        return  # help exits before parsing the rest; `diegocal --help` itself is tested in tests/cli
    group = typer.main.get_command(app)
    ctx = group.make_context("diegocal", list(argv), resilient_parsing=False)
    name, cmd, rest = group.resolve_command(ctx, list(argv))
    while isinstance(cmd, typer.core.TyperGroup):  # simulate kinematics: a group's command
        sub = cmd.make_context(name, rest, parent=ctx)
        name, cmd, rest = cmd.resolve_command(sub, rest)
        ctx = sub
    try:
        cmd.make_context(name, rest, parent=ctx)  # raises on an unknown option or a bad value
    except (DiegocalError, typer.Exit):  # a callback looked for a file of the lab's: parsed all the same
        pass


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_runs(path, tmp_path):
    work = _workdir(tmp_path)
    res = subprocess.run([sys.executable, str(path)], cwd=work, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip()


PYTHON = blocks("python")


@pytest.mark.parametrize("where, line, code", PYTHON, ids=[f"{f}:{n}" for f, n, _ in PYTHON])
def test_every_python_block_runs(where, line, code, tmp_path):
    work = _workdir(tmp_path)
    res = subprocess.run([sys.executable, "-c", code], cwd=work, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]


@pytest.mark.slow
@pytest.mark.parametrize("where, line, block", blocks("sh"), ids=[f"{f}:{n}" for f, n, _ in blocks("sh")])
def test_every_shell_block_runs(where, line, block, tmp_path):
    """Each shell block in a fresh folder, ``diegocal`` from this environment; blocks that need
    what only a lab has (its own files, a cluster, make) are skipped by their first word."""
    first = shlex.split(block, comments=True)[:1]
    if not first or first[0] in ("make", "dask", "source", "pip", "OMP_NUM_THREADS=1"):
        pytest.skip("needs a make run, a cluster or an environment of its own")
    if "trial.c3d" in block or "arm.bag" in block or "logs/" in block:
        pytest.skip("needs the lab's own files")
    work = _workdir(tmp_path)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    res = subprocess.run(["bash", "-e", "-c", block], cwd=work, env=env, capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, (res.stdout[-1000:], res.stderr[-2000:])


def test_the_vocabulary_table_lists_every_cause_of_the_registry():
    """docs/formats.md's vocabulary table has a row per cause, with the registry's domain and role."""
    text = (ROOT / "docs" / "formats.md").read_text()
    for c in CAUSES.values():
        assert re.search(rf"^\| {c.domain} \| `{c.id}` \| {c.role} \|", text, re.M), c.id

"""`diegocal --help` and every `COMMAND --help` answer at once: in a fresh interpreter, a help
loads no heavy library and none of diegocal's fitting code (counted in ``sys.modules``, not timed).

Heavy, measured with ``python -X importtime -c "import X"`` (2-core machine, load ~4): scipy.signal
1.5 s, distributed 0.76 s, pandas 0.58 s, scipy.optimize 0.47 s, matplotlib 0.38 s (pyplot 0.86 s),
pinocchio 0.29 s, dask 0.25 s, h5py 0.22 s, numpy 0.11 s. Light enough to allow: yaml 14 ms, and
pydantic (67 ms), which typer itself loads to parse options.
"""

import json
import os
import subprocess
import sys

import pytest
import typer.core
import typer.main

from diegocal.cli import app

HEAVY = ("numpy", "scipy", "h5py", "pandas", "pinocchio", "matplotlib", "dask", "distributed", "sklearn", "torch")
#: the diegocal modules a help may load: the package, its errors, its vocabularies (plain data) and
#: the command line itself
LIGHT_DIEGOCAL = ("diegocal", "diegocal.errors", "diegocal.causes", "diegocal.domains", "diegocal.cli")

#: Command modules that still import heavy modules at module level: being edited on other
#: branches (issue #16); their commands' help is an expected failure (strict: it fails once they
#: are light, to drop them from here), and the other helps are counted with them stubbed out.
PENDING: dict[str, str] = {}

SCRIPT = """
import json, sys, types
stubs, helps = json.loads(sys.argv[1]), json.loads(sys.argv[2])
for name in stubs:  # a pending command module, left out
    sys.modules[name] = types.ModuleType(name)
import diegocal.cli
loaded = {}
for args in helps:
    sys.argv = ["diegocal", *args]
    try:
        diegocal.cli.main()
    except SystemExit as exc:
        assert exc.code in (0, None), (args, exc.code)
    loaded[" ".join(args)] = sorted(sys.modules)
print("\\n" + json.dumps(loaded))
"""


def _commands():
    """(command path, module) of the app, its groups and every command (each imported here)."""

    def walk(command, path, ctx):
        callback = getattr(command, "callback", None)
        yield path, getattr(callback, "__module__", None)
        if isinstance(command, typer.core.TyperGroup):
            ctx = typer.Context(command, parent=ctx, info_name=path[-1] if path else "diegocal")
            for name in command.list_commands(ctx):
                yield from walk(command.get_command(ctx, name), (*path, name), ctx)

    return list(walk(typer.main.get_command(app), (), None))


COMMANDS = _commands()


def run_helps(helps, stubs=()) -> dict[str, list[str]]:
    """Run the helps one after another in one fresh interpreter; {args: sys.modules after it}.
    The count is cumulative: the first help that loads a heavy module is the culprit."""
    env = {**os.environ, "COLUMNS": "100"}
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(list(stubs)), json.dumps([list(h) for h in helps])],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert out.returncode == 0 and out.stdout.strip(), out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def heavy(modules) -> list[str]:
    """The modules in ``modules`` that a help must not load."""
    return [
        m
        for m in modules
        if m.split(".")[0] in HEAVY
        or (m.startswith("diegocal") and m not in LIGHT_DIEGOCAL and not m.startswith("diegocal.cli."))
    ]


@pytest.fixture(scope="module")
def light_helps():
    """Every help but the pending commands', in that order, with the pending modules stubbed out."""
    helps = [(*path, "--help") for path, module in COMMANDS if module not in PENDING]
    return run_helps(helps, stubs=PENDING)


@pytest.mark.parametrize("path", [p for p, m in COMMANDS if m not in PENDING], ids=lambda p: " ".join(p) or "diegocal")
def test_a_help_loads_nothing_heavy(light_helps, path):
    modules = light_helps[" ".join((*path, "--help"))]
    assert "typer" in modules  # the help really ran
    assert heavy(modules) == []


@pytest.mark.xfail(bool(PENDING), strict=True, reason="; ".join(f"{m} {why}" for m, why in PENDING.items()))
def test_the_whole_app_help_loads_nothing_heavy():
    """Without stubs, what a user gets: `diegocal --help` and the pending commands' helps (an
    expected failure while PENDING is not empty)."""
    helps = [("--help",)] + [(*path, "--help") for path, module in COMMANDS if module in PENDING]
    for modules in run_helps(helps).values():
        assert heavy(modules) == []


def test_a_help_imports_only_its_own_command_module():
    """`diegocal --help` lists the commands from diegocal.cli.app.COMMANDS without importing any
    command module; `diegocal stac --help` imports stac's alone (pip's lazy command table)."""
    loaded = run_helps([("--help",), ("stac", "--help")])
    modules = {k: {m for m in v if m.startswith("diegocal.cli.") and m.endswith("_cmd")} for k, v in loaded.items()}
    assert modules["--help"] == set()
    assert modules["stac --help"] == {"diegocal.cli.stac_cmd"}


def test_a_group_help_does_not_load_the_option_coercion():
    """typer coerces option values with pydantic (0.1 s to import): a help passes through the
    `diegocal` group, whose --help flag must be read without it (#32: help under 0.5 s)."""
    for modules in run_helps([("--help",), ("stac", "--help"), ("simulate", "kinematics", "--help")]).values():
        assert "pydantic" not in modules and "typer._adapters" not in modules


def test_the_command_table_is_the_commands_own():
    """COMMANDS names every command, the module that defines it and its help's first paragraph."""
    from diegocal.cli.app import COMMANDS as TABLE

    found = {path: module for path, module in COMMANDS if path and path != ("simulate",)}
    assert found == {path: module for path, (module, _) in TABLE.items()}
    for path, (_, line) in TABLE.items():
        command = typer.main.get_command(app)
        ctx = typer.Context(command, info_name="diegocal")
        for name in path:
            command = command.get_command(ctx, name)
        assert line == " ".join(command.help.strip().split("\n\n", 1)[0].split()), path


def test_the_count_sees_heavy_modules():
    """The check can fail: this test process, which ran no command, has numpy, h5py and diegocal.io
    loaded (through the pending modules and the test suite), and the count says so."""
    import diegocal.io  # noqa: F401

    found = heavy(sys.modules)
    assert {"numpy", "h5py", "diegocal.io"} <= set(found)
    assert not {"diegocal", "diegocal.errors", "diegocal.cli", "diegocal.cli.common", "typer"} & set(found)

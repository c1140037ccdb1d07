"""Every command's help reads as sentences: each argument and option says what it is (a sentence
ending in a period), a flag shows no value type, and nothing in the text is eaten as rich markup
(``[default: ...]`` inside a help string once left "Robot directory ." behind)."""

import re

import pytest
import typer.core
import typer.main
from typer.testing import CliRunner

from diegocal.cli import app

runner = CliRunner()


def _walk(command, path=(), ctx=None):
    yield path, command
    if isinstance(command, typer.core.TyperGroup):
        ctx = typer.Context(command, parent=ctx, info_name=path[-1] if path else "diegocal")
        for name in command.list_commands(ctx):
            yield from _walk(command.get_command(ctx, name), (*path, name), ctx)


COMMANDS = [(p, c) for p, c in _walk(typer.main.get_command(app)) if p]


@pytest.mark.parametrize("path, command", COMMANDS, ids=[" ".join(p) for p, _ in COMMANDS])
def test_every_parameter_says_what_it_is(path, command):
    for param in command.params:
        text = " ".join((param.help or "").split())
        assert text.endswith("."), f"{' '.join(path)} {param.name}: {text!r}"


@pytest.mark.parametrize("path", [p for p, _ in COMMANDS], ids=[" ".join(p) for p, _ in COMMANDS])
def test_the_help_as_printed(path):
    result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "250"})
    assert result.exit_code == 0, result.output
    lines = [line.strip("│ ") for line in result.output.splitlines()]
    assert not any(re.search(r"\s\.$", line) for line in lines), result.output  # a default eaten as markup
    assert "<bool>" not in result.output  # a flag takes no value
    # an option's line starts with its name (a wrapped help line may start with one mentioned in it)
    options = [line for line in lines if re.match(r"--[a-z][\w-]*(\s|$)", line)]
    assert options and all(len(line.split(None, 1)) == 2 for line in options), result.output  # each has a text

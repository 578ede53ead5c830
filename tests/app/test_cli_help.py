"""Every command's --help shows its options' defaults, which the help texts give in brackets
('[one per core]'): read as Rich markup, a bracket that looks like a tag was dropped from the page."""

from __future__ import annotations

import re

import pytest
import typer
from typer.core import TyperGroup
from typer.testing import CliRunner

from app.cli import _register_commands, app

_register_commands()
COMMAND = typer.main.get_command(app)
assert isinstance(COMMAND, TyperGroup)


def bracketed_help(command: typer.core.TyperCommand) -> list[str]:
    """The bracketed parts of the help texts of a command's options, e.g. '[one per core]'."""
    return [part for p in command.params for part in re.findall(r"\[[^\]]*\]", getattr(p, "help", None) or "")]


@pytest.mark.parametrize("name", sorted(COMMAND.commands))
def test_help_keeps_every_bracketed_default(name: str) -> None:
    result = CliRunner().invoke(app, [name, "--help"], env={"COLUMNS": "4000"})
    assert result.exit_code == 0, result.output
    page = " ".join(result.output.split())
    for part in bracketed_help(COMMAND.commands[name]):
        assert " ".join(part.split()) in page, f"ccsm {name} --help lost {part!r}"


def test_some_command_gives_its_defaults_in_brackets() -> None:
    # Else the test above checks nothing.
    assert sum(len(bracketed_help(c)) for c in COMMAND.commands.values()) >= 5

"""The ``ccsm`` command line: one typer app, one module per command group.

Exit status: 0 on success, 2 on bad input (unreadable file, unknown CRS, bad option, no contour that can be
built), 1 on an internal error (one line on stderr names the log file with its traceback: app/cli/crash_log.py).
"""

from __future__ import annotations

import inspect

import typer

app = typer.Typer(
    name="ccsm",
    help="Continuously generalized terrain contours (CCSM, Qian et al. 2021): simplify, evaluate, build, export "
    "and serve tiles.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # Help texts give defaults in brackets ('[one per core]'): plain text, not Rich markup, which would drop them.
    rich_markup_mode=None,
)


def _register_commands() -> None:
    # Each module adds its commands to ``app``; imported here so ``ccsm --help`` lists them all.
    from app.cli import (
        commands_engine,  # noqa: F401  simplify, evaluate
        commands_export,  # noqa: F401  export
        commands_service,  # noqa: F401  serve, build
    )

    # ``ccsm --help`` lists each command with its docstring's whole first paragraph (its summary sentence,
    # which may wrap onto a second line): click would cut it to fit.
    for command in app.registered_commands:
        if command.short_help is None and command.callback is not None and command.callback.__doc__:
            command.short_help = command_summary(command.callback.__doc__)


def command_summary(doc: str) -> str:
    """A command docstring's first paragraph on one line."""
    return " ".join(inspect.cleandoc(doc).partition("\n\n")[0].split())


def main() -> None:
    """Entry point of the ``ccsm`` console script."""
    from app.cli.crash_log import internal_errors_exit

    _register_commands()
    with internal_errors_exit():
        app()

"""An engine error as the CLI says it: the input parameter it is about named as the CLI's option.

The engine's messages do not spell a parameter (``CCSMError.parameter`` carries its engine name), so each
front end names it in its own words: here ``--interval``, over HTTP the query parameter (app/http/errors.py).
"""

from __future__ import annotations

from engine.errors import CCSMError

#: The engine's parameter names as the options of the ``ccsm`` commands, with what to give.
CLI_OPTIONS: dict[str, str] = {
    "interval": "give --interval N (the contour interval, in the DEM's vertical unit)",
    "elevation_field": "give --elevation-field NAME",
}


def cli_message(exc: CCSMError) -> str:
    """The error's message, and which option to give when it is about one."""
    hint = CLI_OPTIONS.get(exc.parameter or "")
    return f"{exc}; {hint}" if hint else str(exc)

"""The CLI's internal errors: exit status 1 and one line pointing to a log file that holds the traceback, never
a traceback on the terminal (bad input is exit status 2 with a message: app/cli/__init__.py)."""

from __future__ import annotations

import os
import sys
import tempfile
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from engine.errors import short_reason


def write_crash_log(exc: BaseException) -> Path:
    """Write the traceback of ``exc`` (and the command line) to a new file in the temporary folder."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    fd, name = tempfile.mkstemp(prefix=f"ccsm-error-{stamp}-", suffix=".log")
    with os.fdopen(fd, "w") as fh:
        fh.write("command: " + " ".join(sys.argv) + "\n\n")
        fh.write("".join(traceback.format_exception(exc)))
    return Path(name)


@contextmanager
def internal_errors_exit() -> Iterator[None]:
    """Turn an unexpected exception into a short message, the log's path and exit status 1."""
    try:
        yield
    except Exception as exc:  # every expected error has left by now (SystemExit is not an Exception)
        try:
            where = f"the traceback is in {write_crash_log(exc)}"
        except OSError as log_error:
            where = f"no log could be written ({log_error.strerror or log_error})"
        print(f"internal error: {short_reason(exc)}; {where}", file=sys.stderr)
        sys.exit(1)

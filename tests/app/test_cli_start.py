"""What ``ccsm build`` and ``ccsm export`` import: neither is a web request, so neither loads the web framework
(FastAPI, Starlette, the service's modules), which cost each command half a second before any work."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.app.conftest import REPO

#: Prints, as the command exits, which web modules it loaded.
WATCH = (
    "import atexit, sys\n"
    "atexit.register(lambda: print('WEB', sorted(m for m in ('fastapi', 'starlette', 'app.service') "
    "if m in sys.modules)))\n"
    "from app.cli import main\n"
    "main()\n"
)


def web_modules_of(*args: object) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", WATCH, *map(str, args)], cwd=REPO, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stdout + done.stderr
    line = next(ln for ln in done.stdout.splitlines() if ln.startswith("WEB "))
    return eval(line[4:])  # noqa: S307 - a list of module names this test printed itself


def test_a_build_and_an_export_load_no_web_framework(tmp_path: Path, synthetic_path: Path) -> None:
    store = tmp_path / "ccsm.sqlite"
    assert web_modules_of("build", synthetic_path, "--store", store, "--id", "hills", "--workers", "1") == []
    archive = tmp_path / "hills.pmtiles"
    assert web_modules_of("export", "hills", "--store", store, "-o", archive, "--maxzoom", "10", "--workers", "1") == []
    assert archive.stat().st_size > 0

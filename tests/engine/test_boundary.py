"""The engine is pure: importing it must not pull in the web framework (STYLE.md section 4)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_importing_the_engine_does_not_import_fastapi_or_starlette() -> None:
    code = (
        "import json, sys\n"
        "import engine, engine.ccsm.build, engine.ccsm.ccs, engine.io.source, engine.store.store, "
        "engine.serve.renderer, engine.tiles.mvt, engine.tiles.grid\n"
        "web = ('fastapi', 'starlette', 'uvicorn', 'pydantic_settings')\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in web)))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.strip().splitlines()[-1]) == []

"""Issue 10: a render worker's first morph tile compiles nothing (the fork server's warm-up covered it).

Render workers are forked from a fork server that ran ``engine.warmup.warm_up`` (app/render_preload.py). A
kernel the warm-up misses is compiled by the first request that needs it, in every fresh worker: seconds
inside that request, with its worker held meanwhile. Here a fresh interpreter warms up, then draws morph
tiles of a real store, and reports every numba kernel that gained a compiled signature while it drew them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.app.conftest import LAT0, LON0
from tests.app.helpers import tile_for

REPO = Path(__file__).resolve().parents[2]

PROBE = """
import json, sys
from numba.core.registry import CPUDispatcher
from engine.warmup import warm_up
from engine.serve.renderer import Renderer
from engine.store.sqlite import CCSStore


def compiled():
    found = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("engine."):
            continue
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher):
                found[f"{name}.{attr}"] = len(value.signatures)
    return found


warm_up()
before = compiled()
renderer = Renderer(CCSStore(sys.argv[1]))
for z, x, y in json.loads(sys.argv[2]):
    renderer.morph_tile("hills", z, x, y)
after = compiled()
print(json.dumps(sorted(k for k, n in after.items() if n > before.get(k, 0))))
"""


def test_morph_tiles_compile_nothing_after_the_warm_up(built_store):
    tiles = [tile_for(LON0, LAT0, z) for z in (10, 12, 14)]
    out = subprocess.run(
        [sys.executable, "-c", PROBE, str(built_store), json.dumps(tiles)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []

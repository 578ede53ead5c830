"""Issue 10: a render worker's first morph tile compiles nothing (the fork server's warm-up covered it).

Render workers are forked from a fork server that ran ``engine.warmup.warm_up`` (app/render/preload.py). A
kernel the warm-up misses is compiled by the first request that needs it, in every fresh worker: seconds
inside that request, with its worker held meanwhile. Here a fresh interpreter warms up, then draws morph
tiles of a real store, and reports every numba kernel that gained a compiled signature while it drew them.
"""

from __future__ import annotations

import json

from tests.app.conftest import LAT0, LON0
from tests.app.helpers import tile_for
from tests.warmup_probe import compiled_after_warm_up

MORPH_TILES = """
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore

renderer = Renderer(CCSStore(sys.argv[1]))
n = 0
for z, x, y in json.loads(sys.argv[2]):
    n += renderer.morph_tile("hills", z, x, y).data is not None
"""


def test_morph_tiles_compile_nothing_after_the_warm_up(built_store):
    tiles = [tile_for(LON0, LAT0, z) for z in (10, 12, 14)]
    compiled, drawn = compiled_after_warm_up(MORPH_TILES, str(built_store), json.dumps(tiles))
    assert drawn > 0
    assert compiled == []

"""The warm-up compiles the build's kernels: a build in a fresh interpreter that warmed up compiles nothing.

numba compiles a kernel on its first call in each process (or loads it from its cache): a kernel the warm-up
misses costs that first build, or the first render worker that needs it, the compile. A fresh interpreter warms
up, builds real contours (part of the bundled sample, with its crossing repair), and reports every numba
kernel that gained a signature during the build.
"""

from __future__ import annotations

from tests.warmup_probe import compiled_after_warm_up

BUILD = """
from engine.ccsm.build import build_contour_set
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.params import BuildParams
from engine.types import ContourSet

source = read_source(sample_contours_path())
part = ContourSet(source.contours[::10], source.working_crs, source.source_crs, name="part")
n = len(build_contour_set(part, BuildParams(), workers=1).surfaces)
"""


def test_a_build_compiles_nothing_after_the_warm_up() -> None:
    compiled, surfaces = compiled_after_warm_up(BUILD)
    assert surfaces > 100
    assert compiled == []


TILES_OF_PIECES = """
import tempfile
from pathlib import Path
from engine.io.sample import sample_contours_path
from engine.build.datasets import SourceSpec, build_dataset
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

n = 0
with tempfile.TemporaryDirectory() as tmp:
    store = CCSStore(Path(tmp) / "sample.sqlite")
    build_dataset(store, SourceSpec(sample_contours_path(), "sample", "sample"), workers=1)
    bounds = Bounds(*store.dataset("sample").bounds_3857)
    before = compiled()  # counted from here: what the tiles compile, not the build
    per_tile = Renderer(store, contour_cache_bytes=0)  # every tile joins its stored pieces
    for z, x, y in tiles_covering(bounds, 13)[::7]:
        n += per_tile.tile("sample", z, x, y).data is not None
    store.close()
"""


def test_a_tile_of_stored_pieces_compiles_nothing_after_the_warm_up() -> None:
    compiled, drawn = compiled_after_warm_up(TILES_OF_PIECES)
    assert drawn > 5
    assert compiled == []

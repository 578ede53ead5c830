"""The warm-up compiles the build's kernels: a build in a fresh interpreter that warmed up compiles nothing.

numba compiles a kernel on its first call in each process (or loads it from its cache): a kernel the warm-up
misses costs that first build, or the first render worker that needs it, the compile. A fresh interpreter warms
up, builds real contours (part of the bundled sample, with its crossing repair), and reports every numba
kernel that gained a signature during the build.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

PROBE = """
import json, sys
from numba.core.registry import CPUDispatcher
from engine.warmup import warm_up


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
from engine.ccsm.build import build_contour_set
from engine.io.sample import sample_contours_path
from engine.io.source import read_source
from engine.params import BuildParams
from engine.types import ContourSet

source = read_source(sample_contours_path())
before = compiled()
part = ContourSet(source.contours[::10], source.working_crs, source.source_crs, name="part")
built = build_contour_set(part, BuildParams(), workers=1)
after = compiled()
print(json.dumps({"compiled": sorted(k for k, n in after.items() if n > before.get(k, 0)), "n": len(built.surfaces)}))
"""


def test_a_build_compiles_nothing_after_the_warm_up() -> None:
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=REPO, capture_output=True, text=True, timeout=600, check=True
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["n"] > 100
    assert report["compiled"] == []


TILE_PROBE = """
import json, sys, tempfile
from pathlib import Path
from numba.core.registry import CPUDispatcher
from engine.warmup import warm_up


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
from engine.io.sample import sample_contours_path
from engine.serve.datasets import SourceSpec, build_dataset
from engine.serve.renderer import Renderer
from engine.store.sqlite import CCSStore
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

with tempfile.TemporaryDirectory() as tmp:
    store = CCSStore(Path(tmp) / "sample.sqlite")
    build_dataset(store, SourceSpec(sample_contours_path(), "sample", "sample"), workers=1)
    bounds = Bounds(*store.dataset("sample").bounds_3857)
    before = compiled()
    per_tile = Renderer(store, contour_cache_bytes=0)  # every tile joins its stored pieces
    drawn = 0
    for z, x, y in tiles_covering(bounds, 13)[::7]:
        drawn += per_tile.tile("sample", z, x, y).data is not None
    after = compiled()
    store.close()
print(json.dumps({"compiled": sorted(k for k, n in after.items() if n > before.get(k, 0)), "n": drawn}))
"""


def test_a_tile_of_stored_pieces_compiles_nothing_after_the_warm_up() -> None:
    out = subprocess.run(
        [sys.executable, "-c", TILE_PROBE], cwd=REPO, capture_output=True, text=True, timeout=600, check=True
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["n"] > 5
    assert report["compiled"] == []

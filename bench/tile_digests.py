"""SHA-256 of a fixed set of tiles of the bundled sample: to show a change of the serving path leaves every
tile's bytes as they were (line layers at whole and fractional zooms, every method, morph tiles, label layers).

The sample is built into ``STORE`` when the store does not hold it yet; ``--cache-mb`` sets the renderer's
contour memory (a small one makes the renderer pack every tile from the contours it touches).

Usage: python bench/tile_digests.py STORE [--cache-mb 512]   (prints one line per tile, then the total)
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> None:
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.io.source import sample_contours_path
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    parser = argparse.ArgumentParser()
    parser.add_argument("store", type=Path)
    parser.add_argument("--cache-mb", type=float, default=512.0)
    args = parser.parse_args()
    store = CCSStore(args.store)
    if "sample" not in store.dataset_ids():
        build_dataset(store, SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    renderer = Renderer(store, contour_cache_bytes=int(args.cache_mb * (1 << 20)))
    info = store.dataset("sample")
    total = hashlib.sha256()
    count = 0

    def record(name: str, data: bytes | None) -> None:
        nonlocal count
        digest = hashlib.sha256(data or b"").hexdigest()
        total.update(f"{name} {digest}\n".encode())
        count += 1
        print(name, digest)

    for z in (10, 11, 12, 13, 14):
        for x, y in [(t[1], t[2]) for t in tiles_covering(Bounds(*info.bounds_3857), z)][::3]:
            record(f"ccsm {z}/{x}/{y}", renderer.tile("sample", z, x, y).data)
            record(f"ccsm {z}.5/{x}/{y}", renderer.tile("sample", z, x, y, zoom=z + 0.5).data)
            record(f"pinned {z}/{x}/{y}", renderer.tile("sample", z, x, y, t=0.3).data)
            record(f"morph {z}/{x}/{y}", renderer.morph_tile("sample", z, x, y).data)
            if z >= 12:
                for method in ("original", "dp", "vw"):
                    record(f"{method} {z}/{x}/{y}", renderer.tile("sample", z, x, y, method=method).data)
    print(f"{count} tiles, total {total.hexdigest()}")


if __name__ == "__main__":
    main()

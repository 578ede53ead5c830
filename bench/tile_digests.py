"""SHA-256 of a fixed set of tiles of the bundled sample: to show a change of the serving path leaves every
tile's bytes as they were (line layers at whole and fractional zooms, every method, morph tiles, label layers).

The sample is built into ``STORE`` when the store does not hold it yet; ``--cache-mb`` sets the renderer's
contour memory (a small one makes the renderer pack every tile from the contours it touches).

Usage: python bench/tile_digests.py STORE [--cache-mb 512]   (prints one line per tile, then the total)
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> None:
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.io.source import sample_contours_path
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from tests.support.tile_digests import tile_digests, total_digest

    parser = argparse.ArgumentParser()
    parser.add_argument("store", type=Path)
    parser.add_argument("--cache-mb", type=float, default=512.0)
    args = parser.parse_args()
    store = CCSStore(args.store)
    if "sample" not in store.dataset_ids():
        build_dataset(store, SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    renderer = Renderer(store, contour_cache_bytes=int(args.cache_mb * (1 << 20)))

    def printed(digests: Iterator[tuple[str, str]]) -> Iterator[tuple[str, str]]:
        for name, digest in digests:
            print(name, digest)
            yield name, digest

    count, total = total_digest(printed(tile_digests(renderer, "sample")))
    print(f"{count} tiles, total {total}")


if __name__ == "__main__":
    main()

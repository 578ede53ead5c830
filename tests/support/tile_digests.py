"""SHA-256 of a fixed set of tiles of the bundled sample (line layers at whole and fractional zooms, a pinned t,
morph tiles, the baselines' tiles): equal digests mean a change left every one of those tiles' bytes as it was.

Used by ``tests/engine/serve/test_sample_tile_digests.py`` and ``bench/tile_digests.py``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

from engine.serve.renderer import Renderer
from engine.tiles.grid import tiles_covering
from engine.types import Bounds

ZOOMS = (10, 11, 12, 13, 14)
#: Every third tile of a zoom over the sample: 888 tiles in all, drawn in a few seconds.
EVERY = 3


def tile_digests(renderer: Renderer, dataset: str) -> Iterator[tuple[str, str]]:
    """(name, SHA-256 hex of the tile's bytes; an empty tile hashes as b"") of every tile of the set."""

    def digest(data: bytes | None) -> str:
        return hashlib.sha256(data or b"").hexdigest()

    info = renderer.info(dataset)[0]
    for z in ZOOMS:
        for _, x, y in tiles_covering(Bounds(*info.bounds_3857), z)[::EVERY]:
            yield f"ccsm {z}/{x}/{y}", digest(renderer.tile(dataset, z, x, y).data)
            yield f"ccsm {z}.5/{x}/{y}", digest(renderer.tile(dataset, z, x, y, zoom=z + 0.5).data)
            yield f"pinned {z}/{x}/{y}", digest(renderer.tile(dataset, z, x, y, t=0.3).data)
            yield f"morph {z}/{x}/{y}", digest(renderer.morph_tile(dataset, z, x, y).data)
            if z >= 12:
                for method in ("original", "dp", "vw"):
                    yield f"{method} {z}/{x}/{y}", digest(renderer.tile(dataset, z, x, y, method=method).data)


def total_digest(digests: Iterator[tuple[str, str]]) -> tuple[int, str]:
    """How many tiles, and the SHA-256 of their ``name digest`` lines in order."""
    total = hashlib.sha256()
    count = 0
    for name, digest in digests:
        total.update(f"{name} {digest}\n".encode())
        count += 1
    return count, total.hexdigest()

"""Build a .pmtiles archive of morph tiles fetched from a running service (a test helper until `ccsm export`
is on main): every morph tile over the dataset's bounds at the given zooms, gzip-compressed as the format
says, with the TileJSON's fields as metadata.
"""

from __future__ import annotations

import gzip
import math
from collections.abc import Callable, Iterable
from pathlib import Path

import httpx
from pmtiles.tile import Compression, TileType, zxy_to_tileid
from pmtiles.writer import Writer


def tiles_over(bounds: list[float], z: int) -> Iterable[tuple[int, int]]:
    """(x, y) of the web-mercator tiles of zoom z over bounds (west, south, east, north)."""
    w, s, e, n = bounds
    count = 2**z

    def tx(lon: float) -> int:
        return min(count - 1, max(0, int((lon + 180) / 360 * count)))

    def ty(lat: float) -> int:
        r = math.radians(lat)
        return min(count - 1, max(0, int((1 - math.log(math.tan(r) + 1 / math.cos(r)) / math.pi) / 2 * count)))

    for x in range(tx(w), tx(e) + 1):
        for y in range(ty(n), ty(s) + 1):
            yield x, y


def write_pmtiles(
    out: Path, tiles: dict[tuple[int, int, int], bytes], bounds: list[float], metadata: dict[str, object]
) -> Path:
    """Write raw MVT bytes per (z, x, y) as a gzip-compressed PMTiles v3 archive."""
    with out.open("wb") as f:
        writer = Writer(f)
        for (z, x, y), data in sorted(tiles.items(), key=lambda kv: zxy_to_tileid(*kv[0])):
            writer.write_tile(zxy_to_tileid(z, x, y), gzip.compress(data, mtime=0))
        zooms = [z for z, _, _ in tiles]
        w, s, e, n = bounds
        writer.finalize(
            {
                "tile_type": TileType.MVT,
                "tile_compression": Compression.GZIP,
                "min_zoom": min(zooms),
                "max_zoom": max(zooms),
                "min_lon_e7": int(w * 1e7),
                "min_lat_e7": int(s * 1e7),
                "max_lon_e7": int(e * 1e7),
                "max_lat_e7": int(n * 1e7),
                "center_zoom": min(zooms),
            },
            metadata,
        )
    return out


def morph_pmtiles_from_service(
    base_url: str,
    dataset: str,
    zooms: Iterable[int],
    out: Path,
    fetch: Callable[[str], httpx.Response] | None = None,
) -> Path:
    """Fetch the morph tiles of ``dataset`` at ``zooms`` from the service and write them to ``out``."""
    get = fetch or (lambda url: httpx.get(url, timeout=120))
    tj = get(f"{base_url}/morph/{dataset}/tilejson.json").json()
    template = tj["tiles"][0]
    tiles: dict[tuple[int, int, int], bytes] = {}
    for z in zooms:
        for x, y in tiles_over(tj["bounds"], z):
            r = get(template.replace("{z}", str(z)).replace("{x}", str(x)).replace("{y}", str(y)))
            if r.status_code == 204:
                continue
            r.raise_for_status()
            tiles[(z, x, y)] = r.content  # httpx undoes the Content-Encoding: raw MVT
    meta = {k: tj[k] for k in ("name", "attribution", "vector_layers", "ccsm_morph") if k in tj}
    return write_pmtiles(out, tiles, tj["bounds"], meta)

"""The whole map of an exported dataset as static files beside its morph-tile archive: the service's style
(``style.json``) pointing at the archive, the glyphs its labels need, and the hillshade of a DEM as a second
archive of PNG tiles. The page that draws them (``index.html`` and its modules) is
:mod:`engine.serve.static_page`'s.

The style is :func:`engine.cartography.style.build_style`'s, the one the service serves, with relative URLs:
``pmtiles://contours.pmtiles`` for the contours and labels, ``pmtiles://…-hillshade.pmtiles/{z}/{x}/{y}`` for the
relief and ``fonts/{fontstack}/{range}.pbf`` for the glyphs (the page resolves them against its own address).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from engine.cartography.dataset import MINUS, DatasetCartography
from engine.cartography.glyphs import glyph_range_pbf
from engine.cartography.style import FONT_STACK, StyleSource, build_style, rank_fades
from engine.io.crs import crs_to_string
from engine.io.dem import read_dem
from engine.serve.export import ATTRIBUTION, archive_meta, lonlat_bounds, pyramid
from engine.serve.relief import relief_dem_path
from engine.store.records import DatasetInfo
from engine.tiles.archives import ArchiveMeta, PMTilesArchive
from engine.tiles.hillshade import hillshade_tile, shade_relief

Progress = Callable[[int, int], None]

#: The style file written beside the archive.
STYLE_FILE = "style.json"
#: The folder of glyph ranges, as the style's ``glyphs`` template names it.
FONTS_DIR = "fonts"
#: Code points per glyph range file (MapLibre asks for 0-255, 256-511, ...).
GLYPH_RANGE = 256
#: Hillshade tiles are made to this many zooms past the deepest morph tiles: a 256 px raster tile of zoom
#: z + 1 covers a 512 px map tile of zoom z, and MapLibre overzooms beyond the source's maxzoom.
HILLSHADE_EXTRA_ZOOMS = 1


@dataclass(frozen=True)
class StaticMap:
    """What was written beside the archive: the style, the glyph files, and the hillshade archive (or None)."""

    style: Path
    glyphs: list[Path]
    hillshade: Path | None
    hillshade_tiles: int


def hillshade_name(archive: Path) -> str:
    """The hillshade archive's file name beside a morph archive: ``contours.pmtiles`` ->
    ``contours-hillshade.pmtiles``."""
    return f"{archive.stem}-hillshade.pmtiles"


def label_characters(carto: DatasetCartography) -> str:
    """Every character a label of the dataset can hold: digits, point, space, the minus of depths, the unit."""
    return f"0123456789. {MINUS}{carto.options.units}"


def glyph_ranges(text: str) -> list[tuple[int, int]]:
    """The 256-code-point ranges that hold the characters of ``text``.

    >>> glyph_ranges("12 m\u2212")
    [(0, 255), (8704, 8959)]
    """
    starts = sorted({ord(c) // GLYPH_RANGE * GLYPH_RANGE for c in text})
    return [(s, s + GLYPH_RANGE - 1) for s in starts]


def write_glyphs(folder: Path, font_path: str | os.PathLike[str], text: str) -> list[Path]:
    """Write the glyph ranges of ``text`` as ``fonts/{FONT_STACK}/{start}-{end}.pbf`` under ``folder``."""
    out = folder / FONTS_DIR / FONT_STACK
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for start, end in glyph_ranges(text):
        path = out / f"{start}-{end}.pbf"
        path.write_bytes(glyph_range_pbf(font_path, FONT_STACK, start, end))
        written.append(path)
    return written


def static_style(
    info: DatasetInfo,
    carto: DatasetCartography,
    archive: Path,
    hillshade: Path | None,
    meta: ArchiveMeta,
) -> dict[str, Any]:
    """The service's style of the dataset with its sources in the files beside it (relative URLs), centred
    where the archive says."""
    source = StyleSource(
        dataset=info.id,
        name=info.name,
        tilejson_url=f"pmtiles://{archive.name}",
        glyphs_url=f"{FONTS_DIR}/{{fontstack}}/{{range}}.pbf",
        bounds=lonlat_bounds(info),
        schedule=rank_fades(carto.schedule),
        hillshade_tiles_url=f"pmtiles://{hillshade.name}/{{z}}/{{x}}/{{y}}" if hillshade else None,
        hillshade_maxzoom=meta.maxzoom + HILLSHADE_EXTRA_ZOOMS,
    )
    style = build_style(source)
    style["center"] = [meta.center[0], meta.center[1]]
    style["zoom"] = meta.center[2]
    return style


def export_hillshade(
    info: DatasetInfo, out: Path, minzoom: int, maxzoom: int, progress: Progress | None = None
) -> int | None:
    """Write the hillshade of the dataset's DEM, zooms ``minzoom`` .. ``maxzoom``, as a PMTiles archive of PNG
    tiles (tiles that miss the DEM are left out); the number of tiles, or None when the dataset has no DEM.

    Raises
    ------
    SourceError
        The stored DEM can no longer be read.
    """
    dem = relief_dem_path(info)
    if dem is None:
        return None
    grid = read_dem(dem)
    relief = shade_relief(grid.z, grid.transform, crs_to_string(grid.crs))
    tiles = pyramid(info.bounds_3857, minzoom, maxzoom)
    archive = PMTilesArchive(out, png=True)
    try:
        for done, tile in enumerate(tiles, 1):
            png = hillshade_tile(relief, tile)
            if png is not None:
                archive.add(*tile, png)
            if progress:
                progress(done, len(tiles))
        bounds = lonlat_bounds(info)
        centre = ((bounds[0] + bounds[2]) / 2, (bounds[1] + bounds[3]) / 2, minzoom)
        archive.commit(
            ArchiveMeta(
                name=f"{info.name}: hillshade",
                minzoom=minzoom,
                maxzoom=maxzoom,
                bounds=bounds,
                center=centre,
                vector_layers=[],
                description="Shaded relief of the DEM the contours were traced from.",
                attribution=ATTRIBUTION,
                format="png",
            )
        )
    except BaseException:
        archive.abort()
        raise
    return archive.tiles


def write_static_map(
    info: DatasetInfo,
    carto: DatasetCartography,
    archive: Path,
    minzoom: int,
    maxzoom: int,
    font_path: str | os.PathLike[str],
    progress: Progress | None = None,
) -> StaticMap:
    """Write ``style.json``, the glyphs and (for a dataset with a DEM) the hillshade archive beside the morph
    archive ``archive`` of zooms ``minzoom`` .. ``maxzoom``.

    Raises
    ------
    InvalidParameter
        The font cannot be read, or a file cannot be written.
    SourceError
        The dataset's DEM can no longer be read.
    """
    folder = archive.parent
    hillshade = folder / hillshade_name(archive)
    count = export_hillshade(info, hillshade, minzoom, maxzoom + HILLSHADE_EXTRA_ZOOMS, progress)
    shade = hillshade if count else None
    meta = archive_meta(info, carto, minzoom, maxzoom)
    style = static_style(info, carto, archive, shade, meta)
    path = folder / STYLE_FILE
    path.write_text(json.dumps(style, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    glyphs = write_glyphs(folder, font_path, label_characters(carto))
    return StaticMap(path, glyphs, shade, count or 0)

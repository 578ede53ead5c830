"""The sources a service is configured with (``CCSM_SOURCES``, or the bundled sample) as build specs.

A source is anything ``ccsm build`` takes (:func:`engine.io.source.parse_source`): a file, a GeoTIFF URL or a
terrain tile pyramid ``ENCODING:LOCATION``, with the service's area (``CCSM_BBOX``) and DEM zoom
(``CCSM_DEM_ZOOM``) for the sources that take them. Nothing is fetched here: a source written wrongly is a
problem of its own dataset (shown as its failed build), never a service that does not start.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.settings import Settings
from engine.build.datasets import SourceSpec, slugify
from engine.errors import CCSMError
from engine.io.source import Source, parse_source, takes_area
from engine.io.terrain_tiles import parse_encoding
from engine.io.tile_fetch import TileCache

#: Dataset id of the bundled sample.
SAMPLE_ID = "sample"
SAMPLE_NAME = "Jacksboro, Tennessee: 20 m contours (USGS DEM, bundled sample)"


@dataclass
class ConfiguredSources:
    """The configured sources: a build spec for each that could be read as a source, and for each that
    could not, its dataset id and why."""

    specs: list[SourceSpec] = field(default_factory=list)
    problems: dict[str, str] = field(default_factory=dict)


def tile_cache_dir(settings: Settings) -> Path:
    """Where a service keeps the terrain tiles its builds fetch: beside the store."""
    return settings.store_path.parent / "tile-cache"


def configured_sources(settings: Settings) -> ConfiguredSources:
    """The sources the settings name (the bundled sample when none is named and serve_sample is on)."""
    common: dict[str, Any] = {
        "elevation_field": settings.elevation_field,
        "interval": settings.interval,
        "source_scale": settings.source_scale,
        "target_scale": settings.target_scale,
        "cartography": settings.cartography,
    }
    out = ConfiguredSources()
    if settings.sources:
        seen: set[str] = set()
        for text in settings.sources:
            try:
                source: Source | None = _parse(text, settings)
                why = ""
            except CCSMError as exc:
                source, why = None, str(exc)
            stem = source.stem if source is not None else _stem_of(text)
            ident = slugify(stem)
            while ident in seen:
                ident += "-2"
            seen.add(ident)
            if source is None:
                out.problems[ident] = why if text in why else f"{text}: {why}"
            else:
                out.specs.append(SourceSpec(path=source, dataset=ident, name=stem, **common))
        return out
    if settings.serve_sample:
        out.specs.append(_sample_spec(common))
    return out


def _stem_of(text: str) -> str:
    """A name for the dataset of a source that could not be read: its last path part that is not a template
    field or a host, else ``source``."""
    parts = [p for p in text.split("?")[0].replace("\\", "/").split("/") if p and "{" not in p and ":" not in p]
    return Path(parts[-1]).stem if parts else "source"


def _parse(text: str, settings: Settings) -> Source:
    return configured_source(
        text,
        bbox=settings.bbox,
        dem_zoom=settings.dem_zoom,
        source_scale=settings.source_scale,
        tile_cache=TileCache(tile_cache_dir(settings)),
    )


def configured_source(
    text: str,
    *,
    bbox: tuple[float, float, float, float] | None,
    dem_zoom: int | None,
    source_scale: float,
    tile_cache: TileCache | None = None,
) -> Source:
    """The source ``text`` names, with the area where the source takes one (a tile pyramid, a raster) and
    the zoom where it is a tile pyramid: one area and zoom serve every configured source.

    Raises
    ------
    CCSMError
        Not a source, or a tile pyramid without an area (the message says which).
    """
    area = bbox if takes_area(text) else None
    zoom = dem_zoom if not Path(text).exists() and parse_encoding(text) is not None else None
    source = parse_source(text, bbox=area, dem_zoom=zoom, source_scale=source_scale, tile_cache=tile_cache)
    return source.expanduser() if isinstance(source, Path) else source


def _sample_spec(common: dict[str, Any]) -> SourceSpec:
    from engine.io.sample import sample_dem_path
    from engine.io.source import sample_contours_path

    common = {**common, "elevation_field": None, "interval": None}
    # The sample's contours were traced from the bundled DEM: shade that under them.
    try:
        relief = {"relief_dem": sample_dem_path()}
    except CCSMError:  # no DEM beside the sample (an installed wheel): no hillshade, contours still served
        relief = {}
    return SourceSpec(path=sample_contours_path(), dataset=SAMPLE_ID, name=SAMPLE_NAME, **common, **relief)  # type: ignore[arg-type]

"""A dataset's MapLibre style (style spec v8): hillshade, contour lines weighted by index, labels, all fading
with the interval schedule (docs/clients.md).

Pure: the caller passes every URL (absolute, built from the service's public base) and the schedule's fade
ranges; nothing here reads files or knows HTTP.

Why one line layer and one label layer per rank: a MapLibre ``["zoom"]`` ramp takes literal stops only, so a
rank's own fade range (its ``fade_zoom`` and ``hide_zoom``) has to be written into the layer that draws it,
and a filter on ``rank`` picks the features. The ramp is exponential with base 2 between ``hide_zoom``
(opacity 0) and ``fade_zoom`` (opacity 1): a rank's ink per screen area falls like 2^-z as the map zooms
out, so an opacity that also changes like 2^z over the fade range keeps the summed ink nearly flat.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from engine.cartography.schedule import NEVER, Schedule
from engine.errors import InvalidParameter

#: The one font stack the service serves (app/routes/styles.py makes its glyphs from DejaVu Sans).
FONT_STACK = "DejaVu Sans Book"

#: Paper, line and label colours (a brown contour ink over a warm white, as printed topographic maps).
PAPER_COLOR = "#f6f3ec"
LINE_COLOR = "#a0643a"
INDEX_LINE_COLOR = "#7d4520"
LABEL_COLOR = "#6e3c1a"
HALO_COLOR = "#f6f3ec"

#: Line widths in CSS pixels: intermediate and index contours (index lines are drawn heavier).
LINE_WIDTH_PX = 0.7
INDEX_LINE_WIDTH_PX = 1.5
#: Width of index lines once the base interval has faded out (the schedule's rank 0 is gone). They are then the
#: finest lines on the map, so they need no emphasis over thinner neighbours; at 1.5 px they would double the
#: ink per line just as the visible interval grows, and the map would darken as it zooms out (bench/bench_ink.py).
INDEX_LINE_WIDTH_ALONE_PX = 0.9

#: Label text size and halo width, CSS pixels.
LABEL_SIZE_PX = 11.0
LABEL_HALO_PX = 1.6

#: How strongly the hillshade shows through (raster opacity; the contours stay the darkest ink).
HILLSHADE_OPACITY = 0.45

#: A label fades in over this many zoom levels above its own first zoom (the tiles' ``min_zoom`` of the label).
LABEL_FADE_IN_ZOOMS = 0.5
#: Zoom stops of the label opacity ramp are this far apart (linear between them: within 2 % of the exact ramp).
LABEL_RAMP_STEP = 0.25
#: The label ramp runs to this zoom; above it every label is at full opacity (past any served zoom).
LABEL_RAMP_END = 20.0

#: Source ids in the style.
CONTOUR_SOURCE = "ccsm-contours"
HILLSHADE_SOURCE = "ccsm-hillshade"


@dataclass(frozen=True)
class RankFade:
    """When the lines and labels of one rank of the interval schedule fade out.

    Attributes
    ----------
    rank
        Position in the schedule (0 = only the base interval).
    fade_zoom
        Map zoom below which the rank starts fading (fully drawn at zoom >= fade_zoom).
    hide_zoom
        Map zoom at which it is fully faded (opacity 0 at zoom <= hide_zoom); None: never hides (the top rank).
    """

    rank: int
    fade_zoom: float
    hide_zoom: float | None

    def __post_init__(self) -> None:
        if self.rank < 0:
            raise InvalidParameter(f"rank {self.rank} is negative")
        if self.hide_zoom is not None and not self.hide_zoom < self.fade_zoom:
            raise InvalidParameter(
                f"rank {self.rank}: hide_zoom {self.hide_zoom} must be below fade_zoom {self.fade_zoom}"
            )


@dataclass(frozen=True)
class StyleSource:
    """Everything the style of one dataset says.

    Attributes
    ----------
    dataset, name
        Dataset id and human name (the style's ``name``).
    tilejson_url
        Absolute URL of the dataset's vector TileJSON (layers ``contours`` and ``contour_labels``).
    glyphs_url
        Absolute glyphs template with ``{fontstack}`` and ``{range}``.
    bounds
        (west, south, east, north) degrees of the data.
    schedule
        The fade range of every rank of the dataset's interval schedule.
    hillshade_tiles_url
        Absolute XYZ template of the hillshade PNG tiles, or None when the dataset has no DEM.
    hillshade_maxzoom
        Deepest zoom the hillshade tiles are made for (MapLibre overzooms beyond).
    attribution
        HTML attribution of the data (already escaped).
    webfonts_url
        Template of a CSS file declaring the label font as a web font (``{font-family}``, ``{fontweight}``,
        ``{-fontstyle}``), for clients that draw text with the browser's fonts (ol-mapbox-style reads it from
        the style's ``metadata["ol:webfonts"]``); None leaves it out.
    """

    dataset: str
    name: str
    tilejson_url: str
    glyphs_url: str
    bounds: tuple[float, float, float, float]
    schedule: Sequence[RankFade]
    hillshade_tiles_url: str | None = None
    hillshade_maxzoom: int = 14
    attribution: str = ""
    webfonts_url: str | None = None


def rank_fades(schedule: Schedule) -> list[RankFade]:
    """The fade range of each rank of a dataset's schedule (the top rank, at NEVER, never hides)."""
    return [RankFade(r.rank, r.fade_zoom, None if r.hide_zoom == NEVER else r.hide_zoom) for r in schedule.ranks]


def fade_opacity(fade: RankFade) -> float | list[Any]:
    """The opacity of a rank as a MapLibre expression: 0 at hide_zoom, 1 from fade_zoom, exponential base 2.

    >>> fade_opacity(RankFade(0, 12.0, 11.0))
    ['interpolate', ['exponential', 2], ['zoom'], 11.0, 0, 12.0, 1]
    >>> fade_opacity(RankFade(3, 9.0, None))
    1
    """
    if fade.hide_zoom is None:
        return 1
    return ["interpolate", ["exponential", 2], ["zoom"], fade.hide_zoom, 0, fade.fade_zoom, 1]


def rank_opacity_at(fade: RankFade, zoom: float) -> float:
    """The rank's opacity at a zoom, as :func:`fade_opacity` draws it.

    >>> rank_opacity_at(RankFade(0, 12.0, 11.0), 11.5)
    0.4142
    """
    if fade.hide_zoom is None or zoom >= fade.fade_zoom:
        return 1.0
    if zoom <= fade.hide_zoom:
        return 0.0
    span = fade.fade_zoom - fade.hide_zoom
    return round((2 ** (zoom - fade.hide_zoom) - 1) / (2**span - 1), 4)


def label_opacity(fade: RankFade) -> list[Any]:
    """A label's opacity: its rank's fade out (as its line's) times its own fade in over LABEL_FADE_IN_ZOOMS
    above the label's first zoom (``min_zoom``, fixed per label where its anchor holds still and it meets no
    other label; absent: shown as its line).

    A zoom ramp takes literal stops only, so the product is sampled every LABEL_RAMP_STEP zooms: at each stop
    the rank's part is a number and the label's part an expression of ``min_zoom``.
    """
    start = max(0.0, float(int(fade.hide_zoom))) if fade.hide_zoom is not None and fade.hide_zoom > 0 else 0.0
    n = int(round((LABEL_RAMP_END - start) / LABEL_RAMP_STEP))
    zooms = {round(start + k * LABEL_RAMP_STEP, 4) for k in range(n + 1)}
    if fade.hide_zoom is not None and fade.hide_zoom >= start:  # the rank ramp's own ends, exactly
        zooms |= {round(fade.hide_zoom, 4), round(fade.fade_zoom, 4)}
    stops: list[Any] = []
    for zoom in sorted(zooms):
        fade_in = [
            "max",
            0,
            ["min", 1, ["/", ["-", zoom, ["to-number", ["get", "min_zoom"], -1]], LABEL_FADE_IN_ZOOMS]],
        ]
        stops += [zoom, ["*", rank_opacity_at(fade, zoom), fade_in]]
    return ["interpolate", ["linear"], ["zoom"], *stops]


def _layer_minzoom(fade: RankFade) -> dict[str, float]:
    # Below hide_zoom the rank is invisible anyway; the layer's minzoom spares the renderer the work. MapLibre
    # takes minzoom >= 0 and tiles only carry the rank where hide_zoom < z + 1, so flooring loses nothing.
    if fade.hide_zoom is None or fade.hide_zoom < 0:
        return {}
    return {"minzoom": float(int(fade.hide_zoom))}


def _rank_layer_head(fade: RankFade, id_prefix: str, layer_type: str, source_layer: str) -> dict[str, Any]:
    """What the line and the label layer of one rank have in common: the contour source's features of that rank,
    none drawn below the rank's hide zoom."""
    return {
        "id": f"{id_prefix}-rank-{fade.rank}",
        "type": layer_type,
        "source": CONTOUR_SOURCE,
        "source-layer": source_layer,
        **_layer_minzoom(fade),
        "filter": ["==", ["to-number", ["get", "rank"]], fade.rank],
    }


#: MapLibre's test for an index contour (``level`` 1), which is drawn heavier and darker.
_IS_INDEX = ["==", ["to-number", ["get", "level"]], 1]


def line_width(base: RankFade) -> float | list[Any]:
    """Line width as a MapLibre expression: index contours (``level`` 1) at INDEX_LINE_WIDTH_PX while the base
    interval (rank 0, ``base``) is fully drawn, thinning to INDEX_LINE_WIDTH_ALONE_PX as it fades out, with the
    same exponential base 2 ramp as its opacity; intermediate ones at LINE_WIDTH_PX.

    >>> line_width(RankFade(0, 12.0, None))
    ['case', ['==', ['to-number', ['get', 'level']], 1], 1.5, 0.7]
    >>> line_width(RankFade(0, 12.0, 10.0))[:4]
    ['interpolate', ['exponential', 2], ['zoom'], 10.0]
    """
    heavy = ["case", _IS_INDEX, INDEX_LINE_WIDTH_PX, LINE_WIDTH_PX]
    if base.hide_zoom is None:
        return heavy
    alone = ["case", _IS_INDEX, INDEX_LINE_WIDTH_ALONE_PX, LINE_WIDTH_PX]
    return ["interpolate", ["exponential", 2], ["zoom"], base.hide_zoom, alone, base.fade_zoom, heavy]


def contour_line_layer(fade: RankFade, base: RankFade | None = None) -> dict[str, Any]:
    """The line layer of one rank: index contours (``level`` 1) heavier and darker than intermediate ones, as
    long as the base interval (``base``, rank 0 of the schedule; default ``fade``) is drawn (:func:`line_width`)."""
    return {
        **_rank_layer_head(fade, "contours", "line", "contours"),
        "layout": {"line-join": "round", "line-cap": "round"},
        "paint": {
            "line-color": ["case", _IS_INDEX, INDEX_LINE_COLOR, LINE_COLOR],
            "line-width": line_width(base or fade),
            "line-opacity": fade_opacity(fade),
        },
    }


#: The coastline's ink: the blue of water on printed maps, a little heavier than an index contour.
COASTLINE_COLOR = "#3b7fb6"
COASTLINE_WIDTH_PX = 1.6


def coastline_layer() -> dict[str, Any]:
    """The coastline: the 0 m line of a dataset built with ``sea="coastline"`` (features with ``coastline``
    true, which never fade), drawn over the contours; it matches nothing in other datasets."""
    return {
        "id": "coastline",
        "type": "line",
        "source": CONTOUR_SOURCE,
        "source-layer": "contours",
        "filter": ["==", ["get", "coastline"], True],
        "layout": {"line-join": "round", "line-cap": "round"},
        "paint": {"line-color": COASTLINE_COLOR, "line-width": COASTLINE_WIDTH_PX},
    }


def contour_label_layer(fade: RankFade) -> dict[str, Any]:
    """The label layer of one rank: the elevation with its unit, along the line at the tiles' ``angle`` (its top
    toward higher ground, or upright), with a halo."""
    return {
        **_rank_layer_head(fade, "contour-labels", "symbol", "contour_labels"),
        "layout": {
            "symbol-placement": "point",
            "text-field": ["to-string", ["get", "label"]],
            "text-font": [FONT_STACK],
            "text-size": LABEL_SIZE_PX,
            "text-rotate": ["to-number", ["get", "angle"]],
            "text-rotation-alignment": "map",
            "text-pitch-alignment": "map",
            "text-allow-overlap": False,
            "text-ignore-placement": False,
            "text-padding": 2,
        },
        "paint": {
            "text-color": LABEL_COLOR,
            "text-halo-color": HALO_COLOR,
            "text-halo-width": LABEL_HALO_PX,
            "text-opacity": label_opacity(fade),
        },
    }


def hillshade_source(src: StyleSource) -> dict[str, Any]:
    """The raster source of the hillshade PNG tiles."""
    return {
        "type": "raster",
        "tiles": [src.hillshade_tiles_url],
        "tileSize": 256,
        "bounds": list(src.bounds),
        "maxzoom": src.hillshade_maxzoom,
        "attribution": src.attribution,
    }


def build_style(src: StyleSource) -> dict[str, Any]:
    """A complete MapLibre style v8 of a dataset.

    Layers, bottom to top: paper, hillshade (when the dataset has a DEM), contour lines rank by rank from the
    base interval up (coarser ranks draw over finer ones), the coastline, then labels rank by rank.

    Parameters
    ----------
    src
        The dataset's URLs, bounds and schedule.

    Returns
    -------
    dict
        The style document, JSON-serialisable.

    Raises
    ------
    InvalidParameter
        The schedule is empty or repeats a rank.
    """
    ranks = [f.rank for f in src.schedule]
    if not ranks:
        raise InvalidParameter(f"dataset {src.dataset}: the interval schedule is empty")
    if len(set(ranks)) != len(ranks):
        raise InvalidParameter(f"dataset {src.dataset}: the interval schedule repeats a rank ({ranks})")
    schedule = sorted(src.schedule, key=lambda f: f.rank)
    west, south, east, north = src.bounds
    metadata = {"ccsm:dataset": src.dataset}
    if src.webfonts_url:
        metadata["ol:webfonts"] = src.webfonts_url
    sources: dict[str, Any] = {CONTOUR_SOURCE: {"type": "vector", "url": src.tilejson_url}}
    layers: list[dict[str, Any]] = [
        {"id": "background", "type": "background", "paint": {"background-color": PAPER_COLOR}}
    ]
    if src.hillshade_tiles_url:
        sources[HILLSHADE_SOURCE] = hillshade_source(src)
        layers.append(
            {
                "id": "hillshade",
                "type": "raster",
                "source": HILLSHADE_SOURCE,
                "paint": {"raster-opacity": HILLSHADE_OPACITY, "raster-fade-duration": 0},
            }
        )
    layers += [contour_line_layer(f, schedule[0]) for f in schedule]
    layers.append(coastline_layer())
    layers += [contour_label_layer(f) for f in schedule]
    return {
        "version": 8,
        "name": src.name,
        "metadata": metadata,
        "center": [(west + east) / 2, (south + north) / 2],
        "zoom": 11,
        "glyphs": src.glyphs_url,
        "sources": sources,
        "layers": layers,
    }

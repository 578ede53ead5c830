"""A stored dataset's cartography: its options, schedule and the attributes its tile features carry
(docs/design.md section 9)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.cartography.labels import LabelSource, first_label_zoom
from engine.cartography.options import CartographyOptions
from engine.cartography.schedule import ZOOM_DECIMALS, Schedule, make_schedule
from engine.store.records import ContourRecord, DatasetInfo, LabelAnchors
from engine.tiles.grid import mercator_to_lonlat
from engine.tiles.scale import zoom_for_scale

#: Key of the stored parameters that says on which side of its direction a contour has higher ground ("left" or
#: "right"), when the source gives every line the same orientation (a DEM's traced lines); absent: unknown.
UPHILL_SIDE_KEY = "uphill_side"
#: The sign of negative label text ("−200 m"): the typographic minus, not the hyphen.
MINUS = "\u2212"


@dataclass(frozen=True)
class DatasetCartography:
    """What tiles of one dataset version need to draw its contours as a map reader expects.

    Attributes
    ----------
    options
        The dataset's options, ``units`` resolved ("m" when neither given nor found in the source).
    schedule
        Its interval schedule (zooms at ``latitude``).
    latitude
        Degrees, the centre of the dataset's extent.
    start_zoom
        Zoom of the dataset's source scale at ``latitude`` (every level is drawn from there in).
    uphill_side
        "left" or "right": the side of its direction every contour has higher ground on (:data:`UPHILL_SIDE_KEY`);
        None when the source does not say.
    """

    options: CartographyOptions
    schedule: Schedule
    latitude: float
    start_zoom: float
    uphill_side: str | None = None

    def is_sea_level(self, elevations: ArrayLike) -> NDArray[np.bool_]:
        """Which of ``elevations`` are the 0 m line (the coastline of a DEM with sea)."""
        return np.asarray(np.abs(np.asarray(elevations, dtype=np.float64)) < 1e-9, dtype=bool)

    def shown_in_tile(self, elevations: ArrayLike, z: int) -> NDArray[np.bool_]:
        """Which contours a tile of zoom ``z`` carries: those not fully faded somewhere in [z, z + 1), the 0 m
        line not with ``sea="drop"``."""
        _, hide = self.schedule.zooms_of(self.schedule.rank_of(elevations))
        shown = np.asarray(hide < z + 1, dtype=bool)
        if self.options.sea == "drop":
            return shown & ~self.is_sea_level(elevations)
        return shown

    def line_columns(self, elevations: NDArray[np.float64]) -> dict[str, list[Any]]:
        """The cartography attributes of contour features: elevation (named per the options), index, level,
        rank, fade_zoom and hide_zoom, in that order (``t`` is the renderer's), then ``coastline`` (true on the
        0 m line) with ``sea="coastline"``; 0 is a multiple of every step, so the 0 m line is of the top rank and
        never fades."""
        ranks = self.schedule.rank_of(elevations)
        levels = self.schedule.level_of(elevations)
        fade, hide = self.schedule.zooms_of(ranks)
        columns: dict[str, list[Any]] = {
            self.options.elevation_key: elevations.tolist(),
            "index": (levels == 1).tolist(),
            "level": levels.tolist(),
            "rank": ranks.tolist(),
            "fade_zoom": fade.tolist(),
            "hide_zoom": hide.tolist(),
        }
        if self.options.sea == "coastline":
            columns["coastline"] = self.is_sea_level(elevations).tolist()
        return columns

    def label_text(self, elevation: float) -> str:
        """A contour label: the elevation and its unit ("600 m", "2000 ft", "10 fm"; decimals only when needed);
        a depth as "−200 m" (a true minus sign), or as "200 m" with ``depth_labels="below-datum"``."""
        if elevation < 0:
            sign = "" if self.options.depth_labels == "below-datum" else MINUS
            return f"{sign}{-elevation:g} {self.options.units}"
        return f"{elevation:g} {self.options.units}"

    def as_json(self) -> dict[str, Any]:
        """TileJSON's ``ccsm_cartography`` object."""
        return {
            "units": self.options.units,
            "index_every": self.options.index_every,
            "base_interval": self.schedule.base_interval,
            "attribute_names": self.options.attribute_names,
            "start_zoom": self.start_zoom,
            "schedule": self.schedule.as_json(),
        }


def centre_latitude(info: DatasetInfo) -> float:
    """Latitude of the centre of a dataset's extent, degrees (within Web Mercator's range)."""
    minx, miny, maxx, maxy = info.bounds_3857
    _, lat = mercator_to_lonlat(np.array([(minx + maxx) / 2]), np.array([(miny + maxy) / 2]))
    return float(np.clip(lat[0], -85.05, 85.05))


def dataset_cartography(info: DatasetInfo, interval: float | None, elevations: ArrayLike) -> DatasetCartography:
    """The cartography of a stored dataset from its metadata, interval and levels.

    Raises
    ------
    InvalidParameter
        Its stored options or schedule override are invalid.
    """
    options = CartographyOptions.from_params(info.params).checked()
    if options.units is None:
        options = replace(options, units="m")
    lat = centre_latitude(info)
    schedule = make_schedule(
        interval,
        start_scale=info.source_scale,
        latitude=lat,
        units=options.units or "m",
        index_every=options.index_every,
        elevations=elevations,
        override=options.schedule,
    )
    start = round(float(zoom_for_scale(info.source_scale, lat)), ZOOM_DECIMALS)
    side = info.params.get(UPHILL_SIDE_KEY)
    return DatasetCartography(options, schedule, lat, start, side if side in ("left", "right") else None)


#: :attr:`LabelSource.uphill` of each :attr:`DatasetCartography.uphill_side` (None: unknown, labels upright).
UPHILL_SIGN: dict[str | None, int] = {"left": 1, "right": -1, None: 0}


def is_labelled(carto: DatasetCartography, elevations: ArrayLike) -> NDArray[np.bool_]:
    """Which contours of these elevations carry labels: the index contours, but not the 0 m line unless
    ``sea="keep"`` (a coastline is not labelled with a height, a dropped line not at all)."""
    heights = np.asarray(elevations, dtype=np.float64)
    index = carto.schedule.level_of(heights) == 1
    return np.asarray(index & ~(carto.is_sea_level(heights) & (carto.options.sea != "keep")), dtype=np.bool_)


def label_sources(carto: DatasetCartography, records: Sequence[ContourRecord]) -> list[LabelSource]:
    """The index contours among ``records``, as the label placement takes them (not the 0 m line unless
    ``sea="keep"``: a coastline is not labelled with a height, a dropped line not at all); each told which
    way its label turns (:func:`~engine.cartography.labels.orient_angle`)."""
    if not records:
        return []
    elevations = np.array([r.elevation for r in records])
    ranks = carto.schedule.rank_of(elevations)
    uphill = UPHILL_SIGN[carto.uphill_side] if carto.options.label_orientation == "uphill" else 0
    out = []
    for rec, rank, wanted in zip(records, ranks.tolist(), is_labelled(carto, elevations).tolist(), strict=True):
        if not wanted:
            continue
        label_zoom = carto.schedule.label_zoom(rank, carto.start_zoom)
        out.append(
            LabelSource(
                fid=rec.fid,
                elevation=float(rec.elevation),
                text=carto.label_text(float(rec.elevation)),
                rank=rank,
                base=rec.base,
                top=rec.top,
                t_at_scale=rec.t_at_scale,
                first_zoom=first_label_zoom(label_zoom, rec.vanish_scale, carto.latitude),
                uphill=uphill,
            )
        )
    return out


def label_columns(carto: DatasetCartography, labels: LabelAnchors) -> dict[str, list[Any]]:
    """The properties of ``contour_labels`` features: elevation (named per the options), label, angle, level,
    rank, fade_zoom, hide_zoom (of the contour) and min_zoom (where the label is first shown)."""
    fade, hide = carto.schedule.zooms_of(labels.rank)
    return {
        carto.options.elevation_key: labels.elevation.tolist(),
        "label": list(labels.text),
        "angle": np.round(labels.angle, 1).tolist(),
        "level": carto.schedule.level_of(labels.elevation).tolist(),
        "rank": labels.rank.tolist(),
        "fade_zoom": fade.tolist(),
        "hide_zoom": hide.tolist(),
        "min_zoom": np.round(labels.min_zoom, ZOOM_DECIMALS).tolist(),
    }


def contour_fields(carto: DatasetCartography) -> dict[str, str]:
    """TileJSON ``fields`` of the ``contours`` layer (before the renderer's ``t`` and the morph fields)."""
    s = carto.schedule
    return {
        carto.options.elevation_key: f"Number: height of the contour, {carto.options.units}",
        "index": f"Boolean: true on index contours (multiples of {s.index_every * s.base_interval:g})",
        "level": "Number: 1 on index contours, 0 on intermediate ones",
        "rank": "Number: rank in the interval schedule (ccsm_cartography.schedule); higher ranks stay longer",
        "fade_zoom": "Number: the line starts fading out below this zoom (-1: never)",
        "hide_zoom": "Number: the line is fully faded at and below this zoom (-1: never)",
        **(
            {"coastline": "Boolean: true on the 0 m line, drawn as the coastline"}
            if carto.options.sea == "coastline"
            else {}
        ),
    }


def label_fields(carto: DatasetCartography) -> dict[str, str]:
    """TileJSON ``fields`` of the ``contour_labels`` layer."""
    return {
        carto.options.elevation_key: f"Number: height of the labelled contour, {carto.options.units}",
        "label": f"String: the label text, with its unit (e.g. '600 {carto.options.units}')",
        "angle": "Number: text-rotate in degrees (clockwise, 0 = west to east; within [-90, 90] when upright, "
        "else the text's top toward higher ground, within [-180, 180])",
        "level": "Number: 1 (labels sit on index contours)",
        "rank": "Number: rank of the labelled contour",
        "fade_zoom": "Number: fade_zoom of the labelled contour",
        "hide_zoom": "Number: hide_zoom of the labelled contour",
        "min_zoom": "Number: the label is placed to be shown from this zoom on (no overlap from there)",
    }

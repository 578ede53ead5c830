"""Every contour of a stored dataset as it looks at one map scale: the engine side of ``/simplify`` and of
``ccsm simplify``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.ccsm.regression import t_at_scales
from engine.checks import check_bbox, check_method, check_scale
from engine.io.crs import WEB_MERCATOR, make_transformer
from engine.serve.feature_columns import T_DECIMALS
from engine.serve.renderer import Renderer
from engine.tiles.grid import lonlat_to_mercator, mercator_to_lonlat
from engine.types import Coords


@dataclass(frozen=True)
class SimplifiedContour:
    """One contour at a scale, in EPSG:3857 (a ring as a closed path), with its t and similarity."""

    fid: int
    contour_id: str
    elevation: float
    closed: bool
    t: float
    similarity: float
    coords_3857: Coords
    level: int = 0
    rank: int = 0


@dataclass(frozen=True)
class Simplified:
    """The answer for a dataset at a scale: the contours drawn, how many were left out as too small
    (``vanished``), and how many because their level is not drawn at that scale (``dropped``: fully faded
    by the interval schedule, docs/design.md section 9)."""

    contours: list[SimplifiedContour]
    vanished: int
    dropped: int = 0


def simplify(
    renderer: Renderer,
    dataset: str,
    scale: float,
    *,
    bbox_lonlat: Sequence[float] | None = None,
    method: str = "ccsm",
    all_levels: bool = False,
) -> Simplified:
    """Every contour of a dataset at a scale denominator.

    Parameters
    ----------
    dataset
        Stored dataset id.
    scale
        Scale denominator, > 0 (any value: t is interpolated in each contour's table).
    bbox_lonlat
        (west, south, east, north) degrees: only contours whose extent meets it.
    method
        ccsm, dp, wm, vw or original.
    all_levels
        Keep the levels the interval schedule no longer draws at this scale (by default they are left out and
        counted in ``dropped``).

    Raises
    ------
    InvalidParameter, UnknownLayer
    """
    value = check_scale(scale)
    how = renderer.methods[check_method(method)]
    bbox = check_bbox(bbox_lonlat) if bbox_lonlat is not None else None
    info, _ = renderer.info(dataset)
    if bbox is None:
        fids = renderer.store.all_fids(dataset)
    else:
        xs, ys = lonlat_to_mercator(np.array([bbox.minx, bbox.maxx]), np.array([bbox.miny, bbox.maxy]))
        fids = renderer.store.query(dataset, (xs[0], ys[0], xs[1], ys[1]))
    recs = renderer.records(fids)
    carto = renderer.cartography(dataset)
    schedule = carto.schedule
    ranks = schedule.rank_of([r.elevation for r in recs]).tolist()
    faded = [schedule.ranks[k].hide_scale is not None and value >= schedule.ranks[k].hide_scale for k in ranks]
    # The 0 m line, as tiles draw it: left out with sea "drop" (even with all_levels), never faded as a coastline.
    at_sea = carto.is_sea_level([r.elevation for r in recs]) & (carto.options.sea != "keep")
    drop_sea = carto.options.sea == "drop"
    kept = [
        (r, k)
        for r, k, f, sea in zip(recs, ranks, faded, at_sea.tolist(), strict=True)
        if (not drop_sea if sea else all_levels or not f)
    ]
    shown = [(r, k) for r, k in kept if how.is_visible(r, value)]
    dropped = len(recs) - len(kept)
    if not shown:
        return Simplified([], len(kept), dropped)
    ts = t_at_scales(info.ladder, np.stack([r.t_at_scale for r, _ in shown]), value)
    levels = schedule.level_of([r.elevation for r, _ in shown]).tolist()
    out = []
    for (rec, rank), t, level in zip(shown, ts.tolist(), levels, strict=True):
        xy, sim = how.contour_at(rec, t, value, info)
        out.append(
            SimplifiedContour(
                rec.fid,
                rec.contour_id,
                float(rec.elevation),
                rec.closed,
                round(t, T_DECIMALS),
                sim,
                xy,
                level,
                rank,
            )
        )
    return Simplified(out, len(kept) - len(shown), dropped)


def _to_lonlat(xy: Coords) -> Coords:
    lon, lat = mercator_to_lonlat(xy[:, 0], xy[:, 1])
    return np.column_stack([lon, lat])


def feature_collection(
    contours: Sequence[SimplifiedContour],
    scale: float,
    method: str,
    *,
    crs: str = "EPSG:4326",
    decimals: int = 7,
    dropped: int | None = None,
) -> dict[str, Any]:
    """A GeoJSON FeatureCollection of simplified contours (RFC 7946 in EPSG:4326; another CRS is named in a
    ``crs`` member, as GDAL reads it); ``dropped`` (the levels left out at this scale) as a top-level member."""
    to_crs = _to_lonlat if crs == "EPSG:4326" else make_transformer(WEB_MERCATOR, crs)
    doc: dict[str, Any] = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "id": c.fid,
                "properties": {
                    "id": c.contour_id,
                    "elevation": c.elevation,
                    "t": c.t,
                    "similarity": round(c.similarity, 6),
                    "level": c.level,
                    "rank": c.rank,
                    "scale": scale,
                    "method": method,
                },
                "geometry": {
                    "type": "LineString",
                    "coordinates": np.round(to_crs(c.coords_3857), decimals).tolist(),
                },
            }
            for c in contours
        ],
    }
    if dropped is not None:
        doc["dropped"] = dropped
    if crs != "EPSG:4326":
        doc["crs"] = {"type": "name", "properties": {"name": crs}}
    return doc

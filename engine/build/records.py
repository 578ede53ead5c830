"""Built contours -> store rows: reprojection to EPSG:3857 and row significance, done once at save time.

Coordinates. ``base``/``top`` (the CCS rows) and the original contour are transformed once, from the working
CRS (metres, e.g. UTM) to EPSG:3857, and a tile's slice ``(1 - t) base + t top`` is then taken in EPSG:3857.
Interpolating the two transformed rows instead of transforming the interpolated row differs by the
projection's non-linearity over one link: a link joins two corresponding points at most a few hundred metres
apart, and over such a distance UTM -> Web Mercator is affine up to terms of order (link / earth radius)² x
link, i.e. (500 m / 6,378 km)² x 500 m ≈ 3e-6 m: far below a centimetre and the tile grid (2.4 m at z16).
The original coordinates in the working CRS are kept too, because the baseline simplifiers must run in metres
of a conformal projected CRS.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from engine.ccsm.build import BuiltSet, SpooledSet
from engine.ccsm.ccs import CCS
from engine.errors import StoreError
from engine.geom.polyline import closed_path
from engine.io.crs import WEB_MERCATOR, make_transformer
from engine.store.records import NewContour, NewDataset
from engine.tiles.significance import row_significance
from engine.types import BadFeature, Contour


def contour_rows(surfaces: Sequence[CCS], working_crs: str, contours: Sequence[Contour]) -> list[NewContour]:
    """The store rows of built surfaces (coordinates in ``working_crs``); ``contours`` are the input contours
    they were built from.

    Contours whose reprojection is not finite (outside Web Mercator's range) are left out.

    Raises
    ------
    StoreError
        A built contour's input coordinates are not among ``contours``.
    """
    to_3857 = make_transformer(working_crs, WEB_MERCATOR)
    originals = {(c.id, float(c.elevation), c.n_vertices): c.coords for c in contours}
    inputs: list[np.ndarray] = []
    for ccs in surfaces:
        key = (ccs.contour_id, float(ccs.elevation), int(ccs.n_input_vertices))
        if key not in originals:
            raise StoreError(f"contour {ccs.contour_id!r}: its input coordinates were not passed to save()")
        inputs.append(np.asarray(originals[key], dtype=np.float64))
    projected = _projected_in_one_call(to_3857, surfaces, inputs)
    rows: list[NewContour] = []
    for ccs, original_w, (both, original) in zip(surfaces, inputs, projected, strict=True):
        m = len(ccs.base)
        base, top = both[:m], both[m:]
        if not (np.isfinite(both).all() and np.isfinite(original).all()):
            continue
        allxy = np.concatenate([both, original])
        lo, hi = allxy.min(axis=0), allxy.max(axis=0)
        rows.append(
            NewContour(
                contour_id=str(ccs.contour_id),
                elevation=float(ccs.elevation),
                closed=bool(ccs.closed),
                group=int(ccs.group),
                vanish_scale=float(ccs.vanish_scale),
                length_m=float(ccs.length_m),
                n_input=len(original_w),
                base=base,
                top=top,
                original=original,
                original_w=original_w,
                t_at_scale=ccs.t_at_scale,
                sim_t=ccs.sim_t,
                sim=ccs.sim,
                sig=row_significance(base, top),
                sig_top=row_significance(top),
                sig_original=row_significance(original),
                box=(float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])),
                issues=tuple(ccs.issues),
            )
        )
    return rows


def _projected_in_one_call(
    to_3857: Callable[[np.ndarray], np.ndarray], surfaces: Sequence[CCS], inputs: Sequence[np.ndarray]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(base and top rows stacked, original as a path) of each surface in EPSG:3857, every point of the batch in
    one transform: a call per row cost more than its points (a fifth of a batch's rows). Each point is
    projected alone, so the numbers are those of a call per row."""
    parts: list[np.ndarray] = []
    for ccs, original_w in zip(surfaces, inputs, strict=True):
        parts += [ccs.base, ccs.top, closed_path(original_w) if ccs.closed else original_w]
    if not parts:
        return []
    ends = np.cumsum([len(a) for a in parts])
    pieces = np.split(to_3857(np.concatenate(parts)), ends[:-1])
    return [(np.concatenate(pieces[k : k + 2]), pieces[k + 2]) for k in range(0, len(pieces), 3)]


def bad_feature_dict(b: BadFeature) -> dict[str, Any]:
    """A bad feature as stored and reported (JSON-safe id)."""
    return {"id": b.id if isinstance(b.id, int) else str(b.id), "reason": b.reason, "where": b.where}


def dataset_meta(
    built: BuiltSet | SpooledSet,
    *,
    name: str,
    source: str,
    source_hash: str,
    params: dict[str, Any],
    build_seconds: float,
) -> NewDataset:
    """The metadata row of a built set."""
    return NewDataset(
        name=name,
        source=source,
        source_hash=source_hash,
        params=params,
        build_seconds=build_seconds,
        working_crs=built.working_crs,
        source_crs=built.source_crs,
        interval=built.interval,
        source_scale=float(built.model.source_scale),
        target_scale=float(built.model.target_scale),
        ladder=np.asarray(built.model.ladder, dtype=np.float64),
        bad_features=[bad_feature_dict(b) for b in built.bad_features],
    )

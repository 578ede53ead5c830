"""Cleaning of contour lines, shared by every source: line parts checked in their CRS, projected to the working
CRS, rings closed, duplicate vertices merged and empty lines left out, each rejection with its reason.

Sources (:mod:`engine.io.vector_reader`, :mod:`engine.io.dem`) hand over :class:`LineParts` in batches of about
:data:`ASSEMBLE_BATCH_VERTICES` vertices, so that the temporary arrays stay that size whatever the size of the
source; every step is vectorised over a batch's vertices.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NoReturn

import numpy as np
import pyproj
from numpy.typing import NDArray

from engine.errors import SourceError
from engine.intervals import infer_interval
from engine.io.crs import choose_working_crs, crs_to_string, lonlat_validity, make_transformer
from engine.scratch import ReadScratch, ScratchContours
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances
from engine.types import BadFeature, Contour, ContourSet, Coords, FeatureId

#: Largest latitude Web Mercator (EPSG:3857) covers: the edge of the square world; contours beyond cannot be
#: tiled, so they are reported as bad features at read time rather than accepted and then unservable.
WEB_MERCATOR_MAX_LAT = 85.0511287798066


@dataclass
class LineParts:
    """Candidate contour lines in the source CRS, before cleaning (one entry per line part).

    Attributes
    ----------
    xy
        (N, 2) float64 vertices of all parts, concatenated, in the source CRS.
    offsets
        (m + 1,) int64: part k is ``xy[offsets[k]:offsets[k + 1]]``.
    ids
        m feature ids.
    elevations
        (m,) float64 elevations (all finite: features without one are already in ``bad``).
    bad
        Features already rejected (bad geometry type, no elevation, ...).
    """

    xy: Coords
    offsets: NDArray[np.int64]
    ids: list[FeatureId]
    elevations: NDArray[np.float64]
    bad: list[BadFeature] = field(default_factory=list)


#: Vertices checked and projected at once while a source is assembled: the several temporary (n, 2) arrays of
#: a batch stay a few tens of MB whatever the size of the source (a national contour set has hundreds of
#: millions of vertices).
ASSEMBLE_BATCH_VERTICES = 1 << 20

#: Lists of a reader's scratch file (:class:`~engine.scratch.ReadScratch`): checked batches waiting for
#: the working CRS, and the usable contours.
CHECKED_LIST = "checked"
CONTOURS_LIST = "contours"


@dataclass
class _Checked:
    """A batch of parts checked in the source CRS: which parts are usable so far, why the others are not, and
    the lon/lat extent of the usable ones (None when there is none)."""

    ok: NDArray[np.bool_]
    reasons: dict[int, str]
    bounds: tuple[float, float, float, float] | None


@dataclass
class CheckedBatch:
    """A batch of line parts checked in their CRS (:func:`check_batch`): what a worker that traced the parts hands
    over, so that the build process does not check them again. ``bad`` are the batch's own rejected features."""

    parts: LineParts
    check: _Checked
    bad: list[BadFeature]


def check_batch(batch: LineParts, source_crs: pyproj.CRS) -> CheckedBatch:
    """The first pass of :func:`assemble_batches` over one batch: its parts checked in ``source_crs``."""
    parts = LineParts(batch.xy, batch.offsets, batch.ids, batch.elevations)  # its bad ones are listed apart
    return CheckedBatch(parts, _check_in_source_crs(parts, source_crs), list(batch.bad))


def assemble_batches(
    batches: Iterable[LineParts | CheckedBatch],
    *,
    source_crs: pyproj.CRS,
    where: str,
    name: str,
    tolerances: Tolerances = DEFAULT_TOLERANCES,
    interval: float | None = None,
    scratch: ReadScratch | None = None,
) -> ContourSet:
    """Validate, project and clean line parts into a :class:`ContourSet` (shared by vector and DEM sources). The
    parts come in batches (each of about :data:`ASSEMBLE_BATCH_VERTICES` vertices or fewer, :func:`in_batches`),
    so that a reader never holds the whole source, and the temporary arrays are that size.

    Per part, in this order: coordinates must be finite and valid for ``source_crs`` (see
    :func:`engine.io.crs.lonlat_validity`); all vertices are projected to the working CRS in one call; a part
    whose ends lie within ``tolerances.duplicate_m`` is a closed ring and loses its repeated last vertex;
    consecutive vertices closer than ``duplicate_m`` are merged (the first is kept); a line needs 2 distinct
    vertices, a ring 3, and a length of at least ``tolerances.zero_length_m``.

    Two passes: each batch is checked in the source CRS as it comes, the working CRS is chosen from the
    extent of every usable part, then each batch is projected and cleaned. With ``scratch``, the checked
    batches wait in the scratch file between the passes and the contours are kept there too (the set's
    ``contours`` then read from it when asked, :class:`~engine.scratch.ScratchContours`); without, both
    stay in memory. Either way the same contours in the same order. Each batch's own ``bad`` (features
    rejected before it was made) is listed before the reasons found here.

    Parameters
    ----------
    batches
        Line parts in ``source_crs``, or already checked in it (:func:`check_batch`, run where they were made).
    source_crs
        Their CRS.
    where
        File name recorded in each :class:`BadFeature`.
    name
        Name of the set.
    tolerances
        Distances in metres of the working CRS.
    interval
        Contour interval; inferred from the elevations when None.
    scratch
        Where the checked batches and the contours wait (see above); None = in memory.

    Raises
    ------
    SourceError
        No part is usable.
    """
    bad: list[BadFeature] = []
    checked: list[tuple[LineParts, _Checked]] = []
    usable = []
    for batch in batches:
        done = batch if isinstance(batch, CheckedBatch) else check_batch(batch, source_crs)
        bad.extend(done.bad)
        if scratch is not None:
            scratch.extend(CHECKED_LIST, [(done.parts, done.check)])
        else:
            checked.append((done.parts, done.check))
        if done.check.bounds is not None:
            usable.append(done.check.bounds)
    # Read back one batch at a time: a batch is up to ASSEMBLE_BATCH_VERTICES vertices.
    waiting: Iterable[tuple[LineParts, _Checked]] = (
        scratch.read(CHECKED_LIST, batch=1) if scratch is not None else checked
    )
    if not usable:
        listed = [b for batch, c in waiting for b in _bad_from_reasons(batch, c.reasons, where)]
        _raise_nothing_usable(where, bad + listed)
    # The working CRS from the extent of the usable parts, then each batch projected with one call.
    extent = np.array(usable)
    bounds = (
        float(extent[:, 0].min()),
        float(extent[:, 1].min()),
        float(extent[:, 2].max()),
        float(extent[:, 3].max()),
    )
    source_text = crs_to_string(source_crs)
    working_crs = choose_working_crs(source_text, bounds)
    to_working = make_transformer(source_text, working_crs)
    contours: list[Contour] = []
    elevations: set[float] = set()  # for the interval, when it is to be inferred
    for batch, check in waiting:
        cleaned = _clean_in_working_crs(batch, check, to_working, working_crs, tolerances)
        elevations.update(c.elevation for c in cleaned)
        if scratch is not None:
            scratch.extend(CONTOURS_LIST, cleaned)
        else:
            contours.extend(cleaned)
        bad.extend(_bad_from_reasons(batch, check.reasons, where))
    if scratch is not None:
        scratch.drop(CHECKED_LIST)
    kept: Sequence[Contour] = ScratchContours(scratch, CONTOURS_LIST) if scratch is not None else contours
    if not kept:
        _raise_nothing_usable(where, bad)
    if interval is None:
        interval = infer_interval(np.array(sorted(elevations), dtype=np.float64))
    return ContourSet(
        contours=kept,
        working_crs=working_crs,
        source_crs=source_text,
        bad_features=bad,
        name=name,
        interval=interval,
    )


def in_batches(parts: LineParts) -> Iterator[LineParts]:
    """``parts`` in batches of about :data:`ASSEMBLE_BATCH_VERTICES` vertices; the first carries ``parts.bad``."""
    for k, (a, b) in enumerate(_batch_ranges(parts.offsets, ASSEMBLE_BATCH_VERTICES)):
        batch = _sub_parts(parts, a, b)
        yield replace(batch, bad=list(parts.bad)) if k == 0 else batch
    if len(parts.ids) == 0 and parts.bad:
        yield replace(parts, bad=list(parts.bad))


def _batch_ranges(offsets: NDArray[np.int64], vertices: int) -> list[tuple[int, int]]:
    """Consecutive part ranges [a, b) of about ``vertices`` vertices each (a bigger part makes a batch alone).

    >>> _batch_ranges(np.array([0, 3, 5, 20, 21]), 4)
    [(0, 1), (1, 2), (2, 3), (3, 4)]
    >>> _batch_ranges(np.array([0, 1, 2, 3]), 10)
    [(0, 3)]
    """
    n = len(offsets) - 1
    out: list[tuple[int, int]] = []
    a = 0
    while a < n:
        b = int(np.searchsorted(offsets, offsets[a] + vertices, side="right")) - 1
        b = min(max(b, a + 1), n)
        out.append((a, b))
        a = b
    return out


def _sub_parts(parts: LineParts, a: int, b: int) -> LineParts:
    """Parts a .. b - 1 as a LineParts of their own (the vertices a view, not a copy)."""
    lo, hi = int(parts.offsets[a]), int(parts.offsets[b])
    return LineParts(parts.xy[lo:hi], parts.offsets[a : b + 1] - lo, parts.ids[a:b], parts.elevations[a:b])


def _check_in_source_crs(parts: LineParts, source_crs: pyproj.CRS) -> _Checked:
    """Steps 1 and 2 of :func:`assemble_batches` for one batch: finite, valid for the CRS, within Web Mercator."""
    n_parts = len(parts.ids)
    counts = np.diff(parts.offsets)
    part_of = np.repeat(np.arange(n_parts), counts)
    xy = parts.xy
    ok = counts > 0
    reasons: dict[int, str] = {int(k): "empty geometry" for k in np.flatnonzero(~ok)}

    # 1. NaN / inf coordinates.
    finite_vertex: NDArray[np.bool_] = np.asarray(np.isfinite(xy).all(axis=1), dtype=np.bool_)
    for k in np.unique(part_of[~finite_vertex]):
        reasons.setdefault(int(k), "NaN or infinite coordinates")
    ok &= _all_per_part(finite_vertex, part_of, n_parts)

    # 2. Out of range for the source CRS (|lat| > 90, outside the projection's area of use...).
    candidate = ok[part_of]
    lonlat = np.full_like(xy, np.nan)
    valid_vertex = np.zeros(len(xy), dtype=bool)
    if candidate.any():
        lonlat[candidate], valid_vertex[candidate] = lonlat_validity(source_crs, xy[candidate])
    crs_label = _short_crs_name(source_crs)
    for k in np.unique(part_of[candidate & ~valid_vertex]).tolist():
        lo, hi = int(parts.offsets[k]), int(parts.offsets[k + 1])
        x, y = xy[lo + int(np.argmin(valid_vertex[lo:hi]))]  # the part's first invalid vertex
        reasons.setdefault(int(k), f"coordinates out of range for {crs_label} ({x:.8g}, {y:.8g})")
    ok &= _all_per_part(valid_vertex | ~candidate, part_of, n_parts)

    # 2b. Beyond Web Mercator's latitudes: valid coordinates, yet no tile can show them.
    ok &= ~_beyond_web_mercator(parts, part_of, ok, lonlat, reasons)
    if not ok.any():
        return _Checked(ok, reasons, None)
    ll = lonlat[ok[part_of]]
    return _Checked(
        ok, reasons, (float(ll[:, 0].min()), float(ll[:, 1].min()), float(ll[:, 0].max()), float(ll[:, 1].max()))
    )


def _clean_in_working_crs(
    parts: LineParts, check: _Checked, to_working: Any, working_crs: str, tolerances: Tolerances
) -> list[Contour]:
    """Steps 3 and 4 of :func:`assemble_batches` for one checked batch: projected, rings closed, duplicate
    vertices merged, too short parts left out (their reasons added to ``check.reasons``)."""
    n_parts = len(parts.ids)
    counts = np.diff(parts.offsets)
    part_of = np.repeat(np.arange(n_parts), counts)
    xy, ok, reasons = parts.xy, check.ok.copy(), check.reasons
    if not ok.any():
        return []
    use = ok[part_of]
    projected = np.full_like(xy, np.nan)
    projected[use] = to_working(xy[use])
    projected_ok = np.isfinite(projected).all(axis=1) | ~use
    for k in np.unique(part_of[~projected_ok]):
        reasons.setdefault(int(k), f"coordinates cannot be projected to {working_crs}")
    ok &= _all_per_part(projected_ok, part_of, n_parts)

    # 4. Rings, duplicate vertices, too few points, zero length.
    dup = float(tolerances.duplicate_m)
    starts = parts.offsets[:-1]
    ends = parts.offsets[1:] - 1
    closed = np.zeros(n_parts, dtype=bool)
    has_two = ok & (counts >= 2)
    gap = np.full(n_parts, np.inf)
    gap[has_two] = np.hypot(*(projected[ends[has_two]] - projected[starts[has_two]]).T)
    closed[has_two] = gap[has_two] < dup
    keep = ok[part_of].copy()
    keep[ends[closed]] = False  # a ring's repeated last vertex
    keep = dedup_mask(projected, part_of, keep, closed, dup)

    kept_counts = np.bincount(part_of[keep], minlength=n_parts)
    lengths = _part_lengths(projected, part_of, keep, closed, n_parts)
    for k in np.flatnonzero(ok):
        if kept_counts[k] < 2:
            reasons[int(k)] = "fewer than 2 distinct points"
        elif closed[k] and kept_counts[k] < 3:
            reasons[int(k)] = "closed ring with fewer than 3 distinct points"
        elif lengths[k] < tolerances.zero_length_m:
            reasons[int(k)] = f"zero length ({lengths[k]:.3g} m)"
    ok &= np.array([k not in reasons for k in range(n_parts)], dtype=bool)
    kept_xy = projected[keep]
    kept_offsets = np.concatenate([[0], np.cumsum(kept_counts)])
    return [
        Contour(
            id=parts.ids[k],
            elevation=float(parts.elevations[k]),
            coords=kept_xy[kept_offsets[k] : kept_offsets[k + 1]],
            closed=bool(closed[k]),
        )
        for k in np.flatnonzero(ok)
    ]


def _beyond_web_mercator(
    parts: LineParts,
    part_of: NDArray[np.int64],
    ok: NDArray[np.bool_],
    lonlat: NDArray[np.float64],
    reasons: dict[int, str],
) -> NDArray[np.bool_]:
    """(n_parts,) True for the usable parts with a vertex beyond ±WEB_MERCATOR_MAX_LAT (reason recorded)."""
    polar = ok[part_of] & (np.abs(lonlat[:, 1]) > WEB_MERCATOR_MAX_LAT)
    for k in np.unique(part_of[polar]).tolist():
        lo, hi = int(parts.offsets[k]), int(parts.offsets[k + 1])
        lat = float(lonlat[lo + int(np.argmax(np.abs(lonlat[lo:hi, 1])))][1])
        reasons.setdefault(int(k), f"latitude {lat:.6g} is outside Web Mercator's range (±{WEB_MERCATOR_MAX_LAT:.4f}°)")
    return np.isin(np.arange(len(ok)), part_of[polar])


def _bad_from_reasons(parts: LineParts, reasons: dict[int, str], where: str) -> list[BadFeature]:
    """BadFeatures for the parts in ``reasons`` (part index -> reason), in part order."""
    return [BadFeature(parts.ids[k], reason, where) for k, reason in sorted(reasons.items())]


def _raise_nothing_usable(where: str, listed: list[BadFeature]) -> NoReturn:
    sample = "; ".join(f"{b.id}: {b.reason}" for b in listed[:5])
    more = f" (and {len(listed) - 5} more)" if len(listed) > 5 else ""
    raise SourceError(f"{where}: no usable contour among {len(listed)} features: {sample}{more}")


def _short_crs_name(crs: pyproj.CRS) -> str:
    text = crs_to_string(crs)
    return text if len(text) < 40 else str(crs.name)


def _all_per_part(flag: NDArray[np.bool_], part_of: NDArray[np.int64], n_parts: int) -> NDArray[np.bool_]:
    """Per part: True when ``flag`` holds at every one of its vertices (and for parts without vertices)."""
    failures = np.bincount(part_of[~flag], minlength=n_parts)
    result: NDArray[np.bool_] = failures == 0
    return result


def dedup_mask(
    xy: Coords,
    part_of: NDArray[np.int64],
    keep: NDArray[np.bool_],
    closed: NDArray[np.bool_],
    dup: float,
) -> NDArray[np.bool_]:
    """Drop vertices closer than ``dup`` to the previous kept vertex of the same part.

    Greedy along each part, as a sequential scan would do: the first vertex of a part is always kept, a vertex
    is kept when it lies at least ``dup`` from the last kept one. For a closed part (stored without its
    repeated vertex) the last kept vertex must also lie at least ``dup`` from the first.

    Parameters
    ----------
    xy
        (N, 2) float64 coordinates in metres (rows with ``keep`` False are ignored and may be NaN).
    part_of
        (N,) int part index of each vertex, non-decreasing.
    keep
        (N,) bool, vertices still in play.
    closed
        (m,) bool per part.
    dup
        Distance in metres.

    Returns
    -------
    (N,) bool
        The new keep mask: consecutive kept vertices of a part are never closer than ``dup``.
    """
    keep = keep.copy()
    idx = np.flatnonzero(keep)
    if len(idx) >= 2:
        kept_parts = part_of[idx]
        same = kept_parts[1:] == kept_parts[:-1]
        step = np.hypot(*(xy[idx[1:]] - xy[idx[:-1]]).T)
        affected = np.unique(kept_parts[1:][same & (step < dup)])
        # The scan is sequential (whether a vertex stays depends on which earlier ones stayed), so it runs in
        # Python, but only over the parts that have a too-close pair at all: few in real data.
        bounds = np.searchsorted(kept_parts, np.stack([affected, affected + 1]))
        for lo, hi in bounds.T.tolist():
            members = idx[lo:hi]
            xs = xy[members, 0].tolist()
            ys = xy[members, 1].tolist()
            last_x, last_y = xs[0], ys[0]
            for j in range(1, len(members)):
                if math.hypot(xs[j] - last_x, ys[j] - last_y) < dup:
                    keep[members[j]] = False
                else:
                    last_x, last_y = xs[j], ys[j]
    # A ring must not end on top of its start.
    while True:
        idx = np.flatnonzero(keep)
        if len(idx) == 0:
            break
        kept_parts = part_of[idx]
        boundaries = np.flatnonzero(np.diff(kept_parts)) + 1
        first = idx[np.concatenate([[0], boundaries])]
        last = idx[np.concatenate([boundaries - 1, [len(idx) - 1]])]
        p = part_of[first]
        wrap = closed[p] & (last != first)
        wrap[wrap] = np.hypot(*(xy[last[wrap]] - xy[first[wrap]]).T) < dup
        if not wrap.any():
            break
        keep[last[wrap]] = False
    return keep


def _part_lengths(
    xy: Coords, part_of: NDArray[np.int64], keep: NDArray[np.bool_], closed: NDArray[np.bool_], n_parts: int
) -> NDArray[np.float64]:
    """Length in metres of each part's kept vertices (rings include their closing segment)."""
    idx = np.flatnonzero(keep)
    lengths = np.zeros(n_parts, dtype=np.float64)
    if len(idx) < 2:
        return lengths
    same = part_of[idx[1:]] == part_of[idx[:-1]]
    step = np.hypot(*(xy[idx[1:]] - xy[idx[:-1]]).T)
    np.add.at(lengths, part_of[idx[1:]][same], step[same])
    kept_parts = part_of[idx]
    boundaries = np.flatnonzero(np.diff(kept_parts)) + 1
    first = idx[np.concatenate([[0], boundaries])]
    last = idx[np.concatenate([boundaries - 1, [len(idx) - 1]])]
    p = part_of[first]
    ring = closed[p]
    lengths[p[ring]] += np.hypot(*(xy[last[ring]] - xy[first[ring]]).T)
    return lengths

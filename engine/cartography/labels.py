"""Label anchors on index contours: fixed points where a contour holds still and runs straight
(docs/design.md section 9.3).

A contour drawn at t is ``(1 - t) base + t top`` row by row, so the row i of the base line is off the drawn
line by ``t * |top_i - base_i|``. Over the zooms a label is shown (from its first zoom to the last served
zoom), a row whose offset stays under ``LabelStyle.max_drift_px`` on screen is a place where the label can
sit still while the line morphs. Among such rows, a label goes where the line over the label's length is
straight (chord / arc >= ``min_straightness``), at most one per ``spacing_px`` of line at the first zoom;
then every contour's candidates are placed greedily (coarser ranks, then straighter places, first), each
kept only if its screen box does not meet a kept one at the zoom both are first shown together.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from itertools import islice
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from engine.cartography.label_grid import kept_apart
from engine.cartography.label_lines import straightness_at_zooms
from engine.ccsm.regression import t_at_scales
from engine.errors import short_reason
from engine.parallel import map_ordered
from engine.store.records import LabelAnchors
from engine.tiles.scale import EARTH_RADIUS_M, TILE_SIZE_PX, scale_for_zoom, zoom_for_scale

log = logging.getLogger("ccsm.labels")

#: EPSG:3857 metres per pixel at zoom 0 (512 px tiles).
MERCATOR_M_PER_PX_Z0 = 2 * math.pi * EARTH_RADIUS_M / TILE_SIZE_PX
#: A label whose top faces uphill is turned this far from upright at most (degrees): past it, where the text
#: would read nearly upside down (a line running west with higher ground to the south), it is turned upright.
UPSIDE_DOWN_LIMIT_DEG = 120.0


@dataclass(frozen=True)
class LabelStyle:
    """The screen geometry labels are placed for (pixels, as the map draws them).

    ``char_px`` and ``height_px`` are the box of one character of the label font (about 12 px text with its
    halo); ``padding_px`` is added around every box.
    """

    char_px: float = 7.0
    height_px: float = 14.0
    padding_px: float = 4.0
    spacing_px: float = 600.0
    max_drift_px: float = 1.0
    min_straightness: float = 0.97
    zoom_step: float = 0.5


@dataclass(frozen=True)
class LabelSource:
    """One index contour to label: its CCS rows (EPSG:3857), t table and when its label is first shown."""

    fid: int
    elevation: float
    text: str
    rank: int
    base: NDArray[np.float64]
    top: NDArray[np.float64]
    t_at_scale: NDArray[np.float64]
    first_zoom: float
    uphill: int = 0  # higher ground on the left of the line's direction (1), on its right (-1), unknown (0)


def metres_per_px(zoom: float | NDArray[np.float64]) -> NDArray[np.float64]:
    """EPSG:3857 metres per screen pixel at a (fractional) zoom."""
    return np.asarray(MERCATOR_M_PER_PX_Z0 / np.power(2.0, zoom), dtype=np.float64)


def upright_angle(dx: NDArray[np.float64], dy: NDArray[np.float64]) -> NDArray[np.float64]:
    """``text-rotate`` degrees of a direction (dx east, dy north): clockwise, kept within [-90, 90].

    >>> (upright_angle(np.array([1.0, 0.0, -1.0, 1.0]), np.array([0.0, 1.0, 0.0, 1.0])) + 0.0).tolist()
    [0.0, -90.0, 0.0, -45.0]
    """
    a = -np.degrees(np.arctan2(dy, dx))  # screen y points down: a line rising to the east turns anticlockwise
    a = np.where(a > 90, a - 180, a)
    return np.where(a < -90, a + 180, a)


def orient_angle(
    dx: NDArray[np.float64], dy: NDArray[np.float64], uphill: int, limit_deg: float = UPSIDE_DOWN_LIMIT_DEG
) -> NDArray[np.float64]:
    """``text-rotate`` degrees of a label along a direction (dx east, dy north) of a contour with higher ground
    on its left (``uphill`` 1) or right (-1): the text's top toward higher ground, unless that turns it more
    than ``limit_deg`` from upright, where it is turned upright; ``uphill`` 0 (unknown): :func:`upright_angle`.

    Text rotated by a (clockwise) reads along (cos a, -sin a) with its top toward (sin a, cos a), the left of
    its reading direction: so it reads along the line where higher ground is on the left, against it where
    higher ground is on the right.

    Higher ground on the right of lines running north, south-west and east: the first reads southward, top
    east; the second reads north-east, top north-west; the third would be upside down and is turned upright.

    >>> (orient_angle(np.array([0.0, -1.0, 1.0]), np.array([1.0, -1.0, 0.0]), -1) + 0.0).tolist()
    [90.0, -45.0, 0.0]
    """
    if uphill == 0:
        return upright_angle(dx, dy)
    a = -np.degrees(np.arctan2(dy, dx)) + (0.0 if uphill > 0 else 180.0)
    a = (a + 180.0) % 360.0 - 180.0  # within [-180, 180)
    return np.where(np.abs(a) > limit_deg, upright_angle(dx, dy), a)


def _t_through_zooms(
    src: LabelSource, ladder: NDArray[np.float64], latitude: float, max_zoom: float, step: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Zooms from the label's first zoom to ``max_zoom`` every ``step``, and the contour's t at each."""
    zooms = np.arange(src.first_zoom, max_zoom + step, step)
    tables = src.t_at_scale[None, :]
    ts = np.array([t_at_scales(ladder, tables, float(scale_for_zoom(z, latitude)))[0] for z in zooms])
    return zooms, ts


def contour_candidates(
    src: LabelSource, ladder: NDArray[np.float64], latitude: float, max_zoom: float, style: LabelStyle
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Candidate anchors of one contour: (k, 2) points, (k,) angles, (k,) straightness and (k,) first zooms.

    A row qualifies from the first zoom (on the ``zoom_step`` grid from the contour's own first label zoom) from
    which on, at every zoom: the drawn line stays within ``max_drift_px`` of the row and runs straight over the
    label's length centred there (checked on the line as drawn at that zoom: generalized at small scales,
    detailed further in). A curvy line is thus labelled from a larger scale on, where a label spans less of it.
    """
    empty = np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0)
    base = np.asarray(src.base, dtype=np.float64)
    top = np.asarray(src.top, dtype=np.float64)
    if len(base) < 3:
        return empty
    zooms, ts = _t_through_zooms(src, ladder, latitude, max_zoom, style.zoom_step)
    if len(zooms) == 0:  # first shown past the last zoom (a ring too small to draw before): never labelled
        return empty
    mpp = metres_per_px(zooms)
    label_px = style.char_px * len(src.text) + 2 * style.padding_px
    drift = np.hypot(*(top - base).T) * float(np.max(ts / mpp))
    ratio, inside = straightness_at_zooms(
        np.ascontiguousarray(base), np.ascontiguousarray(top), np.asarray(ts, dtype=np.float64), label_px * mpp
    )
    good = inside & (ratio >= style.min_straightness) & (drift <= style.max_drift_px)[None, :]
    # A row's first zoom: the first of a run of good zooms that lasts to the last zoom.
    holds = np.flip(np.cumprod(np.flip(good, axis=0), axis=0), axis=0).astype(bool)
    cand = np.flatnonzero(holds[-1])
    if len(cand) == 0:
        return empty
    first_k = np.argmax(holds[:, cand], axis=0)
    first = zooms[first_k]
    score = ratio[first_k, cand]
    # Greedy along the line (earlier-shown, then straighter, first): labels at least `spacing_px` of line
    # apart at the zoom both show.
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(base, axis=0).T))])
    at = s[cand]
    spacing = style.spacing_px * metres_per_px(first)  # metres of line, at each candidate's first zoom
    taken = spaced_along(at, first, score, spacing)
    pick = np.flatnonzero(taken)
    rows = cand[pick]
    half = label_px * metres_per_px(first[pick]) / 2
    ends = [np.clip(s[rows] + sign * half, 0.0, s[-1]) for sign in (-1.0, 1.0)]
    dx, dy = (np.interp(ends[1], s, base[:, i]) - np.interp(ends[0], s, base[:, i]) for i in (0, 1))
    return base[rows], orient_angle(dx, dy, src.uphill), score[pick], first[pick]


def spaced_along(
    at: NDArray[np.float64], first: NDArray[np.float64], score: NDArray[np.float64], spacing: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Which candidates along one line to take: greedily, earlier-shown then straighter first, each unless a
    taken one lies nearer along the line than the spacing at the zoom both show (the later first zoom's, where
    the spacing, ``spacing`` metres at each candidate's first zoom, is the smaller).

    In that order the zoom both show is always the candidate's own (none taken before it shows later), so only
    the taken candidates nearest along the line, on either side, can be too close: they are kept sorted. (A long
    contour has thousands of candidates; testing each against every taken one had been a tenth of a build.)

    >>> spaced_along(np.array([0.0, 5.0, 12.0]), np.zeros(3), np.array([1.0, 0.9, 0.8]), np.full(3, 10.0)).tolist()
    [True, False, True]
    """
    taken = np.zeros(len(at), dtype=bool)
    taken_at: list[float] = []
    positions, gaps = at.tolist(), spacing.tolist()
    for j in np.lexsort((-score, first)).tolist():
        k = bisect.bisect_left(taken_at, positions[j])
        after = k < len(taken_at) and taken_at[k] - positions[j] < gaps[j]
        before = k > 0 and positions[j] - taken_at[k - 1] < gaps[j]
        if not (after or before):
            taken[j] = True
            taken_at.insert(k, positions[j])
    return taken


def box_px(text_len: NDArray[np.int64], angle_deg: NDArray[np.float64], style: LabelStyle) -> NDArray[np.float64]:
    """(n, 2) width and height of each label's axis-aligned screen box, rotation and padding included."""
    w = style.char_px * text_len + 2 * style.padding_px
    h = style.height_px + 2 * style.padding_px
    a = np.radians(angle_deg)
    c, s = np.abs(np.cos(a)), np.abs(np.sin(a))
    return np.column_stack([w * c + h * s, w * s + h * c])


def boxes_overlap(
    xy: NDArray[np.float64], box: NDArray[np.float64], zoom: NDArray[np.float64], j: int, others: NDArray[np.intp]
) -> NDArray[np.bool_]:
    """Whether label ``j``'s box meets each of ``others``' boxes at the zoom both are first shown together."""
    mpp = metres_per_px(np.maximum(zoom[j], zoom[others]))
    half = (box[j] + box[others]) / 2 * mpp[:, None]
    d = np.abs(xy[others] - xy[j])
    return (d[:, 0] < half[:, 0]) & (d[:, 1] < half[:, 1])


def _keep_apart(
    xy: NDArray[np.float64], box: NDArray[np.float64], zoom: NDArray[np.float64], order: NDArray[np.intp]
) -> list[int]:
    """The labels kept, taken in ``order`` (first zoom ascending): each kept unless its box meets a kept one's.

    A kept label was first shown no later than the one being placed, so two boxes can only meet within
    (largest box) x metres-per-pixel at the later label's first zoom: a distance that only shrinks as the
    placement goes on. Kept labels are filed in a grid of cells at least that wide, so each label is tested
    against the few kept labels in the 3 x 3 cells around it rather than all of them (a dataset with a hundred
    thousand index-contour labels is placed in seconds, not the hour the test against every kept label took),
    and the grid is refiled at half the width whenever the distance halves. The decisions are those of the
    test against every kept label (:func:`boxes_overlap`): only labels that cannot meet are skipped.

    The walk is compiled (:func:`~engine.cartography.label_grid.kept_apart`): it is the one part of a build's
    labels that runs in the build process, serially, and in Python it took 0.9 s of that process's 14 CPU s on
    the 16x terrain.
    """
    if not len(order):
        return []
    # Metres per pixel at the later of two first zooms is the smaller of the two labels' own (it falls as the
    # zoom grows): the same numbers boxes_overlap computes from the larger zoom.
    mpp = np.asarray(metres_per_px(zoom), dtype=np.float64)
    kept = kept_apart(
        np.ascontiguousarray(xy, dtype=np.float64),
        np.ascontiguousarray(box, dtype=np.float64),
        mpp,
        np.asarray(order, dtype=np.int64),
        float(box.max()),
    )
    return [int(i) for i in kept]


#: (k, 2) points, (k,) angles, (k,) straightness and (k,) first zooms: one contour's candidate anchors.
Candidates = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
#: No candidates: what a contour whose candidates could not be found gets.
NO_CANDIDATES: Candidates = (np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0))

#: Contours whose candidates one task finds while a dataset's labels are placed on an executor.
CANDIDATE_BATCH = 64


def batch_candidates(
    sources: Sequence[LabelSource], ladder: NDArray[np.float64], latitude: float, max_zoom: float, style: LabelStyle
) -> list[Candidates | str]:
    """:func:`contour_candidates` of each source: a task a worker runs (each contour's candidates are its own,
    so finding them is the part of the placement that can be shared out).

    A contour whose candidates cannot be found gets none, and the reason in their place (a string): one
    contour left without a label, not a dataset without labels.
    """
    out: list[Candidates | str] = []
    for src in sources:
        try:
            out.append(contour_candidates(src, ladder, latitude, max_zoom, style))
        except Exception as exc:  # the per-contour boundary: this contour only goes unlabelled
            log.warning("contour fid %s is left without a label: %s", src.fid, short_reason(exc))
            log.debug("label candidates of contour fid %s", src.fid, exc_info=True)
            out.append(short_reason(exc))
    return out


def place_labels(
    sources: Iterable[LabelSource],
    ladder: NDArray[np.float64],
    latitude: float,
    max_zoom: float,
    style: LabelStyle | None = None,
    executor: Executor | None = None,
) -> LabelAnchors:
    """Anchors of every labelled contour of a dataset, none overlapping another at their first common zoom.

    Parameters
    ----------
    sources
        The contours to label (index contours), with their first zooms: read once, and only their candidates
        and a few numbers kept, so a generator that loads them in batches holds one batch of rows at a time.
    ladder
        (S,) the dataset's scale ladder (of the t tables).
    latitude
        Degrees; zooms are turned into scales there.
    max_zoom
        The last zoom labels are shown at (the served maximum): drift is checked up to it.
    executor
        Where the contours' candidates are found, :data:`CANDIDATE_BATCH` contours a task (see
        :mod:`engine.parallel`); None = in this process. The placement among them runs here.
    """
    style = style or LabelStyle()
    return place_among(found_candidates(sources, ladder, latitude, max_zoom, style, executor), style)


def found_candidates(
    sources: Iterable[LabelSource],
    ladder: NDArray[np.float64],
    latitude: float,
    max_zoom: float,
    style: LabelStyle,
    executor: Executor | None = None,
) -> Iterator[tuple[LabelSource, Candidates | str]]:
    """Each source with its candidates (or why it has none), found :data:`CANDIDATE_BATCH` sources a task on
    ``executor`` (None: here), in the sources' order."""
    sent: deque[list[LabelSource]] = deque()  # the batches whose candidates are being found, in order

    def tasks() -> Iterator[tuple[object, ...]]:
        it = iter(sources)
        while batch := list(islice(it, CANDIDATE_BATCH)):
            sent.append(batch)
            yield batch, ladder, latitude, max_zoom, style

    for batch_found in map_ordered(executor, batch_candidates, tasks()):
        yield from zip(sent.popleft(), batch_found, strict=True)


class LabelHead(Protocol):
    """What the placement reads of a labelled contour besides its candidates (a :class:`LabelSource` is one)."""

    @property
    def fid(self) -> int: ...  # noqa: D102
    @property
    def elevation(self) -> float: ...  # noqa: D102
    @property
    def text(self) -> str: ...  # noqa: D102
    @property
    def rank(self) -> int: ...  # noqa: D102


def place_among(found: Iterable[tuple[LabelHead, Candidates | str]], style: LabelStyle) -> LabelAnchors:
    """The anchors placed among each labelled contour's candidates (:func:`place_labels`): a walk over them in
    order of first zoom that keeps a label only where it overlaps no label kept before it."""
    pts, ang, score, zoom, owner = [], [], [], [], []
    fids, elevations, ranks, labels = [], [], [], []  # of each source
    issues: list[tuple[int, str]] = []
    for k, (src, cands) in enumerate(found):
        if isinstance(cands, str):
            issues.append((src.fid, cands))
            cands = NO_CANDIDATES
        p, a, sc, fz = cands
        pts.append(p)
        ang.append(a)
        score.append(sc)
        zoom.append(fz)
        owner.append(np.full(len(p), k, dtype=np.int64))
        fids.append(src.fid)
        elevations.append(src.elevation)
        ranks.append(src.rank)
        labels.append(src.text)
    if not sum(len(o) for o in owner):
        z = np.zeros(0)
        return LabelAnchors(
            np.zeros((0, 2)), z, z, np.zeros(0, np.int64), np.zeros(0, np.int64), z, [], np.zeros((0, 2)),
            tuple(issues),
        )
    xy, angle, straight, own = np.concatenate(pts), np.concatenate(ang), np.concatenate(score), np.concatenate(owner)
    first = np.concatenate(zoom)
    rank = np.array(ranks, dtype=np.int64)[own]
    texts = [labels[k] for k in own.tolist()]
    boxes = box_px(np.array([len(t) for t in texts]), angle, style)
    # Labels shown from smaller scales first (coarser ranks first among them), then straighter places.
    order = np.lexsort((-straight, -rank, first))
    kept = _keep_apart(xy, boxes, first, order)
    placed = np.array(sorted(kept), dtype=np.intp)
    return LabelAnchors(
        xy[placed],
        angle[placed],
        first[placed],
        np.array(fids, dtype=np.int64)[own[placed]],
        rank[placed],
        np.array(elevations, dtype=np.float64)[own[placed]],
        [texts[i] for i in placed.tolist()],
        boxes[placed],
        tuple(issues),
    )


def first_label_zoom(label_zoom: float, vanish_scale: float, latitude: float) -> float:
    """The zoom a contour's label first shows: its rank's label zoom, or later when the contour (a small ring)
    is not drawn yet there."""
    if math.isfinite(vanish_scale) and vanish_scale > 0:
        return max(label_zoom, float(zoom_for_scale(vanish_scale, latitude)))
    return label_zoom

"""Which side of a label is higher ground where the source does not say (docs/design.md section 9.3).

A contour file's lines run either way, so the side of higher ground is read off the neighbouring levels: from
each label's anchor a short probe goes out perpendicular to the line on each side, and the nearest line it
crosses tells that side. A neighbour higher than the label's level on the text's top side (or lower on its
foot side) means the top faces uphill. A summit's innermost ring has no line inside, but its outer neighbour
is lower; a pit's is higher: one side is enough. Where the two sides disagree, or neither meets another level
(a lone line, a neighbour of the same level at a saddle, the probe crossing the label's own line first), the
side is unknown and the label stays upright.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

#: How far a probe reaches on each side of a label (EPSG:3857 metres, about 1.2–1.6 km on the ground in mid
#: latitudes): further than the spacing of neighbouring levels on all but nearly flat ground.
PROBE_M = 2000.0

#: Where a probe starts, off the anchor (metres): clear of the label's own line, which passes through it.
PROBE_START_M = 0.5


def text_top(angle_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 2) unit vectors toward the top of text rotated ``angle_deg`` clockwise (x east, y north)."""
    a = np.radians(angle_deg)
    return np.column_stack([np.sin(a), np.cos(a)])


def nearest_crossed(
    start: NDArray[np.float64],
    direction: NDArray[np.float64],
    lines: Sequence[NDArray[np.float64]],
    elevations: NDArray[np.float64],
    probe_m: float = PROBE_M,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(n,) elevation of the first of ``lines`` each probe crosses (from ``start`` + ``PROBE_START_M`` along
    ``direction`` for ``probe_m``), NaN where it crosses none; and (n,) how far along the probe that is (inf)."""
    out = np.full(len(start), np.nan)
    far = np.full(len(start), np.inf)
    if not len(start):
        return out, far
    a = start + PROBE_START_M * direction
    b = start + probe_m * direction
    probes = shapely.linestrings(np.stack([a, b], axis=1))
    keep = [k for k, line in enumerate(lines) if len(line) >= 2]
    if not keep:
        return out, far
    elevations = np.asarray(elevations, dtype=np.float64)[keep]
    counts = np.array([len(lines[k]) for k in keep])
    geoms = shapely.linestrings(
        np.concatenate([lines[k] for k in keep]), indices=np.repeat(np.arange(len(keep)), counts)
    )
    tree = shapely.STRtree(geoms)
    probe_i, line_i = tree.query(probes, predicate="intersects")
    if not len(probe_i):
        return out, far
    hits = shapely.intersection(probes[probe_i], geoms[line_i])
    along = shapely.distance(shapely.points(a[probe_i]), hits)
    order = np.lexsort((along, probe_i))  # by probe, nearest first
    first = order[np.r_[True, probe_i[order][1:] != probe_i[order][:-1]]]
    out[probe_i[first]] = elevations[line_i[first]]
    far[probe_i[first]] = along[first] + PROBE_START_M
    return out, far


def top_uphill(
    xy: NDArray[np.float64],
    angle_deg: NDArray[np.float64],
    elevation: NDArray[np.float64],
    lines: Sequence[NDArray[np.float64]],
    line_elevations: NDArray[np.float64],
    probe_m: float = PROBE_M,
) -> NDArray[np.int64]:
    """(n,) for each label at ``xy`` rotated ``angle_deg`` on a line of ``elevation``: 1 where higher ground is
    on its text's top side, -1 where it is on its foot side, 0 where the neighbouring ``lines`` (every line
    near the labels, their own included) do not tell."""
    up = text_top(angle_deg)
    above, _ = nearest_crossed(xy, up, lines, line_elevations, probe_m)
    below, _ = nearest_crossed(xy, -up, lines, line_elevations, probe_m)
    with np.errstate(invalid="ignore"):
        from_top = np.sign(above - elevation)  # NaN (no line) and 0 (its own level) tell nothing
        from_foot = np.sign(elevation - below)
    votes = np.stack([np.nan_to_num(from_top), np.nan_to_num(from_foot)])
    agree = ~((votes[0] * votes[1]) < 0)
    return np.where(agree, np.sign(votes.sum(axis=0)), 0).astype(np.int64)

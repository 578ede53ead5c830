"""The interval-by-scale rule: from which scale each contour level fades out (docs/design.md section 9).

A dataset's levels are ranked by the coarsest step of a chain of intervals they are a multiple of: rank 0 is
the base interval, then the index interval (``index_every`` base intervals), then coarser values of the usual
series 1, 2, 2.5, 5 x 10^k, each a multiple of the one before. Ink on screen is proportional to 2^-z divided
by the visible interval, so the visible interval grows in proportion to the scale denominator: the base
interval is fully drawn down to the ``start_scale`` (the data's source scale), and rank r is fully drawn while
the visible interval is at most its own step and gone when it reaches the next step:

    fade_scale(r) = start_scale * step(r) / base,    hide_scale(r) = start_scale * step(r + 1) / base.

The top rank never hides (``hide_zoom`` = ``fade_zoom`` = -1, scales None).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.errors import InvalidParameter
from engine.intervals import ELEVATION_DECIMALS, INDEX_EVERY, UNIT_NAMES
from engine.tiles.scale import zoom_for_scale

#: Mantissas of the usual contour-interval series (1, 2, 2.5, 5, 10, 20, 25, 50, 100, ...).
SERIES_MANTISSAS = (1.0, 2.0, 2.5, 5.0)
#: Zoom of a rank that never hides (the sentinel the tiles carry in ``fade_zoom`` and ``hide_zoom``).
NEVER = -1.0
#: Decimals of the zooms written to tiles and TileJSON (1e-4 of a zoom level is far below a frame).
ZOOM_DECIMALS = 4
#: Units a dataset's elevations may be in.
UNITS = ("m", "ft", "fm")
#: Relative tolerance of "is a multiple of" (elevations are rounded to ELEVATION_DECIMALS anyway).
MULTIPLE_RTOL = 1e-6


@dataclass(frozen=True)
class Rank:
    """One rank of a schedule: levels that are multiples of ``step`` (and of no coarser step of the chain).

    Scales are denominators; zooms are at the dataset's centre latitude. The top rank has ``hide_scale`` and
    ``fade_scale`` None and both zooms ``NEVER``.
    """

    rank: int
    step: float
    fade_scale: float | None
    hide_scale: float | None
    fade_zoom: float
    hide_zoom: float

    def as_json(self) -> dict[str, float | int | None]:
        """The rank as TileJSON's ``ccsm_cartography.schedule`` lists it."""
        return {
            "rank": self.rank,
            "step": self.step,
            "fade_zoom": self.fade_zoom,
            "hide_zoom": self.hide_zoom,
            "fade_scale": self.fade_scale,
            "hide_scale": self.hide_scale,
        }


@dataclass(frozen=True)
class Schedule:
    """A dataset's interval schedule: ranks from the base interval (rank 0) to the top rank (never hides)."""

    base_interval: float
    index_every: int
    units: str
    ranks: tuple[Rank, ...]

    @property
    def steps(self) -> NDArray[np.float64]:
        """(R,) step of each rank."""
        return np.array([r.step for r in self.ranks], dtype=np.float64)

    def rank_of(self, elevations: ArrayLike) -> NDArray[np.int64]:
        """Rank of each elevation: the coarsest step of the chain it is a multiple of (0 when none)."""
        e = np.asarray(elevations, dtype=np.float64)
        steps = self.steps
        q = e[..., None] / steps
        multiple = np.abs(q - np.round(q)) <= MULTIPLE_RTOL * np.maximum(1.0, np.abs(q))
        # The chain is nested: a multiple of step r is a multiple of every finer step, so count them.
        return (np.cumprod(multiple, axis=-1).sum(axis=-1) - 1).clip(min=0).astype(np.int64)

    def level_of(self, elevations: ArrayLike) -> NDArray[np.int64]:
        """1 on index contours (multiples of ``index_every`` base intervals), 0 on the others."""
        e = np.asarray(elevations, dtype=np.float64)
        q = e / (self.index_every * self.base_interval)
        return (np.abs(q - np.round(q)) <= MULTIPLE_RTOL * np.maximum(1.0, np.abs(q))).astype(np.int64)

    def zooms_of(self, ranks: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(fade_zoom, hide_zoom) of each rank."""
        r = np.asarray(ranks, dtype=np.int64)
        fade = np.array([k.fade_zoom for k in self.ranks])
        hide = np.array([k.hide_zoom for k in self.ranks])
        return fade[r], hide[r]

    def label_zoom(self, rank: int, start_zoom: float) -> float:
        """The zoom from which labels of a rank's contours are shown: where the visible interval equals its step
        (its ``fade_zoom``; for the top rank the same rule continued)."""
        k = self.ranks[rank]
        if k.fade_scale is not None:
            return k.fade_zoom
        return round(start_zoom - math.log2(k.step / self.base_interval), ZOOM_DECIMALS)

    def as_json(self) -> list[dict[str, float | int | None]]:
        """Every rank, as TileJSON lists them."""
        return [r.as_json() for r in self.ranks]


def check_units(units: object) -> str:
    """``units`` if it is "m", "ft" or "fm" (case and spelling variants accepted), else raise naming it."""
    if isinstance(units, str) and units.strip().lower() in UNIT_NAMES:
        return UNIT_NAMES[units.strip().lower()]
    raise InvalidParameter(f"units must be one of {', '.join(UNITS)}, got {units!r}")


def check_index_every(index_every: object) -> int:
    """``index_every`` as an int >= 2, else raise naming it."""
    if isinstance(index_every, bool) or not isinstance(index_every, int | float) or index_every != int(index_every):
        raise InvalidParameter(f"index_every must be a whole number >= 2, got {index_every!r}")
    if int(index_every) < 2:
        raise InvalidParameter(f"index_every must be >= 2, got {index_every!r}")
    return int(index_every)


def _is_multiple(value: float, step: float) -> bool:
    q = value / step
    return abs(q - round(q)) <= MULTIPLE_RTOL * max(1.0, abs(q))


def series_above(step: float) -> float:
    """The smallest value of the usual series that is a multiple of ``step`` and larger, within a factor of 10;
    twice ``step`` when the series has none (an interval such as 30 m has no series multiple nearby).

    >>> series_above(20.0), series_above(100.0), series_above(200.0), series_above(30.0)
    (100.0, 200.0, 1000.0, 60.0)
    """
    k0 = math.floor(math.log10(step))
    for k in range(k0, k0 + 2):
        for m in SERIES_MANTISSAS:
            v = round(m * 10.0**k, 9)
            if v > step * (1 + MULTIPLE_RTOL) and v <= 10 * step * (1 + MULTIPLE_RTOL) and _is_multiple(v, step):
                return v
    return 2.0 * step


def default_steps(base_interval: float, index_every: int, elevations: ArrayLike | None = None) -> list[float]:
    """The chain of steps of a base interval: base, index step, then coarser series values, each a multiple of
    the one before. With ``elevations``, the chain stops at the last step that still has two levels (or one,
    when a single level is a multiple of it) among them, so a map zoomed out keeps some lines.

    >>> default_steps(20.0, 5, [20.0, 40.0, 1000.0, 2000.0, 2980.0])
    [20.0, 100.0, 200.0, 1000.0]
    >>> default_steps(10.0, 5)[:6]
    [10.0, 50.0, 100.0, 200.0, 1000.0, 2000.0]
    """
    if not (math.isfinite(base_interval) and base_interval > 0):
        raise InvalidParameter(f"base interval must be a positive number, got {base_interval!r}")
    levels = None
    if elevations is not None:
        levels = np.unique(np.round(np.asarray(elevations, dtype=np.float64), ELEVATION_DECIMALS))
    steps = [float(base_interval), float(base_interval * index_every)]
    while steps[-1] < 1e7 * base_interval:
        steps.append(series_above(steps[-1]))
    if levels is None:
        return steps[:12]
    kept = steps[:1]
    for s in steps[1:]:
        q = levels / s
        n = int(np.count_nonzero(np.abs(q - np.round(q)) <= MULTIPLE_RTOL * np.maximum(1.0, np.abs(q))))
        if n < min(2, len(levels)) or (n < 2 and len(kept) > 1):
            break
        kept.append(s)
    return kept


def parse_schedule(text: str) -> list[tuple[float, float | None]]:
    """An override table ``STEP:HIDE_SCALE,STEP:HIDE_SCALE,...,STEP`` as (step, hide scale) pairs (the last,
    the top rank, has no hide scale). Checked: steps ascending, each a multiple of the one before, hide
    scales ascending; a bad entry is named.

    >>> parse_schedule("20:100000, 100:500000, 1000")
    [(20.0, 100000.0), (100.0, 500000.0), (1000.0, None)]
    """
    if not isinstance(text, str) or not text.strip():
        raise InvalidParameter("schedule must be a non-empty text STEP:HIDE_SCALE,...,STEP")
    entries = [e.strip() for e in text.split(",")]
    out: list[tuple[float, float | None]] = []
    for i, entry in enumerate(entries, start=1):
        where = f"schedule entry {i} {entry!r}"
        fields = [f.strip() for f in entry.split(":")]
        last = i == len(entries)
        if len(fields) != (1 if last else 2):
            want = "STEP (the last entry, never hidden)" if last else "STEP:HIDE_SCALE"
            raise InvalidParameter(f"{where}: expected {want}")
        try:
            numbers = [float(f) for f in fields]
        except ValueError:
            raise InvalidParameter(f"{where}: not a number") from None
        if not all(math.isfinite(v) and v > 0 for v in numbers):
            raise InvalidParameter(f"{where}: step and scale must be positive numbers")
        step, hide = numbers[0], (numbers[1] if len(numbers) > 1 else None)
        if out:
            prev_step, prev_hide = out[-1]
            if step <= prev_step or not _is_multiple(step, prev_step):
                raise InvalidParameter(f"{where}: step must be a larger multiple of the previous step {prev_step:g}")
            if hide is not None and prev_hide is not None and hide <= prev_hide:
                raise InvalidParameter(f"{where}: hide scale must be larger than the previous one {prev_hide:g}")
        out.append((step, hide))
    return out


def make_schedule(
    base_interval: float | None,
    *,
    start_scale: float,
    latitude: float,
    units: str = "m",
    index_every: int = INDEX_EVERY,
    elevations: ArrayLike | None = None,
    override: str | Sequence[tuple[float, float | None]] | None = None,
) -> Schedule:
    """A dataset's interval schedule.

    Parameters
    ----------
    base_interval
        The data's contour interval, in ``units`` (None when it has a single level: one rank that never hides).
    start_scale
        Scale denominator down to which every level is fully drawn (the data's source scale).
    latitude
        Degrees; zooms are computed from scales there (the dataset's centre).
    elevations
        The data's levels: the default chain stops where coarser steps would leave no line.
    override
        A table (text for :func:`parse_schedule`, or its pairs) replacing the default; its first step must
        divide the base interval, so every level has a rank.

    Raises
    ------
    InvalidParameter
        A bad option or override entry, named.
    """
    units = check_units(units)
    index_every = check_index_every(index_every)
    base = float(base_interval) if base_interval else None
    if override is not None:
        pairs = parse_schedule(override) if isinstance(override, str) else list(override)
        if base is not None and not _is_multiple(base, pairs[0][0]):
            raise InvalidParameter(
                f"schedule entry 1: step {pairs[0][0]:g} must divide the data's interval {base:g} {units}"
            )
        base = base or pairs[0][0]
        first_hide = pairs[0][1]
        if first_hide is not None and first_hide <= start_scale:
            raise InvalidParameter(
                f"schedule entry 1: hide scale {first_hide:g} must be larger than the source scale {start_scale:g} "
                "(every level is fully drawn at the source scale)"
            )
    else:
        if base is None:
            return Schedule(1.0, index_every, units, (Rank(0, 1.0, None, None, NEVER, NEVER),))
        steps = default_steps(base, index_every, elevations)
        pairs = [(s, start_scale * nxt / base) for s, nxt in zip(steps, steps[1:], strict=False)]
        pairs.append((steps[-1], None))
    ranks = []
    fade: float | None = float(start_scale)
    for r, (step, hide) in enumerate(pairs):
        if hide is None:
            ranks.append(Rank(r, step, None, None, NEVER, NEVER))
            break
        fade_scale = min(fade, hide) if fade is not None else hide
        fz, hz = (round(float(zoom_for_scale(s, latitude)), ZOOM_DECIMALS) for s in (fade_scale, hide))
        ranks.append(Rank(r, step, fade_scale, hide, fz, hz))
        fade = hide
    return Schedule(base, index_every, units, tuple(ranks))

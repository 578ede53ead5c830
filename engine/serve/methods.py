"""One interface for a generalization method, and its five implementations (ccsm, original, dp, wm, vw).

Tiles, ``/simplify`` and the CLI ask a :class:`Method` the same two questions: which lines to draw in a tile
(:meth:`Method.tile_lines`, fed to the one tile pipeline of :mod:`engine.serve.renderer`) and what one
contour looks like at a scale (:meth:`Method.contour_at`). Whatever else a route or a pool needs to know about
a method (whether a pinned t applies, whether its tiles keep the input's topology, whether it simplifies on
each request) it asks the method too, never its name; the names are those of :mod:`engine.method_names`.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from engine.baselines import simplify_at_scale
from engine.ccsm.regression import t_at_scales
from engine.ccsm.similarity import similarity
from engine.errors import InvalidParameter
from engine.geom.polyline import closed_path
from engine.io.crs import WEB_MERCATOR, make_transformer
from engine.method_names import BASELINE_METHODS, CCSM, METHODS, ORIGINAL
from engine.serve.cache import LRUCache
from engine.serve.pack import DatasetPack, LineSet
from engine.store.records import ContourRecord, DatasetInfo
from engine.types import Coords

#: Baseline results are cached per 1/16 of a zoom level of scale: a 4 % step, invisible on screen.
SCALE_STEPS_PER_OCTAVE = 16


class ContourTooLarge(InvalidParameter):
    """A contour has more vertices than a baseline method is allowed to simplify in one request."""


class RecordSource(Protocol):
    """Where a method gets decoded contour rows (the renderer's cache)."""

    def records(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decoded rows of these fids, in the order given."""
        ...


@dataclass(frozen=True)
class TileLines:
    """What a method draws in a tile, one entry per drawn contour (aligned with the contours asked for)."""

    #: The line set to draw from.
    lines: LineSet
    #: (n,) line of ``lines`` of each contour.
    which: NDArray[np.intp]
    #: (n,) t each line is sliced at (0 for lines that do not morph).
    slice_t: NDArray[np.float64]
    #: (n,) column of ``lines.sig`` that decides which rows a contour keeps.
    column: NDArray[np.int64]
    #: (n,) a line that collapses to one point is drawn again with all its rows (a contour smaller than a grid cell
    #: shows as the full line does instead of vanishing).
    refill: NDArray[np.bool_]

    @classmethod
    def unmorphed(cls, lines: LineSet, which: NDArray[np.intp]) -> TileLines:
        """Lines drawn as stored: t 0, the first significance column, no refill."""
        n = len(which)
        return cls(lines, which, np.zeros(n), np.zeros(n, np.int64), np.zeros(n, bool))


class Method(ABC):
    """A generalization method as the tiles, ``/simplify`` and the CLI see it."""

    name: ClassVar[str]
    #: Whether a hand-pinned t applies (only the continuous method has a t of its own).
    honours_t: ClassVar[bool] = False
    #: Whether the method's lines never cross where the input's do not, so tiles keep that by snap rounding
    #: (docs/design.md section 4.8); the per-scale baselines make crossings of their own.
    keeps_topology: ClassVar[bool] = True
    #: Which stored rows the method's tile lines are cut from: ``ccs``, ``original``, or None (from whole decoded
    #: contours); a tile of a dataset too large to pack whole reads only those (engine.serve.pieces).
    stored_rows: ClassVar[str | None] = None

    @property
    def simplifies_per_request(self) -> bool:
        """Whether the method simplifies whole contours on each request instead of cutting stored rows: pure
        Python and up to super-linear in a contour's size (Wang–Müller), so its tiles queue apart from the
        millisecond ones."""
        return self.stored_rows is None

    def visible(self, pack: DatasetPack, idx: NDArray[np.intp], scale: float) -> NDArray[np.intp]:
        """The contours of ``idx`` drawn at a scale: small rings vanish where the map cannot show them."""
        return idx[scale < pack.vanish[idx]]

    def is_visible(self, rec: ContourRecord, scale: float) -> bool:
        """:meth:`visible` for one decoded contour."""
        return scale < rec.vanish_scale

    @abstractmethod
    def tile_lines(
        self, pack: DatasetPack, idx: NDArray[np.intp], ts: NDArray[np.float64], scale: float, ctx: TileContext
    ) -> TileLines:
        """The lines of contours ``idx`` (positions in ``pack``) at ``scale``, their t being ``ts``."""

    @abstractmethod
    def contour_at(self, rec: ContourRecord, t: float, scale: float, info: DatasetInfo) -> tuple[Coords, float]:
        """One contour at a scale: (EPSG:3857 coordinates, a ring as a closed path; its similarity to the input).

        The similarity is the paper's Sim (1 - improved Fréchet distance / length): for ccsm read from the
        contour's Sim(t) table (exact at the table's t values, linear between them), for the baselines
        computed on their result, 1 for the input itself.
        """


@dataclass(frozen=True)
class TileContext:
    """What a method may need besides the pack: the dataset's metadata, its decoded rows, and the scale at
    the end of the tile's zoom level (z + 1), where what is decided once per level is decided."""

    info: DatasetInfo
    source: RecordSource
    level_end_scale: float
    t_pinned: bool = False


class ContinuousMethod(Method):
    """CCSM: every contour sliced on its continuous changing surface at its own t."""

    name = CCSM
    honours_t = True
    stored_rows = "ccs"

    def tile_lines(
        self, pack: DatasetPack, idx: NDArray[np.intp], ts: NDArray[np.float64], scale: float, ctx: TileContext
    ) -> TileLines:
        """CCS rows; a contour at the target (t = 1) through the whole zoom level keeps rows by the target's own
        significance. The rows are chosen once per level, so every zoom inside it (and a morph tile) keeps
        the same vertices."""
        if ctx.t_pinned:
            at_top = ts >= 1.0
        else:  # t only falls as the zoom rises: at the target at z + 1 means at the target all level long
            at_top = t_at_scales(ctx.info.ladder, pack.tables[idx], ctx.level_end_scale) >= 1.0
        return TileLines(pack.ccs, idx, ts, at_top.astype(np.int64), at_top)

    def contour_at(self, rec: ContourRecord, t: float, scale: float, info: DatasetInfo) -> tuple[Coords, float]:
        """The slice at t; Sim from the contour's table."""
        return rec.base + t * (rec.top - rec.base), float(np.interp(t, rec.sim_t, rec.sim))


class OriginalMethod(Method):
    """The input contours, unsimplified (every contour at every scale)."""

    name = ORIGINAL
    stored_rows = "original"

    def visible(self, pack: DatasetPack, idx: NDArray[np.intp], scale: float) -> NDArray[np.intp]:
        """Every contour."""
        return idx

    def is_visible(self, rec: ContourRecord, scale: float) -> bool:
        """Every contour."""
        return True

    def tile_lines(
        self, pack: DatasetPack, idx: NDArray[np.intp], ts: NDArray[np.float64], scale: float, ctx: TileContext
    ) -> TileLines:
        """The input rows."""
        return TileLines.unmorphed(pack.original, idx)

    def contour_at(self, rec: ContourRecord, t: float, scale: float, info: DatasetInfo) -> tuple[Coords, float]:
        """The input itself."""
        return rec.original, 1.0


class BaselineMethod(Method):
    """A per-scale simplifier (Douglas–Peucker, Wang–Müller, Visvalingam–Whyatt) run on the input contour.

    Results are computed in the working CRS (metres), at the scale rounded to 1/16 of a zoom level, and
    cached per (contour, step).
    """

    keeps_topology = False

    def __init__(
        self,
        name: str,
        cache: LRUCache[tuple[int, str, int], tuple[Coords, Coords]],
        max_vertices: int | None = None,
    ) -> None:
        self.name = name  # type: ignore[misc]
        self.cache = cache
        self.max_vertices = max_vertices
        self._transformers: dict[str, Callable[[Any], Coords]] = {}

    def check_size(self, rec: ContourRecord) -> None:
        """Refuse a contour above ``max_vertices``: Wang–Müller's cost grows faster than its size (a
        1,000,000-vertex line takes minutes), so one request must not be able to ask for it."""
        n = len(rec.original_w)
        if self.max_vertices is not None and n > self.max_vertices:
            raise ContourTooLarge(
                f"contour {rec.contour_id!r} (feature {rec.fid}) has {n:,} vertices; method {self.name!r} "
                f"simplifies contours of at most {self.max_vertices:,} vertices (limit wm_max_vertices); "
                "use method=ccsm, dp or vw"
            )

    def line(self, rec: ContourRecord, scale: float, working_crs: str) -> tuple[Coords, Coords]:
        """(EPSG:3857 closed path, working-CRS coordinates) of the method's result at a scale (cached).

        Raises
        ------
        ContourTooLarge
            The contour has more vertices than ``max_vertices``.
        """
        self.check_size(rec)
        step = round(math.log2(scale) * SCALE_STEPS_PER_OCTAVE)
        hit = self.cache.get((rec.fid, self.name, step))
        if hit is not None:
            return hit
        snapped = 2.0 ** (step / SCALE_STEPS_PER_OCTAVE)
        result_w = np.asarray(simplify_at_scale(self.name, rec.original_w, rec.closed, snapped), dtype=np.float64)
        tr = self._transformers.get(working_crs)
        if tr is None:
            tr = self._transformers[working_crs] = make_transformer(working_crs, WEB_MERCATOR)
        value = (tr(closed_path(result_w) if rec.closed else result_w), result_w)
        self.cache.put((rec.fid, self.name, step), value)
        return value

    def tile_lines(
        self, pack: DatasetPack, idx: NDArray[np.intp], ts: NDArray[np.float64], scale: float, ctx: TileContext
    ) -> TileLines:
        """Each contour's simplified line, taken whole."""
        recs = ctx.source.records(pack.fid[idx].tolist())
        lines = [self.line(r, scale, ctx.info.working_crs)[0] for r in recs]
        return TileLines.unmorphed(LineSet.fixed(lines), np.arange(len(lines)))

    def contour_at(self, rec: ContourRecord, t: float, scale: float, info: DatasetInfo) -> tuple[Coords, float]:
        """The simplified line; Sim computed on it."""
        xy, xy_w = self.line(rec, scale, info.working_crs)
        return xy, float(similarity(rec.original_w, xy_w, rec.closed))


def make_methods(
    baseline_cache_entries: int, max_vertices: Mapping[str, int] | None = None
) -> dict[str, Method]:
    """One instance of every method, by name (the baselines sharing one bounded result cache).

    ``max_vertices`` caps the contour size per baseline method (e.g. ``{"wm": 50_000}``); none by default.
    """
    cache: LRUCache[tuple[int, str, int], tuple[Coords, Coords]] = LRUCache(baseline_cache_entries)
    methods: dict[str, Method] = {CCSM: ContinuousMethod(), ORIGINAL: OriginalMethod()}
    limits = max_vertices or {}
    for name in BASELINE_METHODS:
        methods[name] = BaselineMethod(name, cache, limits.get(name))
    assert set(methods) == set(METHODS), "every method name has an implementation"
    return methods

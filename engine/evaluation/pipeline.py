"""Run the paper's comparison (section 3.2) on a contour set: ladders, similarity curves, crossings, tables.

The per-contour work (CCS build, three baseline ladders, 4 x ``levels`` similarities) runs in worker
processes, a chunk of contours per task, one BLAS thread each (as :mod:`engine.ccsm.build` does). Crossings need
every contour at one level at once, so the workers send back each ladder in its compact form
(:mod:`engine.evaluation.levels`) and the crossings are counted level by level, again on all workers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from engine.ccsm.build import default_workers
from engine.ccsm.similarity import SimilarityReference
from engine.errors import CCSMError, InvalidParameter
from engine.evaluation.levels import (
    EVAL_METHODS,
    Ladder,
    SurfaceLadder,
    VertexLadder,
    contour_ladders,
    eval_params,
    rotate_ring_to,
)
from engine.evaluation.measures import (
    SAME_SCALE_WINDOW,
    ErrorStats,
    crossing_pairs,
    largest_jump,
    linear_density,
    maav,
    pairwise_mean_abs,
    positional_errors,
    same_scale_groups,
)
from engine.params import BuildParams
from engine.types import BadFeature, Contour, ContourSet, FeatureId

#: Called with (stage, done, total).
StageProgress = Callable[[str, int, int], None]

#: Contours per worker task.
CHUNK = 32
#: Methods of the paper's same-scale groups (Table 2); VW is matched to each group afterwards.
PAPER_METHODS: tuple[str, ...] = ("ccsm", "dp", "wm")


@dataclass
class ContourResult:
    """One contour's ladders and similarity curves."""

    #: Position of the contour in the evaluated list.
    index: int
    #: The contour.
    contour: Contour
    #: Method -> ladder.
    ladders: dict[str, Ladder]
    #: (len(EVAL_METHODS), levels) Sim(L0, level i) per method, rows in ``EVAL_METHODS`` order.
    sims: NDArray[np.float64]


def similarity_reference(contour: Contour, ladder: Ladder) -> SimilarityReference:
    """L0 prepared for the similarity of a ladder's levels; a ring starts where the ladder's levels start."""
    xy = contour.coords
    if contour.closed:
        start = ladder.start if isinstance(ladder, SurfaceLadder) else ladder.coords[0]
        xy = rotate_ring_to(xy, start)
    return SimilarityReference.of(xy, contour.closed)


def evaluate_contour(index: int, contour: Contour, levels: int, params: BuildParams) -> ContourResult:
    """Every method's ladder and similarity curve for one contour (raises CCSMError if unusable)."""
    ladders = contour_ladders(contour, levels, params)
    sims = np.empty((len(EVAL_METHODS), levels))
    for row, method in enumerate(EVAL_METHODS):
        ladder = ladders[method]
        reference = similarity_reference(contour, ladder)
        counts = ladder.vertex_counts() if isinstance(ladder, VertexLadder) else None
        for i in range(levels):
            if counts is not None and i > 0 and counts[i] == counts[i - 1]:
                sims[row, i] = sims[row, i - 1]  # nested levels of equal size are the same line
            else:
                sims[row, i] = reference.similarity(ladder.at(i))
    return ContourResult(index=index, contour=contour, ladders=ladders, sims=sims)


def _evaluate_chunk(
    items: Sequence[tuple[int, Contour]], levels: int, params: BuildParams
) -> list[ContourResult | BadFeature]:
    out: list[ContourResult | BadFeature] = []
    for index, contour in items:
        try:
            out.append(evaluate_contour(index, contour, levels, params))
        except CCSMError as exc:
            out.append(BadFeature(contour.id, str(exc)))
    return out


_SHARED: dict[str, object] = {}


def _init_worker(results: list[ContourResult] | None = None) -> None:
    threadpool_limits(1)
    if results is not None:
        _SHARED["results"] = results


def _crossings_for(levels: Sequence[int], methods: Sequence[str]) -> list[tuple[str, int, int, int]]:
    results: list[ContourResult] = _SHARED["results"]  # type: ignore[assignment]
    return _count_crossings(results, levels, methods)


def _count_crossings(
    results: Sequence[ContourResult], levels: Sequence[int], methods: Sequence[str]
) -> list[tuple[str, int, int, int]]:
    closed = [r.contour.closed for r in results]
    out = []
    for method in methods:
        for level in levels:
            lines = [r.ladders[method].at(level) for r in results]
            hit, cross = crossing_pairs(lines, closed)
            out.append((method, int(level), hit, cross))
    return out


@dataclass
class SameScaleContour:
    """The same-scale comparison of one contour (paper Table 2, Fig. 11, Table 3)."""

    #: Input id.
    contour_id: FeatureId
    n_vertices: int
    closed: bool
    #: (g, 4) level index per method (EVAL_METHODS order); columns ccsm, dp, wm from the paper's grouping, vw the VW
    #: level nearest each group's mean similarity.
    groups: NDArray[np.intp]
    #: (g, 4) the similarity of each group member.
    sims: NDArray[np.float64]
    #: Eq. 11 over CCSM/DP/WM (the paper's three methods); NaN without groups.
    maav: float
    #: Eq. 11 over all four methods.
    maav_with_vw: float
    #: (4, 4) mean |Sim_A - Sim_B| over groups.
    sd: NDArray[np.float64]
    #: Method -> mean linear density (eq. 12) over the groups' results.
    linear_density: dict[str, float]
    #: Method -> all positional errors (eq. 13) of the groups' results, metres.
    errors: dict[str, NDArray[np.float64]]
    #: Groups whose VW member lies within the same-scale window of the three others.
    vw_in_window: int


def same_scale_contour(result: ContourResult, window: float = SAME_SCALE_WINDOW) -> SameScaleContour | None:
    """The same-scale groups of one contour and its measures; None when it has no group."""
    rows = [EVAL_METHODS.index(m) for m in PAPER_METHODS]
    vw_row = EVAL_METHODS.index("vw")
    groups3 = same_scale_groups([result.sims[r] for r in rows], window=window)
    if not groups3:
        return None
    vw_curve = result.sims[vw_row]
    groups = []
    for g in groups3:
        mean = float(np.mean([result.sims[r, i] for r, i in zip(rows, g, strict=True)]))
        groups.append((*g, int(np.argmin(np.abs(vw_curve - mean)))))
    levels = np.array(groups, dtype=np.intp)
    order = [PAPER_METHODS.index(m) if m in PAPER_METHODS else 3 for m in EVAL_METHODS]
    levels = levels[:, order]  # columns in EVAL_METHODS order
    sims = result.sims[np.arange(len(EVAL_METHODS))[None, :], levels]
    c = result.contour
    density: dict[str, float] = {}
    errors: dict[str, NDArray[np.float64]] = {}
    for row, method in enumerate(EVAL_METHODS):
        ladder = result.ladders[method]
        errs, dens = [], []
        for k in range(len(levels)):
            simplified = ladder.at(int(levels[k, row]))
            e = positional_errors(c.coords, simplified, c.closed)
            errs.append(e)
            dens.append(linear_density(simplified, c.closed, float(e.std())))
        errors[method] = np.concatenate(errs)
        finite = [d for d in dens if np.isfinite(d)]
        density[method] = float(np.mean(finite)) if finite else float("nan")
    spread = sims.max(axis=1) - sims.min(axis=1)
    paper_cols = [EVAL_METHODS.index(m) for m in PAPER_METHODS]
    return SameScaleContour(
        contour_id=c.id,
        n_vertices=c.n_vertices,
        closed=c.closed,
        groups=levels,
        sims=sims,
        maav=maav(sims[:, paper_cols]),
        maav_with_vw=maav(sims),
        sd=pairwise_mean_abs(sims),
        linear_density=density,
        errors=errors,
        vw_in_window=int(np.count_nonzero(spread <= window + 1e-12)),
    )


#: A rise of Sim from one level to the next smaller than this is rounding, not a rise.
RISE_TOLERANCE = 1e-9


@dataclass
class Evaluation:
    """Everything ``ccsm evaluate`` writes."""

    #: Number of levels per method.
    levels: int
    #: Method names, the row order of ``sims``.
    methods: tuple[str, ...]
    #: (n,) ids of the evaluated contours.
    contour_ids: list[FeatureId]
    closed: NDArray[np.bool_]
    #: (n, methods, levels) similarity of every level of every method for every evaluated contour.
    sims: NDArray[np.float64]
    #: Rows (method, level 0-based, intersecting pairs, crossing pairs).
    crossings: list[tuple[str, int, int, int]]
    #: Every how many levels crossings were counted.
    crossing_step: int
    #: The same-scale comparison of the randomly drawn contours (Table 2, Fig. 11, Table 3).
    table_contours: list[SameScaleContour]
    #: Contours left out, with the reason.
    bad_features: list[BadFeature]
    target: str
    seed: int
    n_input: int
    #: Stage -> seconds.
    timings: dict[str, float] = field(default_factory=dict)

    def mean_curve(self) -> NDArray[np.float64]:
        """(methods, levels) mean similarity over contours (Fig. 10)."""
        return self.sims.mean(axis=0)

    def contour_jumps(self) -> NDArray[np.float64]:
        """(n, methods) each contour's largest consecutive-level jump per method."""
        return np.max(np.abs(np.diff(self.sims, axis=2)), axis=2)

    def contour_rises(self) -> NDArray[np.float64]:
        """(n, methods) each contour's largest rise of Sim from one level to the next (0 if it never rises)."""
        return np.maximum(np.max(np.diff(self.sims, axis=2), axis=2), 0.0)

    def contours_rising(self) -> NDArray[np.intp]:
        """(methods,) how many contours' Sim rises by more than ``RISE_TOLERANCE`` somewhere."""
        return np.count_nonzero(self.contour_rises() > RISE_TOLERANCE, axis=0)

    def mean_curve_rises(self) -> NDArray[np.float64]:
        """(methods,) the largest rise of each method's mean curve (0 if it never rises)."""
        return np.maximum(np.max(np.diff(self.mean_curve(), axis=1), axis=1), 0.0)

    def mean_curve_jumps(self) -> NDArray[np.float64]:
        """(methods,) the largest jump of each method's mean curve."""
        return np.array([largest_jump(c) for c in self.mean_curve()])


def evaluate_set(
    contour_set: ContourSet,
    *,
    levels: int = 100,
    sample: int | None = None,
    seed: int = 0,
    target: str = "extreme",
    source_scale: float = 50_000.0,
    target_scale: float = 500_000.0,
    workers: int | None = None,
    crossing_step: int = 1,
    table_contours: int = 20,
    progress: StageProgress | None = None,
) -> Evaluation:
    """Compare CCSM, DP, WM and VW on a contour set as the paper's section 3.2 does.

    Parameters
    ----------
    contour_set
        Contours in a metric CRS.
    levels
        Results per method and contour (paper: 100).
    sample
        Evaluate this many contours drawn at random (seeded); None = all.
    seed
        Seed of the sample and of the contours of the same-scale tables.
    target
        ``"extreme"``: the paper's Fig. 10 set-up, every method down to its minimal form (a line's two end
        points, a ring's triangle); ``"scale"``: CCSM to DP at ``target_scale``, each baseline to its own
        result at ``target_scale``.
    workers
        Processes; None = one per core.
    crossing_step
        Count crossings at every ``crossing_step``-th level (and always the first and last).
    table_contours
        Contours drawn (seeded) for Table 2, Fig. 11 and Table 3.
    progress
        Called with (stage, done, total).

    Raises
    ------
    InvalidParameter
        ``levels`` < 2, ``sample`` < 1, ``crossing_step`` < 1, a bad target or scale.
    """
    if levels < 2:
        raise InvalidParameter(f"levels must be >= 2, got {levels}")
    if sample is not None and sample < 1:
        raise InvalidParameter(f"sample must be >= 1, got {sample}")
    if crossing_step < 1:
        raise InvalidParameter(f"crossing_step must be >= 1, got {crossing_step}")
    params = eval_params(target, source_scale, target_scale)
    timings: dict[str, float] = {}
    rng = np.random.default_rng(seed)
    contours = list(contour_set.contours)
    if sample is not None and sample < len(contours):
        pick = np.sort(rng.choice(len(contours), size=sample, replace=False))
        contours = [contours[int(i)] for i in pick]
    workers = default_workers() if workers is None else max(1, workers)
    items = list(enumerate(contours))
    chunks = [items[i : i + CHUNK] for i in range(0, len(items), CHUNK)]

    t0 = time.perf_counter()
    raw: list[ContourResult | BadFeature] = []
    done = 0
    if progress:
        progress("ladders", 0, len(items))
    if workers == 1 or len(chunks) <= 1:
        with threadpool_limits(1):
            for chunk in chunks:
                raw.extend(_evaluate_chunk(chunk, levels, params))
                done += len(chunk)
                if progress:
                    progress("ladders", done, len(items))
    else:
        with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker) as pool:
            futures = [pool.submit(_evaluate_chunk, chunk, levels, params) for chunk in chunks]
            for fut, chunk in zip(futures, chunks, strict=True):
                raw.extend(fut.result())
                done += len(chunk)
                if progress:
                    progress("ladders", done, len(items))
    results = [r for r in raw if isinstance(r, ContourResult)]
    bad = list(contour_set.bad_features) + [r for r in raw if isinstance(r, BadFeature)]
    timings["ladders_and_similarity_s"] = time.perf_counter() - t0
    if not results:
        raise InvalidParameter("no contour could be evaluated")

    t0 = time.perf_counter()
    crossing_levels = sorted(set(range(0, levels, crossing_step)) | {levels - 1})
    crossings = _crossings(results, crossing_levels, workers, progress)
    timings["crossings_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    tables = _same_scale_tables(results, table_contours, rng, progress)
    timings["same_scale_tables_s"] = time.perf_counter() - t0

    return Evaluation(
        levels=levels,
        methods=EVAL_METHODS,
        contour_ids=[r.contour.id for r in results],
        closed=np.array([r.contour.closed for r in results]),
        sims=np.stack([r.sims for r in results]),
        crossings=crossings,
        crossing_step=crossing_step,
        table_contours=tables,
        bad_features=bad,
        target=target,
        seed=seed,
        n_input=len(contours),
        timings=timings,
    )


def _crossings(
    results: list[ContourResult], crossing_levels: list[int], workers: int, progress: StageProgress | None
) -> list[tuple[str, int, int, int]]:
    tasks = [(m, crossing_levels[i : i + 5]) for m in EVAL_METHODS for i in range(0, len(crossing_levels), 5)]
    total = len(crossing_levels) * len(EVAL_METHODS)
    rows: list[tuple[str, int, int, int]] = []
    if progress:
        progress("crossings", 0, total)
    if workers == 1 or len(results) < 200:
        for method, lv in tasks:
            rows.extend(_count_crossings(results, lv, [method]))
            if progress:
                progress("crossings", len(rows), total)
    else:
        with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker, initargs=(results,)) as pool:
            futures = [pool.submit(_crossings_for, lv, [method]) for method, lv in tasks]
            for fut in futures:
                rows.extend(fut.result())
                if progress:
                    progress("crossings", len(rows), total)
    order = {m: k for k, m in enumerate(EVAL_METHODS)}
    return sorted(rows, key=lambda r: (order[r[0]], r[1]))


def _same_scale_tables(
    results: list[ContourResult], n: int, rng: np.random.Generator, progress: StageProgress | None
) -> list[SameScaleContour]:
    """Draw contours at random (seeded) until ``n`` have at least one same-scale group."""
    out: list[SameScaleContour] = []
    if progress:
        progress("same-scale tables", 0, n)
    for k in rng.permutation(len(results)):
        table = same_scale_contour(results[int(k)])
        if table is not None:
            out.append(table)
            if progress:
                progress("same-scale tables", len(out), n)
        if len(out) >= n:
            break
    return out


def pooled_errors(tables: Sequence[SameScaleContour]) -> dict[str, ErrorStats]:
    """Table 3: positional error statistics per method over every same-scale result of the drawn contours."""
    out = {}
    for method in EVAL_METHODS:
        arrays = [t.errors[method] for t in tables]
        out[method] = ErrorStats.of(np.concatenate(arrays) if arrays else np.zeros(0))
    return out


def finite_mean(values: Sequence[float]) -> float:
    """Mean of the finite values (NaN if none)."""
    v = [x for x in values if math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")

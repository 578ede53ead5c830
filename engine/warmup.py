"""Compile the numba kernels once, ahead of use: ``python -m engine.warmup``.

numba compiles on first call and caches the machine code next to the sources (``cache=True``). Doing it at
install time keeps that one-off cost (about 20 s on 2 cores) out of the first build, the first tile and the
first test that touch a kernel.
"""

from __future__ import annotations

import time

import numpy as np


def warm_up() -> float:
    """Call every compiled kernel on a tiny input; returns the seconds it took."""
    from engine.baselines import ladder, simplify_at_scale
    from engine.ccsm.similarity import SimilarityReference, similarity
    from engine.evaluation.levels import ranks_from_levels
    from engine.geom.douglas_peucker import douglas_peucker
    from engine.method_names import BASELINE_METHODS
    from engine.tiles.significance import row_significance

    start = time.perf_counter()
    s = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    ring = np.column_stack([np.cos(s) * 500 + np.sin(5 * s) * 40, np.sin(s) * 300])
    line = np.column_stack([np.linspace(0, 2000, 40), np.sin(np.linspace(0, 9, 40)) * 80])
    for coords, closed in ((ring, True), (line, False)):
        douglas_peucker(coords, 10.0, closed)
        similarity(coords, coords[::2], closed)
        rows = np.vstack([coords, coords[:1]]) if closed else coords  # a ring's rows are closed paths
        SimilarityReference.of(coords, closed).slice_similarities(rows, rows * 0.99, np.linspace(0.0, 1.0, 11))
        for method in BASELINE_METHODS:
            levels = ladder(method, coords, closed, levels=5)
            ranks_from_levels(coords, levels)
            simplify_at_scale(method, coords, closed, 250_000)
        row_significance(coords, coords * 0.9)
    _check_build_crossings(line)
    _render_one_tile(ring, line)
    _check_tile_topology()
    return time.perf_counter() - start


def _check_build_crossings(line: np.ndarray) -> None:
    """The build's crossing check over the ladder's steps, on a line and a copy of it that passes through it,
    the blocks' box test and the input's touch test."""
    from engine.ccsm.near import boxes_meeting
    from engine.ccsm.topology import InputTouches, SweepIndex

    below, above = line - [0.0, 5.0], line + [0.0, 5.0]
    index = SweepIndex.of([line, below], [line, above])
    index.contacts_in_steps(np.zeros((2, 1)), np.ones((2, 1)), np.ones((2, 1), dtype=bool))
    boxes = np.array([[*x.min(axis=0), *x.max(axis=0)] for x in (line, below)])
    boxes_meeting(boxes, boxes)
    _ = (0, 1) in InputTouches([line, below])


def _check_tile_topology() -> None:
    """The kernels that keep served lines from crossing (docs/design.md section 4.8): the grid crossing check,
    snap rounding and the morph check, on two lines that cross."""
    from engine.tiles.clip import clip_lines_exact
    from engine.tiles.crossings import crossing_owner_pairs
    from engine.tiles.morph_crossings import MorphParts, morph_crossing_pairs
    from engine.tiles.snap_round import snap_round

    start = np.array([[0, 0], [10, 0], [4, 1], [6, 1]], dtype=np.int64)
    end = np.array([[0, 0], [10, 0], [4, -1], [6, 3]], dtype=np.int64)
    part_len, owner = np.array([2, 2], dtype=np.int64), np.array([0, 1], dtype=np.int64)
    crossing_owner_pairs(end, part_len, owner)
    clip_lines_exact(end.astype(np.float64), part_len, 1.0, 9.0)  # exact lines cut before snap rounding
    snap_round(end.astype(np.float64), part_len)
    morph_crossing_pairs(MorphParts(start, end, part_len, owner), np.array([[0.0, 0.0], [0.0, 0.5], [0.0, 1.0]]))


def _render_one_tile(ring: np.ndarray, line: np.ndarray) -> None:
    """Build two contours into a throwaway store and draw a tile and a morph tile, from the whole dataset and
    from its stored pieces: compiles the kernels of every tile path."""
    import tempfile
    from pathlib import Path

    from engine.build.datasets import save_built
    from engine.ccsm.build import build_contour_set
    from engine.params import BuildParams
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds, Contour, ContourSet

    origin = np.array([750_000.0, 4_060_000.0])  # UTM 16N, near the bundled sample
    contours = [Contour(0, 100.0, ring + origin, True), Contour(1, 120.0, line + origin, False)]
    contour_set = ContourSet(contours, "EPSG:32616", "EPSG:32616", name="warmup")
    built = build_contour_set(contour_set, BuildParams(), workers=1)
    with tempfile.TemporaryDirectory() as tmp:
        store = CCSStore(Path(tmp) / "warmup.sqlite")
        try:
            info = save_built(store, "warmup", built, name="warmup", source="warmup", digest="0", params={})
            z, x, y = tiles_covering(Bounds(*info.bounds_3857), 12)[0]
            renderer = Renderer(store)
            for name, method in renderer.methods.items():
                if method.simplifies_per_request:  # no tile kernels of their own: compiled above
                    continue
                renderer.tile("warmup", z, x, y, zoom=z + 0.5 if method.honours_t else None, method=name)
            renderer.morph_tile("warmup", z, x, y)  # its own kernels (morph runs), else compiled on first use
            # A dataset larger than the contour memory joins each tile's stored pieces: its own kernels.
            Renderer(store, contour_cache_bytes=0).tile("warmup", z, x, y)
        finally:
            store.close()


if __name__ == "__main__":
    print(f"numba kernels ready ({warm_up():.1f} s)")

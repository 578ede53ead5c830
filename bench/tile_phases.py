"""Where a tile's time goes, phase by phase, on stores of growing size (issue 12 item 6: tiles at 64× as fast as
at 1×): the tiles ``bench_scale.py --tiles`` times, rendered by one new renderer per store, with the functions
that do each phase wrapped by timers (nothing else changes).

Phases: ``info`` (the dataset's metadata and version per request), ``query`` (the contours' R*Tree),
``heads`` (the touched contours' per-contour columns), ``pieces sql`` / ``pieces decode`` (the stored pieces
meeting the tile: SQLite's R*Tree, join and page reads, then the blobs to arrays), ``join`` (each contour's
pieces into one line), ``pack`` (chunk boxes and per-contour columns), ``lines`` (the method's lines), ``cut``
(runs, slice, thin, quantise, clip), ``encode`` (MVT), ``labels`` (the label layer). ``other`` is the rest of
the tile. Milliseconds summed over the tiles after the first (which pays for what a renderer does once), then
per tile.

Usage: python bench/tile_phases.py STORE[,STORE...] [--cache-mb MB] [--n 120]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if not os.environ.get("PYTHONPATH"):  # else the checkout PYTHONPATH names (to time main's code with this script)
    sys.path.insert(0, str(REPO))

PHASES = ("info", "query", "heads", "pieces sql", "pieces decode", "join", "pack", "lines", "cut", "encode", "labels")


def instrument(spent: dict[str, float]) -> None:
    """Wrap the functions of each phase so their time adds up in ``spent`` (innermost phase wins)."""
    import engine.serve.cutters as cutters
    import engine.serve.label_layer as label_layer
    import engine.serve.methods as methods
    import engine.serve.pack as pack
    import engine.serve.pieces as pieces
    import engine.serve.renderer as renderer

    stack: list[str] = []

    def timed(phase: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            stack.append(phase)
            try:
                return fn(*args, **kwargs)
            finally:
                stack.pop()
                dt = time.perf_counter() - t0
                spent[phase] += dt
                if stack:  # an inner phase's time is not its caller's
                    spent[stack[-1]] -= dt

        return wrapper

    try:
        import engine.store.store as store_module

        decode = "piece_column"
    except ImportError:  # a checkout from before the store was split
        import engine.store.sqlite as store_module  # type: ignore[no-redef]

        decode = "_column"
    store = store_module.CCSStore
    store.data_version = timed("info", store.data_version)  # type: ignore[method-assign]
    store.dataset = timed("info", store.dataset)  # type: ignore[method-assign]
    store.query = timed("query", store.query)  # type: ignore[method-assign]
    store.load_heads = timed("heads", store.load_heads)  # type: ignore[method-assign]
    try:
        import engine.serve.heads as heads

        heads.DatasetHeads.of = timed("heads", heads.DatasetHeads.of)  # type: ignore[method-assign]
    except ImportError:  # a checkout without the head memory
        pass
    if hasattr(store, "pieces_meeting"):
        store.pieces_meeting = timed("pieces sql", store.pieces_meeting)  # type: ignore[method-assign]
    setattr(store_module, decode, timed("pieces decode", getattr(store_module, decode)))
    pieces.joined = timed("join", pieces.joined)
    pack.DatasetPack.of_lines = classmethod(timed("pack", pack.DatasetPack.of_lines.__func__))  # type: ignore[method-assign]
    pieces.LineSet.of = classmethod(timed("pack", pack.LineSet.of.__func__))  # type: ignore[method-assign]
    for m in ("ContinuousMethod", "OriginalMethod"):
        cls = getattr(methods, m, None)
        if cls is not None:
            cls.tile_lines = timed("lines", cls.tile_lines)
    cutters.TileCutter.cut = timed("cut", cutters.TileCutter.cut)  # type: ignore[method-assign]
    renderer.encode_line_tile = timed("encode", renderer.encode_line_tile)
    label_layer.LabelLayer.layer = timed("labels", label_layer.LabelLayer.layer)  # type: ignore[method-assign]


def chosen_tiles(store: Any, n: int) -> tuple[str, list[tuple[int, int, int]]]:
    """The tiles bench_scale.tile_run renders: ``n`` distinct z12-z14 tiles of the store's first dataset."""
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    dataset = store.dataset_ids()[0]
    info = store.dataset(dataset)
    tiles = [t for z in (12, 13, 14) for t in tiles_covering(Bounds(*info.bounds_3857), z)]
    rng = np.random.default_rng(0)
    return dataset, [tiles[i] for i in rng.choice(len(tiles), size=min(n, len(tiles)), replace=False)]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("stores")
    parser.add_argument("--cache-mb", type=float, default=None)
    parser.add_argument("--n", type=int, default=120)
    args = parser.parse_args()
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore

    spent: dict[str, float] = defaultdict(float)
    instrument(spent)
    print(f"{'store':26} {'tile p50':>8} {'p95':>6} " + " ".join(f"{p:>8}" for p in (*PHASES, "other")))
    for path in args.stores.split(","):
        store = CCSStore(path, readonly=True)
        dataset, tiles = chosen_tiles(store, args.n)
        kw = {} if args.cache_mb is None else {"contour_cache_bytes": int(args.cache_mb * 2**20)}
        r = Renderer(store, **kw)
        r.pack(dataset)
        wall = []
        for i, (z, x, y) in enumerate(tiles):
            if i == 1:
                spent.clear()
            t0 = time.perf_counter()
            r.tile(dataset, z, x, y)
            wall.append(time.perf_counter() - t0)
        w = np.array(wall[1:]) * 1000
        k = len(w)
        other = w.sum() - 1000 * sum(spent.values())
        cells = [1000 * spent[p] / k for p in PHASES] + [other / k]
        print(
            f"{Path(path).name:26} {np.percentile(w, 50):8.2f} {np.percentile(w, 95):6.2f} "
            + " ".join(f"{c:8.3f}" for c in cells),
            flush=True,
        )


if __name__ == "__main__":
    main()

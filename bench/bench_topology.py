"""Crossings between contours across scales: ccsm's build against per-scale simplifiers, and in served tiles.

Prints, per source, for log-spaced scales between ``--min-scale`` and ``--max-scale``, how many pairs of
different contours that are apart in the input touch or cross: ccsm as served (target at the target scale,
crossing repair on), ccsm without the repair, and Douglas–Peucker / Visvalingam–Whyatt / Wang–Müller run at each
scale the way per-zoom tile tools do. Rings too small for a scale are left out for every method alike.

With ``--tiles``, the source is also built into a store and every tile of the zooms covering those scales is
rendered at three fractional zooms: it prints the pairs apart in the input that cross *properly* on the tile
grid, and how many of them meet in the exact slices (the rest are lines closer than the grid's rounding,
docs/design.md section 4.8).

With ``--render-times``, every tile of z8-z14 over the source is rendered in process with snap rounding off (plain
rounding, as before issue 13) and on: per-level tiles at z and z + 0.5, and morph tiles; it prints render time
p50/p95/max of each, how many tiles came out different (snap-rounded tiles, morph tiles with contours held) and
how many contours the morph tiles hold still (docs/morph-tiles.md). ``--morph-only`` times the morph tiles alone.

    python bench/bench_topology.py [SOURCE ...] [--synthetic] [--scales 20] [--tiles] [--render-times [--morph-only]]

``--synthetic`` adds two contour sets made like GDAL's (tests/synthetic_rasters.py): lines of one level touching at
saddles, at 10 m, and a dense 2 m interval. ``--real`` adds the real DEMs of tests/real_dems.py, contoured the same
way: Maunga Whau at 1 m and 2 m, and Howe Sound / the Coast Mountains from matplotlib's topobathy.npz at 50 m.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import mapbox_vector_tile
import numpy as np

import engine.serve.morph_tiles as morph_module
from engine import BuildParams, build_contour_set, read_source, sample_contours_path
from engine.baselines import simplify_at_scale
from engine.build.datasets import SourceSpec, build_dataset
from engine.ccsm.regression import t_for_scale
from engine.ccsm.topology import INPUT_TOUCH_M, crossing_pairs, proper_crossing_pairs
from engine.geom.polyline import closed_path
from engine.serve.renderer import Renderer, TileOptions
from engine.serve.simplify import simplify
from engine.store.store import CCSStore
from engine.tiles.grid import tiles_covering
from engine.tiles.scale import zoom_for_scale
from engine.types import Bounds

Pair = tuple[object, object]


def new_pairs(lines: list[np.ndarray], ids: list[object], allowed: set[Pair]) -> int:
    found = {(ids[a], ids[b]) for a, b in crossing_pairs(lines)}
    return len({p for p in found if p not in allowed and (p[1], p[0]) not in allowed})


def synthetic_sources(folder: Path) -> list[Path]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from synthetic_rasters import fractal_heights, write_exact_level_geojson

    made = []
    for name, (seed, beta, n, interval, relief) in {
        "saddle-10m": (7, 2.5, 56, 10.0, 220.0),
        "dense-2m": (8, 2.9, 40, 2.0, 70.0),
    }.items():
        z = fractal_heights(seed, beta, n=n, relief_m=relief)
        path = folder / f"{name}.geojson"
        made.append(write_exact_level_geojson(path, z, interval, west=10.0, north=47.0, cell_deg=1 / 1200))
    return made


def real_sources(folder: Path) -> list[Path]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from real_dems import write_maunga_whau_contours, write_topobathy_contours

    return [
        write_maunga_whau_contours(folder / "maunga-whau-1m.geojson", 1.0),
        write_maunga_whau_contours(folder / "maunga-whau-2m.geojson", 2.0),
        write_topobathy_contours(folder / "topobathy-50m.geojson", 50.0),
    ]


def scale_table(source: Path, scales: np.ndarray) -> None:
    contours = read_source(source)
    start = time.perf_counter()
    repaired = build_contour_set(contours, BuildParams())
    built_s = time.perf_counter() - start
    start = time.perf_counter()
    plain = build_contour_set(contours, BuildParams(resolve_crossings=False))
    plain_s = time.perf_counter() - start
    by_id = {c.id: c for c in contours.contours}
    ids = [s.contour_id for s in repaired.surfaces]
    inputs = [by_id[i] for i in ids]
    met = crossing_pairs([closed_path(c.coords) if c.closed else c.coords for c in inputs], within=INPUT_TOUCH_M)
    allowed = {(ids[a], ids[b]) for a, b in met}
    print(f"\n## {source.name}: {len(ids)} contours; input pairs already meeting (left out): {len(allowed)}")
    print(f"build {built_s:.1f} s with the repair, {plain_s:.1f} s without; {repaired.repaired} got a finer target\n")
    print(f"{'scale':>10} {'ccsm':>6} {'ccsm-norepair':>14} {'dp':>6} {'vw':>6} {'wm':>6}")
    totals = dict.fromkeys(("ccsm", "plain", "dp", "vw", "wm"), 0)
    for scale in scales:
        row = {}
        for key, built in (("ccsm", repaired), ("plain", plain)):
            visible = [s for s in built.surfaces if s.vanish_scale > scale]
            lines = [s.at(t_for_scale(built.model.ladder, s.t_at_scale, float(scale))) for s in visible]
            row[key] = new_pairs(lines, [s.contour_id for s in visible], allowed)
        visible_ids = [s.contour_id for s in repaired.surfaces if s.vanish_scale > scale]
        for method in ("dp", "vw", "wm"):
            lines = []
            for cid in visible_ids:
                c = by_id[cid]
                out = simplify_at_scale(method, c.coords, c.closed, float(scale))
                lines.append(closed_path(out) if c.closed else out)
            row[method] = new_pairs(lines, visible_ids, allowed)
        for key, value in row.items():
            totals[key] += value
        print(f"{scale:>10.0f} {row['ccsm']:>6} {row['plain']:>14} {row['dp']:>6} {row['vw']:>6} {row['wm']:>6}")
    print(
        f"{'sum':>10} {totals['ccsm']:>6} {totals['plain']:>14} {totals['dp']:>6} {totals['vw']:>6} {totals['wm']:>6}"
    )


def tile_lines(data: bytes | None) -> tuple[list[np.ndarray], list[int]]:
    if data is None:
        return [], []
    layer = mapbox_vector_tile.decode(data, default_options={"y_coord_down": True}).get("contours", {})
    lines, fids = [], []
    for feat in layer.get("features", []):
        geometry = feat["geometry"]
        parts = [geometry["coordinates"]] if geometry["type"] == "LineString" else geometry["coordinates"]
        lines += [np.asarray(p, dtype=float) for p in parts]
        fids += [feat["id"]] * len(parts)
    return lines, fids


def tile_table(source: Path, smallest: float, largest: float) -> None:
    with tempfile.TemporaryDirectory() as folder:
        store = CCSStore(Path(folder) / "bench.sqlite")
        build_dataset(store, SourceSpec(source, "bench", "bench"))
        renderer = Renderer(store)
        info = renderer.info("bench")[0]
        original = {c.fid: c.coords_3857 for c in simplify(renderer, "bench", 1.0, method="original").contours}
        fids = list(original)
        allowed = {(fids[a], fids[b]) for a, b in crossing_pairs([original[f] for f in fids], within=INPUT_TOUCH_M)}
        lat = math.degrees(math.atan(math.sinh((info.bounds_3857[1] + info.bounds_3857[3]) / 2 / 6378137.0)))
        low = math.floor(float(zoom_for_scale(smallest, lat)))
        high = math.floor(float(zoom_for_scale(largest, lat)))
        print(f"\n{source.name}: tiles (zooms z, z+0.3, z+0.7), pairs apart in the input crossing properly")
        print(f"{'zoom':>5} {'tiles':>6} {'crossing':>9} {'exact-meet':>11}")
        for z in range(low, high + 1):
            tiles = crossing = exact = 0
            for zoom in (z, z + 0.3, z + 0.7):
                for tile in tiles_covering(Bounds(*info.bounds_3857), z):
                    lines, owner = tile_lines(renderer.tile("bench", *tile, zoom=zoom).data)
                    tiles += 1
                    pairs = {
                        (min(owner[a], owner[b]), max(owner[a], owner[b])) for a, b in proper_crossing_pairs(lines)
                    }
                    pairs = {p for p in pairs if p[0] != p[1] and p not in allowed and (p[1], p[0]) not in allowed}
                    crossing += len(pairs)
                    if pairs:
                        drawn = {
                            c.fid: c.coords_3857
                            for c in simplify(
                                renderer, "bench", renderer.scale_of_tile(tile, zoom), all_levels=True
                            ).contours
                        }
                        exact += sum(1 for a, b in pairs if crossing_pairs([drawn[a], drawn[b]]))
            print(f"{z:>5} {tiles:>6} {crossing:>9} {exact:>11}")


class HeldCount:
    """Counts the contours the renderer's morph tiles hold still: wraps the ``untangle`` it calls."""

    def __init__(self) -> None:
        self.per_tile: list[int] = []
        self.untangle = morph_module.untangle

    def __enter__(self) -> HeldCount:
        def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
            parts, held = self.untangle(*args, **kwargs)
            self.per_tile.append(held)
            return parts, held

        morph_module.untangle = counted
        return self

    def __exit__(self, *exc: object) -> None:
        morph_module.untangle = self.untangle


def render_times(source: Path, zooms: range, morph_only: bool = False) -> None:
    """Render time of every tile of ``zooms`` with snap rounding off and on (in process, warm caches)."""
    with tempfile.TemporaryDirectory() as folder, HeldCount() as held:
        store = CCSStore(Path(folder) / "bench.sqlite")
        build_dataset(store, SourceSpec(source, "bench", "bench"))
        variants = {flag: Renderer(store, TileOptions(snap_rounding=flag)) for flag in (False, True)}
        info = variants[True].info("bench")[0]
        tiles = [t for z in zooms for t in tiles_covering(Bounds(*info.bounds_3857), z)]
        for r in variants.values():  # pack, labels and compiled kernels ready before timing
            r.tile("bench", *tiles[0])
            r.morph_tile("bench", *tiles[0])
        held.per_tile.clear()
        times: dict[tuple[str, bool], list[float]] = {}
        differ = dict.fromkeys(("tile", "morph"), 0)
        for tile in tiles:
            for kind in ("morph",) if morph_only else ("tile", "morph"):
                for zoom in (tile.z, tile.z + 0.5) if kind == "tile" else (None,):
                    data = {}
                    for flag, r in variants.items():
                        start = time.perf_counter()
                        result = r.tile("bench", *tile, zoom=zoom) if kind == "tile" else r.morph_tile("bench", *tile)
                        times.setdefault((kind, flag), []).append(time.perf_counter() - start)
                        data[flag] = result.data
                    differ[kind] += data[False] != data[True]
        print(f"\n{source.name}: render time in process, z{zooms.start}-z{zooms.stop - 1}, {len(tiles)} tiles")
        for (kind, flag), values in sorted(times.items()):
            ms = np.array(values) * 1000
            what = f"{kind}s, snap rounding {'on' if flag else 'off'}"
            print(
                f"{what:>28}: p50 {np.percentile(ms, 50):6.2f} ms  p95 {np.percentile(ms, 95):6.2f} ms  "
                f"max {ms.max():7.1f} ms  (n = {len(ms)})"
            )
        print(f"tiles that differ: {differ['tile']} per-level tiles (snap-rounded), {differ['morph']} morph tiles")
        counts = np.array(held.per_tile)
        print(f"morph tiles holding contours still: {np.count_nonzero(counts)}, {counts.sum()} contours held in all")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sources", nargs="*", type=Path)
    parser.add_argument("--synthetic", action="store_true", help="add GDAL-style saddle and dense 2 m data")
    parser.add_argument("--real", action="store_true", help="add the real DEMs of tests/real_dems.py")
    parser.add_argument("--scales", type=int, default=20)
    parser.add_argument("--min-scale", type=float, default=50_000.0, help="largest scale's denominator")
    parser.add_argument("--max-scale", type=float, default=500_000.0, help="smallest scale's denominator")
    parser.add_argument("--tiles", action="store_true", help="also count proper crossings in the tiles")
    parser.add_argument("--render-times", action="store_true", help="tile render times, snap rounding off and on")
    parser.add_argument("--morph-only", action="store_true", help="with --render-times: morph tiles only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        sources = list(args.sources) or ([] if args.synthetic or args.real else [sample_contours_path()])
        if args.synthetic:
            sources += synthetic_sources(Path(folder))
        if args.real:
            sources += real_sources(Path(folder))
        scales = np.geomspace(args.min_scale, args.max_scale, args.scales)
        for source in sources:
            if args.render_times:
                render_times(Path(source), range(8, 15), args.morph_only)
                continue
            scale_table(Path(source), scales)
            if args.tiles:
                tile_table(Path(source), args.max_scale, args.min_scale)


if __name__ == "__main__":
    main()

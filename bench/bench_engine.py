"""Benchmark of the CCSM build on the bundled sample: build time, per-contour and per-vertex cost, slice cost,
peak memory, and growth with the data's size.

Run: ``python bench/bench_engine.py [--workers 2] [--factors 1,4,16] [--growth-subset 0]``

Growth replicates contours side by side (shifted in x by the set's width plus 1 km, so copies never
overlap) and times the build of each copy count. ``--growth-subset N`` grows the first N contours instead of
the whole sample (the 16x full sample is about 30,000 contours).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.ccsm.build import build_contour_set  # noqa: E402
from engine.io.source import read_source, sample_contours_path  # noqa: E402
from engine.params import BuildParams  # noqa: E402
from engine.types import ContourSet  # noqa: E402


def peak_rss_mb() -> tuple[float, float]:
    """Peak resident memory of this process and of its (waited-for) children, MB (Linux reports KB)."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return own, children


def replicate(cs: ContourSet, factor: int) -> ContourSet:
    """``factor`` copies of a contour set side by side in x (copies do not overlap)."""
    xy = np.concatenate([c.coords for c in cs.contours])
    width = float(np.ptp(xy[:, 0])) + 1000.0
    contours = []
    for k in range(factor):
        shift = np.array([k * width, 0.0])
        contours += [dataclasses.replace(c, id=f"{c.id}#{k}", coords=c.coords + shift) for c in cs.contours]
    return dataclasses.replace(cs, contours=contours, bad_features=[])


def time_build(cs: ContourSet, params: BuildParams, workers: int) -> tuple[float, object]:
    t0 = time.perf_counter()
    built = build_contour_set(cs, params, workers=workers)
    return time.perf_counter() - t0, built


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--factors", default="1,4,16", help="copy counts of the growth table")
    ap.add_argument("--growth-subset", type=int, default=0, help="grow the first N contours (0 = all)")
    ap.add_argument("--slices", type=int, default=11, help="t values per contour for the slice timing")
    args = ap.parse_args()
    params = BuildParams()

    cs = read_source(sample_contours_path())
    n = len(cs.contours)
    nv = sum(c.n_vertices for c in cs.contours)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"python {platform.python_version()}, workers {args.workers}"
    )
    print(f"sample: {n} contours, {nv} vertices, {sum(c.closed for c in cs.contours)} rings")

    build_contour_set(ContourSet(cs.contours[:4], cs.working_crs, cs.source_crs), params, workers=1)  # JIT warm-up
    seconds, built = time_build(cs, params, args.workers)
    surfaces = built.surfaces  # type: ignore[attr-defined]
    print(f"build (surfaces + similarity tables + scale model + crossing repair): {seconds:.2f} s")
    print(f"  {1000 * seconds / n:.2f} ms per contour, {1000 * seconds / (nv / 1000):.1f} ms per 1,000 input vertices")
    print(
        f"  built {len(surfaces)}, bad {len(built.bad_features)}, "  # type: ignore[attr-defined]
        f"rebuilt with a finer target so no slices cross: {built.repaired}"  # type: ignore[attr-defined]
    )

    ts = np.linspace(0.0, 1.0, args.slices)
    t0 = time.perf_counter()
    for s in surfaces:
        for t in ts:
            s.at(float(t))
    per_slice = (time.perf_counter() - t0) / (len(surfaces) * len(ts))
    rows = np.mean([len(s.base) for s in surfaces])
    print(f"slice ccs.at(t): {1000 * per_slice:.4f} ms per contour (mean {rows:.0f} points per slice)")

    own, children = peak_rss_mb()
    print(f"peak memory: {own:.0f} MB this process, {children:.0f} MB largest worker")

    base = cs if args.growth_subset <= 0 else dataclasses.replace(cs, contours=cs.contours[: args.growth_subset])
    print("\nlinear growth" + (f" (first {args.growth_subset} contours)" if args.growth_subset > 0 else ""))
    print(f"{'copies':>6} {'contours':>9} {'vertices':>9} {'build s':>9} {'ms/contour':>11} {'x time / x data':>16}")
    first: float | None = None
    for factor in (int(f) for f in args.factors.split(",")):
        data = replicate(base, factor)
        secs, _ = time_build(data, params, args.workers)
        vertices = sum(c.n_vertices for c in data.contours)
        first = first or secs / factor
        print(
            f"{factor:>6} {len(data.contours):>9} {vertices:>9} {secs:>9.2f} "
            f"{1000 * secs / len(data.contours):>11.2f} {secs / factor / first:>16.2f}"
        )
    own, children = peak_rss_mb()
    print(f"peak memory after growth: {own:.0f} MB this process, {children:.0f} MB largest worker")


if __name__ == "__main__":
    main()

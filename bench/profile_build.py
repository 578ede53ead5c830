"""Where the build's time goes (issue 26 item 1): cProfile over one whole build in one process, top costs.

Each case is built by :func:`engine.build.datasets.build_dataset` (the entry ``ccsm build`` calls: read and trace
the DEM, surfaces, similarity tables, scale model, crossing repair, labels, store writes) into a fresh store, with
one worker and no executor, so every step runs in this one process where cProfile sees it (``ccsm build
--workers 1`` runs the same code). Cases (bench_scale.py's data, written into var/bench-scale if missing):

``16x``  the 16x fractal terrain (2048 cells a side) traced at 20 m;
``5m``   the 1x terrain (512 cells a side) traced at 5 m: four times the lines in the same place.

Every case runs in a fresh child process twice: once plain (the build's wall time, µs per input vertex) and once
under cProfile (its overhead inflates Python calls, so the shares, not its absolute seconds, are what to read;
the compiled numba kernels and SQLite are single calls to it, their time counted where they are called).
Prints, per case, the plain and profiled µs per input vertex, the cumulative time of the build's phases (reading,
the CCS of each contour and its parts, the scale model, the crossing repair, the store writes, the labels), then
the top functions by cumulative time (the
time in a function and all it calls) and by self time (in the function's own code and the C calls it makes), each
as seconds, share of the profiled build and µs per input vertex. The raw profile is kept as
var/bench/profile/CASE.prof (``python -m pstats`` or snakeviz read it).

Usage: python bench/profile_build.py [--cases 16x,5m] [--top 12] [--no-plain]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "bench"))

OUT = REPO / "var" / "bench" / "profile"
#: case -> (side of the bench_scale.py terrain in cells, contour interval in m)
CASES = {"16x": (2048, 20.0), "5m": (512, 5.0), "4x": (1024, 20.0), "1x": (512, 20.0)}
#: The build's phases: (label, file, function) whose cumulative time is printed first (indented: part of the one
#: above it). The crossing repair rebuilds the contours it gives finer targets through build_ccs, so that time is
#: in both lines; the labels are placed while the store is written, so theirs is part of the store writes.
PHASES = [
    ("read and trace the DEM", "engine/io/source.py", "read_source"),
    ("CCS of each contour (+ repair's rebuilds)", "engine/ccsm/ccs.py", "build_ccs"),
    ("  similarity tables", "engine/ccsm/similarity.py", "slice_similarities"),
    ("  correspondence", "engine/ccsm/ccs.py", "_correspondence"),
    ("  surface fit check", "engine/ccsm/surface.py", "check_fit"),
    ("  surface rows", "engine/ccsm/surface.py", "surface_rows"),
    ("scale model", "engine/ccsm/regression.py", "fit_scale_model"),
    ("crossing repair (with its rebuilds)", "engine/ccsm/build.py", "resolve_crossings"),
    ("  contacts by block", "engine/ccsm/blocks.py", "find_crossings_by_block"),
    ("store writes (with labels)", "engine/store/store.py", "save"),
    ("  merging the shards", "engine/store/store.py", "_stage_shards"),
    ("  labels", "engine/build/labels.py", "place_dataset_labels"),
]


def dem(side: int) -> Path:
    from bench_scale import WORK, terrain, write_dem

    path = WORK / f"terrain-{side}.tif"
    if not path.exists():
        WORK.mkdir(parents=True, exist_ok=True)
        write_dem(path, terrain(side))
    return path


def build_once(case: str, profile: bool) -> dict[str, float]:
    """Build the case into a fresh store in this process; its vertices and wall seconds (and the profile saved)."""
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.store.store import CCSStore

    side, interval = CASES[case]
    path = dem(side)
    OUT.mkdir(parents=True, exist_ok=True)
    store_path = OUT / f"{case}.sqlite"
    for stale in OUT.glob(f"{store_path.name}*"):
        stale.unlink()
    store = CCSStore(store_path)
    spec = SourceSpec(path, "bench", path.stem, interval=interval)
    profiler = cProfile.Profile() if profile else None
    t0 = time.perf_counter()
    if profiler is not None:
        info, _ = profiler.runcall(build_dataset, store, spec, workers=1, executor=None, force=True)
    else:
        info, _ = build_dataset(store, spec, workers=1, executor=None, force=True)
    seconds = time.perf_counter() - t0
    store.close()
    if profiler is not None:
        profiler.dump_stats(OUT / f"{case}.prof")
    return {"contours": info.n_contours, "vertices": info.n_vertices, "seconds": seconds}


def child(case: str, profile: bool) -> dict[str, float]:
    cmd = [sys.executable, __file__, "--one", case] + (["--profile"] if profile else [])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def where(key: tuple[str, int, str]) -> str:
    """``module.py:line(function)`` with the path made short (engine/..., or the library's file name)."""
    file, line, name = key
    if file == "~":
        return name  # a built-in: {method 'execute' of 'sqlite3.Cursor' objects}
    path = Path(file)
    try:
        short = str(path.relative_to(REPO))
    except ValueError:
        short = "/".join(path.parts[-2:])
    return f"{short}:{line}({name})"


def top(stats: pstats.Stats, column: int, n: int, total: float, vertices: float) -> None:
    """The ``n`` largest entries of ``stats`` by ``column`` (2: self time, 3: cumulative)."""
    raw = stats.stats  # type: ignore[attr-defined]  # {(file, line, name): (cc, nc, tt, ct, callers)}
    rows = sorted(raw.items(), key=lambda kv: kv[1][column], reverse=True)[:n]
    print(f"  {'seconds':>8} {'share':>6} {'µs/vertex':>9} {'calls':>10}  function")
    for key, value in rows:
        s = value[column]
        print(f"  {s:8.2f} {s / total:6.1%} {1e6 * s / vertices:9.2f} {value[1]:10d}  {where(key)}")


def phases(stats: pstats.Stats, total: float, vertices: float) -> None:
    """Cumulative time of each of :data:`PHASES` (summed over the functions of that name in that file)."""
    raw = stats.stats  # type: ignore[attr-defined]
    print(f"  {'seconds':>8} {'share':>6} {'µs/vertex':>9} {'calls':>10}  phase (function)")
    for label, file, name in PHASES:
        hits = [v for (f, _, n), v in raw.items() if n == name and f.endswith(file)]
        s, calls = sum(v[3] for v in hits), sum(v[1] for v in hits)
        print(f"  {s:8.2f} {s / total:6.1%} {1e6 * s / vertices:9.2f} {calls:10d}  {label} ({file}:{name})")


def report(case: str, plain: dict[str, float] | None, profiled: dict[str, float], n: int) -> None:
    vertices = profiled["vertices"]
    side, interval = CASES[case]
    print(
        f"\n== {case}: terrain-{side}.tif at {interval:g} m, {profiled['contours']:.0f} contours, "
        f"{vertices:.0f} input vertices; load average {os.getloadavg()[0]:.1f}"
    )
    if plain is not None:
        print(
            f"plain build      {plain['seconds']:8.1f} s  {1e6 * plain['seconds'] / vertices:6.1f} µs per input vertex "
            "(one process)"
        )
    print(
        f"under cProfile   {profiled['seconds']:8.1f} s  "
        f"{1e6 * profiled['seconds'] / vertices:6.1f} µs per input vertex"
    )
    stats = pstats.Stats(str(OUT / f"{case}.prof"))
    total = profiled["seconds"]
    print("phases (cumulative time under the profiler):")
    phases(stats, total, vertices)
    print(f"top {n} by cumulative time (share of the profiled build, µs per input vertex under the profiler):")
    top(stats, 3, n, total, vertices)
    print(f"top {n} by self time:")
    top(stats, 2, n, total, vertices)
    sys.stdout.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="16x,5m", help=f"Comma-separated, of {', '.join(CASES)}.")
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--no-plain", action="store_true", help="Skip the plain (unprofiled) timing run.")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--profile", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(build_once(args.one, args.profile)))
        return
    print(f"{os.cpu_count()} cores; every build in one process (workers=1, no executor), a fresh child each")
    for case in args.cases.split(","):
        plain = None if args.no_plain else child(case, profile=False)
        profiled = child(case, profile=True)
        report(case, plain, profiled, args.top)


if __name__ == "__main__":
    main()

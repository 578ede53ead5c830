"""Peak memory of reading a big contour file (issue 12 item 2): one read of every feature against reads of a
batch of features at a time, through a scratch file as the build reads.

The contour files are made once from the bench's fractal terrain (``bench_scale``, the ``grid`` series at 20 m)
and written into var/bench-scale as a GeoPackage, a Shapefile and (``--formats``) a GeoJSON file. Each read
runs in a process of its own (``--one``), so its peak RSS is its own; ``whole`` gathers every feature into one
read before its lines are made (``engine.io.vector_reader.READ_VERTICES`` unbounded), as reads were before batches;
``batched`` is the read as it is (every format streamed in Arrow batches, reads of about
``ASSEMBLE_BATCH_VERTICES`` vertices).

Usage: python bench/bench_vector_read.py [--size 64] [--formats gpkg,shp] [--modes whole,batched]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

DRIVERS = {"gpkg": "GPKG", "shp": "ESRI Shapefile", "geojson": "GeoJSON"}


def rss_mb(field: str = "VmRSS") -> float:
    """Resident memory of this process, MB: now (VmRSS) or at its peak (VmHWM). Not ``ru_maxrss``, which a
    process started by another keeps from its parent's peak at the fork."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    return 0.0


def contour_files(size: int, formats: list[str]) -> list[Path]:
    """Contours of the ``size``× bench terrain at 20 m, written once per format (in the DEM's CRS)."""
    import bench_scale
    import shapely
    from pyogrio.raw import write

    from engine.io.source import read_source

    dem = next(path for series, label, path, _ in bench_scale.datasets([size]) if label == f"{size}x")
    paths = [dem.with_name(f"contours-{dem.stem}.{fmt}") for fmt in formats]
    missing = [(fmt, p) for fmt, p in zip(formats, paths, strict=True) if not p.exists()]
    if missing:
        cs = read_source(dem, interval=20.0)
        lines = [np.vstack([c.coords, c.coords[:1]]) if c.closed else c.coords for c in cs.contours]
        wkb = np.asarray(shapely.to_wkb([shapely.LineString(xy) for xy in lines]), dtype=object)
        elevations = np.array([c.elevation for c in cs.contours])
        for fmt, path in missing:
            write(
                path,
                wkb,
                [elevations],
                ["elevation"],
                driver=DRIVERS[fmt],
                crs=cs.working_crs,
                geometry_type="LineString",
            )
    return paths


def read_one(path: Path, mode: str) -> dict[str, float]:
    """Read ``path`` through a scratch file in this process; seconds, contours, RSS before and at the peak."""
    import engine.io.vector_reader as vector
    from engine.io.source import read_source
    from engine.scratch import ReadScratch

    if mode == "whole":
        vector.READ_VERTICES = 1 << 40
    before = rss_mb()
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        scratch = ReadScratch(tmp)
        try:
            start = time.perf_counter()
            cs = read_source(path, scratch=scratch)
            seconds = time.perf_counter() - start
            n = len(cs.contours)
        finally:
            scratch.close()
    peak = rss_mb("VmHWM")
    return {"seconds": seconds, "contours": n, "rss_before_mb": before, "peak_mb": peak}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=64, help="terrain size, × the sample (1, 4, 16, 64)")
    parser.add_argument("--formats", default="gpkg,shp,geojson", help="comma-separated: gpkg, shp, geojson")
    parser.add_argument("--modes", default="whole,batched", help="comma-separated: whole, batched")
    parser.add_argument("--one", nargs=2, metavar=("PATH", "MODE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(read_one(Path(args.one[0]), args.one[1])))
        return
    formats = args.formats.split(",")
    files = contour_files(args.size, formats)
    print(f"{'file':<28} {'MB':>6} {'mode':<8} {'contours':>9} {'read s':>7} {'RSS before':>11} {'peak RSS':>9}")
    for path in files:
        for mode in args.modes.split(","):
            out = subprocess.run(
                [sys.executable, __file__, "--one", str(path), mode], check=True, capture_output=True, text=True
            )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            suffixes = (".shp", ".dbf", ".shx") if path.suffix == ".shp" else (path.suffix,)
            size_mb = sum(path.with_suffix(s).stat().st_size for s in suffixes) / 2**20
            print(
                f"{path.name:<28} {size_mb:>6.0f} {mode:<8} {r['contours']:>9} {r['seconds']:>7.1f} "
                f"{r['rss_before_mb']:>9.0f}MB {r['peak_mb']:>7.0f}MB"
            )


if __name__ == "__main__":
    main()

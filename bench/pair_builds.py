"""One-process builds of the same data by two checkouts, one after the other, with the digest of their tiles:
to show a change of the build keeps every tile's bytes and what it does to the build's time.

Each build runs in a fresh child process whose ``PYTHONPATH`` is the checkout (``--code``; this one when not
given), with one worker and no executor (as ``ccsm build --workers 1``), into a fresh store; then the child draws
every z10 and z12 tile and every 7th z14 tile of the dataset and prints the SHA-256 of their bytes. Cases are
profile_build.py's (bench_scale.py's terrains, written into var/bench-scale if missing). Compile each checkout's
numba kernels first (``PYTHONPATH=CHECKOUT python -m engine.warmup``), or its first build pays for them.

Usage: python bench/pair_builds.py --code OLD --code NEW [--cases 4x,5m,16x] [--repeat 1]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))


def build_and_digest(dem: Path, interval: float, store_path: Path) -> dict[str, object]:
    """In this process (the child, whose engine is the checkout's): build the DEM into a fresh store, then
    digest its tiles."""
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.serve.renderer import Renderer
    from engine.store.store import CCSStore
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    store = CCSStore(store_path)
    start = time.perf_counter()
    info, _ = build_dataset(store, SourceSpec(dem, "bench", "bench", interval=interval), workers=1, force=True)
    seconds = time.perf_counter() - start
    renderer = Renderer(store)
    digest = hashlib.sha256()
    for z, step in ((10, 1), (12, 1), (14, 7)):
        for tz, tx, ty in tiles_covering(Bounds(*store.dataset("bench").bounds_3857), z)[::step]:
            digest.update(renderer.tile("bench", tz, tx, ty).data or b"")
    store.close()
    return {"seconds": seconds, "vertices": info.n_vertices, "digest": digest.hexdigest()[:16]}


def child(code: Path, case: str) -> dict[str, object]:
    """Build ``case`` with ``code`` in a child process (the DEM written here, by this checkout's bench_scale)."""
    from profile_build import CASES, dem

    side, interval = CASES[case]
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, __file__, "--one", str(dem(side)), "--interval", str(interval)]
        cmd += ["--store", str(Path(tmp) / "pair.sqlite")]
        env = {**os.environ, "PYTHONPATH": str(code)}
        done = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--code", action="append", type=Path, help="checkout to build with (repeatable) [this one]")
    parser.add_argument("--cases", default="4x,5m", help="comma-separated, of profile_build.py's cases")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--interval", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--store", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(build_and_digest(args.one, args.interval, args.store)))
        return
    codes = [c.resolve() for c in (args.code or [REPO])]
    load = os.getloadavg()[0]
    print(f"{os.cpu_count()} cores; one-process builds (workers=1), a fresh child each; load average {load:.1f}")
    print(f"{'case':>5} {'code':>28} {'build s':>8} {'µs/vertex':>10}  tiles sha256")
    for case in args.cases.split(","):
        for _ in range(args.repeat):
            for code in codes:
                r = child(code, case)
                us = 1e6 * float(r["seconds"]) / float(r["vertices"])
                print(f"{case:>5} {str(code)[-28:]:>28} {float(r['seconds']):8.1f} {us:10.1f}  {r['digest']}")
                sys.stdout.flush()


if __name__ == "__main__":
    main()

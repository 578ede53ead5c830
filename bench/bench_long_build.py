"""Writes during one long build (issue 28's repro): does anything wait on it?

Starts ``ccsm serve`` (real uvicorn on loopback, an admin token set), uploads one LineString of ``--vertices``
vertices (1,000,000 in the issue), and while its build runs asks, each timed:

- ``GET /readyz`` and ``GET /healthz``;
- a second upload (a small valid one): 202, or 503 with Retry-After;
- ``DELETE`` of the building dataset; afterwards the dataset must stay deleted (404) once the build would
  have ended, and no ``.ccsm-spool-*`` scratch file may be left beside the store.

With the default per-contour limit the long upload is refused at once (413 naming the limit); the repro therefore
runs with ``CCSM_MAX_CONTOUR_VERTICES=0`` (and uploads up to 64 MB) unless ``--keep-limit`` is given.

Run: ``python bench/bench_long_build.py [--vertices 1000000] [--keep-limit] [--watch-seconds 30]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.app.conftest import LiveServer  # noqa: E402

TOKEN = "bench-long-build"
AUTH = {"authorization": f"Bearer {TOKEN}", "content-type": "application/geo+json"}


def wiggly_line(n: int, ident: str, elevation: float) -> bytes:
    """A FeatureCollection of one wiggly line of ``n`` vertices near 36.6 N, 84.25 W."""
    rng = np.random.default_rng(n)
    a = np.linspace(0, 40 * np.pi, n)
    lon = -84.25 + 0.05 * a / a[-1] + 0.002 * np.sin(a) + 1e-5 * rng.standard_normal(n)
    lat = 36.6 + 0.002 * np.cos(a * 1.3) + 1e-5 * rng.standard_normal(n)
    feature = {
        "type": "Feature",
        "properties": {"id": ident, "elevation": elevation},
        "geometry": {"type": "LineString", "coordinates": np.round(np.c_[lon, lat], 7).tolist()},
    }
    return json.dumps({"type": "FeatureCollection", "features": [feature]}).encode()


def timed(call: str, fn: object) -> httpx.Response:
    t0 = time.perf_counter()
    response = fn()  # type: ignore[operator]
    ms = 1000 * (time.perf_counter() - t0)
    retry = response.headers.get("retry-after")
    print(f"  {call:<34} {response.status_code}  {ms:8.1f} ms" + (f"  Retry-After {retry}" if retry else ""))
    return response


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=int, default=1_000_000)
    ap.add_argument("--keep-limit", action="store_true", help="keep CCSM_MAX_CONTOUR_VERTICES at its default")
    ap.add_argument("--watch-seconds", type=float, default=30.0, help="how long to watch after the DELETE")
    args = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="ccsm-long-build-"))
    env = {
        "CCSM_STORE_PATH": str(work / "ccsm.sqlite"),
        "CCSM_SERVE_SAMPLE": "false",
        "CCSM_ADMIN_TOKEN": TOKEN,
        "CCSM_MAX_UPLOAD_MB": "64",
    }  # the 26 MB body
    if not args.keep_limit:
        env["CCSM_MAX_CONTOUR_VERTICES"] = "0"
    body = wiggly_line(args.vertices, "mega", 400.0)
    print(f"one line of {args.vertices:,} vertices ({len(body) / 2**20:.1f} MB); store in {work}")
    server = LiveServer(env, log=work / "serve.log")
    try:
        server.wait_healthy(600)
        with httpx.Client(base_url=server.url, timeout=120) as http:
            up = timed("POST /datasets (mega)", lambda: http.post("/datasets?id=mega", content=body, headers=AUTH))
            if up.status_code != 202:
                print(f"  -> {up.json().get('detail')}")
                return
            while (state := http.get("/datasets/mega").json()["state"]) != "building":
                if state in ("ready", "failed"):
                    print(f"  the build ended ({state}) before it could be watched")
                    return
                time.sleep(0.1)
            time.sleep(2.0)  # well into the build
            print("during the build:")
            timed("GET /readyz", lambda: http.get("/readyz"))
            timed("GET /healthz", lambda: http.get("/healthz"))
            small = wiggly_line(500, "small", 500.0)
            timed("POST /datasets (small)", lambda: http.post("/datasets?id=small", content=small, headers=AUTH))
            timed("DELETE /datasets/mega", lambda: http.delete("/datasets/mega", headers=AUTH))
            timed("GET /datasets/mega", lambda: http.get("/datasets/mega"))
            deadline = time.monotonic() + args.watch_seconds
            while time.monotonic() < deadline and http.get("/datasets/mega").status_code == 404:
                time.sleep(0.5)
            after = http.get("/datasets/mega").status_code
            print(f"after {args.watch_seconds:.0f} s: GET /datasets/mega {after} (404 = the DELETE held)")
            small_state = http.get("/datasets/small").json().get("state")
            print(f"the small upload: {small_state}")
    finally:
        server.stop()
    left = sorted(p.name for p in work.glob(".ccsm-spool-*"))
    print(f"scratch files left beside the store: {left or 'none'}")


if __name__ == "__main__":
    main()

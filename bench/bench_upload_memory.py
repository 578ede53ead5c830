"""Memory of the server around large uploads (issue 10): RSS before, at the peak and after four concurrent
uploads of about 19 MB each (one line of ~760,000 vertices, the issue's hostile upload), builds included.

The server streams each body to disk and parses it in a check process of its own (app/datasets/uploads.py), one at a
time by default; builds run in processes of their own (app/datasets/builds.py). So the server's own RSS should stay
near its baseline throughout, and the child processes' memory is bounded by how many run at once.
To stay within a few minutes the builds are deleted (their processes ended) once every upload is accepted and
``--build-seconds`` have passed; pass a large value to let them finish.

Run: ``python bench/bench_upload_memory.py [--uploads 4] [--vertices 760000] [--build-seconds 20]``
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]


def rss_mb(pid: int) -> float:
    """Resident memory of one process, MB (0 when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            try:
                kids = {int(k) for k in (task / "children").read_text().split()}
            except OSError:
                continue
            todo.extend(kids - out)
            out |= kids
    return out


def long_line(n: int, seed: int) -> bytes:
    """A FeatureCollection of one wiggly line of ``n`` vertices near 36.6 N, 84.25 W."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 40 * np.pi, n)
    lon = -84.25 + 0.05 * a / a[-1] + 0.002 * np.sin(a) + 1e-5 * rng.standard_normal(n)
    lat = 36.6 + 0.002 * np.cos(a * 1.3) + 1e-5 * rng.standard_normal(n)
    coords = ",".join(f"[{x:.7f},{y:.7f}]" for x, y in zip(lon, lat, strict=True))
    head = json.dumps({"type": "Feature", "properties": {"id": f"long{seed}", "elevation": 400}})[:-1]
    return (
        f'{{"type":"FeatureCollection","features":[{head},"geometry":'
        f'{{"type":"LineString","coordinates":[{coords}]}}}}]}}'
    ).encode()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--uploads", type=int, default=4)
    ap.add_argument("--vertices", type=int, default=760_000)
    ap.add_argument("--build-seconds", type=float, default=20.0)
    args = ap.parse_args()

    bodies = [long_line(args.vertices, seed) for seed in range(args.uploads)]
    print(
        f"{args.uploads} uploads of {np.mean([len(b) for b in bodies]) / 2**20:.1f} MB ({args.vertices} vertices each)"
    )
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    tmp = Path(tempfile.mkdtemp())
    env = {
        **os.environ,
        "CCSM_STORE_PATH": str(tmp / "ccsm.sqlite"),
        "CCSM_SERVE_SAMPLE": "false",
        "CCSM_BUILD_QUEUE": str(args.uploads),
    }
    server = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from app.cli import main; main()",
            "serve",
            "--port",
            str(port),
            "--log-level",
            "warning",
        ],
        cwd=REPO,
        env=env,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        time.sleep(1.0)
        base = rss_mb(server.pid)
        peak = {"server": base, "builds": 0.0}
        stop = threading.Event()

        def sample() -> None:
            while not stop.is_set():
                peak["server"] = max(peak["server"], rss_mb(server.pid))
                peak["builds"] = max(peak["builds"], sum(rss_mb(p) for p in descendants(server.pid)))
                time.sleep(0.05)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        t0 = time.perf_counter()
        with ThreadPoolExecutor(args.uploads) as pool:
            answers = list(
                pool.map(
                    lambda b: httpx.post(
                        url + "/datasets", content=b, timeout=1800, headers={"content-type": "application/geo+json"}
                    ),
                    bodies,
                )
            )
        accepted = time.perf_counter() - t0
        print("answers:", [r.status_code for r in answers], f"in {accepted:.1f} s")
        ids = [r.json()["id"] for r in answers if r.status_code == 202]
        deadline = time.monotonic() + args.build_seconds
        while time.monotonic() < deadline:
            states = [httpx.get(f"{url}/datasets/{i}").json()["state"] for i in ids]
            if all(s != "building" for s in states):
                break
            time.sleep(0.5)
        states = [httpx.get(f"{url}/datasets/{i}").json()["state"] for i in ids]
        for i in ids:
            httpx.delete(f"{url}/datasets/{i}")
        time.sleep(3.0)
        stop.set()
        sampler.join()
        after = rss_mb(server.pid)
        left = descendants(server.pid)
        print(f"states before delete: {states}")
        print(f"server RSS: baseline {base:.0f} MB, peak {peak['server']:.0f} MB, after {after:.0f} MB")
        print(
            f"child processes (upload checks, builds, render workers): peak RSS {peak['builds']:.0f} MB in total, "
            f"{len(left)} left after delete"
        )
    finally:
        server.terminate()
        server.wait(30)


if __name__ == "__main__":
    main()

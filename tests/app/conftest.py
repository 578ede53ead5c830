"""Fixtures of the service tests: a small synthetic contour set, a store built once, clients and servers."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import Settings
from engine.build.datasets import SourceSpec, build_dataset
from engine.store.store import CCSStore

REPO = Path(__file__).resolve().parents[2]
#: Centre of the synthetic hills (near the bundled sample, Jacksboro TN), degrees.
LON0, LAT0 = -84.25, 36.6
INTERVAL = 20.0


def synthetic_features(seed: int = 7) -> list[dict]:
    """Three noisy hills of nested rings plus two open lines: about 30 contours, 20 m interval."""
    rng = np.random.default_rng(seed)
    feats = []
    k = 0
    for hx, hy, levels in ((0.0, 0.0, 12), (0.035, 0.02, 8), (-0.03, 0.025, 6)):
        for i in range(levels):
            r = 0.025 * (levels - i) / levels + 0.002
            n = 80
            a = np.linspace(0, 2 * np.pi, n, endpoint=False)
            rr = r * (1 + 0.12 * np.sin(5 * a + i) + 0.04 * rng.standard_normal(n))
            lon = LON0 + hx + rr * np.cos(a) / np.cos(np.radians(LAT0))
            lat = LAT0 + hy + rr * np.sin(a)
            coords = np.column_stack([lon, lat])
            coords = np.vstack([coords, coords[:1]])
            feats.append(
                {
                    "type": "Feature",
                    "properties": {"id": f"h{k}", "elevation": 400 + INTERVAL * i},
                    "geometry": {"type": "LineString", "coordinates": np.round(coords, 7).tolist()},
                }
            )
            k += 1
    for j in range(2):
        x = np.linspace(LON0 - 0.06, LON0 + 0.06, 120)
        y = LAT0 - 0.04 - 0.004 * j + 0.003 * np.sin(x * 300) + 0.0005 * rng.standard_normal(len(x))
        feats.append(
            {
                "type": "Feature",
                "properties": {"id": f"line{j}", "elevation": 380 - INTERVAL * j},
                "geometry": {
                    "type": "LineString",
                    "coordinates": np.round(np.column_stack([x, y]), 7).tolist(),
                },
            }
        )
    return feats


def write_geojson(path: Path, feats: list[dict]) -> Path:
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


@pytest.fixture(scope="session")
def synthetic_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_geojson(tmp_path_factory.mktemp("src") / "hills.geojson", synthetic_features())


@pytest.fixture(scope="session")
def built_store(tmp_path_factory: pytest.TempPathFactory, synthetic_path: Path) -> Path:
    """A store holding the synthetic set as dataset 'hills' (built once per run)."""
    path = tmp_path_factory.mktemp("store") / "ccsm.sqlite"
    build_dataset(CCSStore(path), SourceSpec(synthetic_path, "hills", "hills"), workers=1)
    return path


@pytest.fixture()
def store(tmp_path: Path, built_store: Path) -> Path:
    """A private copy of the store holding 'hills'."""
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    copy = tmp_path / "ccsm.sqlite"
    shutil.copy(built_store, copy)
    return copy


def make_settings(store: Path, sources: list[Path], **kw: object) -> Settings:
    return Settings(store_path=store, sources=[str(s) for s in sources], web_dir=REPO / "web", **kw)  # type: ignore[arg-type]


@pytest.fixture()
def client(tmp_path: Path, built_store: Path, synthetic_path: Path) -> Iterator[TestClient]:
    """A TestClient on a private copy of the built store (tests may write to it)."""
    store = tmp_path / "ccsm.sqlite"
    src = CCSStore(built_store)
    src._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    app = create_app(make_settings(store, [synthetic_path], max_upload_mb=0.5, build_workers=1))
    # A local client addressing the server as localhost: writes need no token (app/routes/security.py).
    with TestClient(app, base_url="http://localhost", client=("127.0.0.1", 50000)) as c:
        yield c


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LiveServer:
    """``ccsm serve`` (uvicorn) in a subprocess on a free loopback port."""

    def __init__(self, env: dict[str, str], args: list[str] | None = None, log: Path | None = None) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        full_env = {**os.environ, **env}
        self.log_path = log
        self._log = open(log, "wb") if log else subprocess.DEVNULL
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from app.cli import main; main()",
                "serve",
                "--port",
                str(self.port),
                "--log-level",
                "warning",
                *(args or []),
            ],
            env=full_env,
            cwd=REPO,
            stdout=self._log,
            stderr=subprocess.STDOUT,
        )

    def wait_healthy(self, timeout: float = 300.0) -> None:  # a first start on a loaded 2-core machine is slow
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}")
            try:
                if httpx.get(self.url + "/healthz", timeout=2).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise TimeoutError("server did not become healthy")

    def wait_ready(self, dataset: str, timeout: float = 180.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            r = httpx.get(f"{self.url}/datasets/{dataset}", timeout=5)
            if r.status_code == 200 and r.json()["state"] == "ready":
                return r.json()
            if r.status_code == 200 and r.json()["state"] == "failed":
                raise RuntimeError(r.text)
            time.sleep(0.2)
        raise TimeoutError(f"dataset {dataset} not ready")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self._log is not subprocess.DEVNULL:
            self._log.close()


@pytest.fixture(scope="module")
def live(
    tmp_path_factory: pytest.TempPathFactory, built_store: Path, synthetic_path: Path
) -> Iterator[LiveServer]:
    """A real server on loopback serving a copy of the synthetic store."""
    d = tmp_path_factory.mktemp("live")
    store = d / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    server = LiveServer(
        {
            "CCSM_STORE_PATH": str(store),
            "CCSM_SOURCES": str(synthetic_path),
            "CCSM_BUILD_WORKERS": "1",
            "CCSM_MAX_UPLOAD_MB": "0.5",
        },
        log=d / "server.log",
    )
    try:
        server.wait_healthy()
        server.wait_ready("hills")
        yield server
    finally:
        server.stop()

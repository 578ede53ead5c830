"""Issue 10, faults of the store: a full disk, a read-only file system, a damaged file, files left by killed
builds, and a server stopped while it builds. Each is a clear answer, never a 500 or a traceback loop.

The disk faults use real mounts (a 2 MB tmpfs, a read-only bind mount; the tests run as root) and always
unmount.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import httpx
from fastapi.testclient import TestClient

from app.main import create_app
from engine.store.store import CCSStore
from tests.app.conftest import REPO, LiveServer, make_settings, synthetic_features

GEOJSON = {"content-type": "application/geo+json"}
BODY = json.dumps({"type": "FeatureCollection", "features": synthetic_features(seed=2)[:3]})


@contextmanager
def mounted(*args: str):
    target = args[-1]
    subprocess.run(["mount", *args], check=True)
    try:
        yield Path(target)
    finally:
        subprocess.run(["umount", "-l", target], check=True)


def local_client(settings) -> TestClient:
    return TestClient(create_app(settings), base_url="http://localhost", client=("127.0.0.1", 5000))


def fill(folder: Path) -> Path:
    """Fill the file system of ``folder`` to the last byte."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError:
        pass
    finally:
        os.close(fd)
    return filler


def test_issue_10_full_disk_is_507_and_readiness_says_so(tmp_path):
    disk = tmp_path / "disk"
    disk.mkdir()
    with mounted("-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)):
        settings = make_settings(disk / "ccsm.sqlite", [], serve_sample=False, max_upload_mb=0.25)
        with local_client(settings) as c:
            assert c.get("/readyz").status_code == 200
            filler = fill(disk)
            r = c.post("/datasets?id=full", content=BODY, headers=GEOJSON)
            assert r.status_code == 507, r.text
            assert "No space left" in r.json()["detail"]
            assert [p.name for p in (disk / "uploads").iterdir()] == []  # no 0-byte upload file
            ready = c.get("/readyz")
            assert ready.status_code == 503
            text = " ".join(ready.json()["problems"])
            assert "disk is full" in text or "free" in text, text
            wal = disk / "ccsm.sqlite-wal"
            assert not wal.exists() or wal.stat().st_size < 64 * 1024  # the WAL does not keep the disk full
            filler.unlink()
            assert c.get("/readyz").status_code == 200
            ok = c.post("/datasets?id=full", content=BODY, headers=GEOJSON)
            assert ok.status_code == 202, ok.text
            c.app.state.service.wait_for_builds(120)
            assert c.get("/datasets/full").json()["state"] == "ready"


def test_issue_10_read_only_upload_folder_is_507_and_readiness_says_so(tmp_path):
    settings = make_settings(tmp_path / "ccsm.sqlite", [], serve_sample=False)
    (tmp_path / "uploads").mkdir()
    (tmp_path / "uploads-src").mkdir()
    read_only_uploads = mounted("--bind", "-o", "ro", str(tmp_path / "uploads-src"), str(tmp_path / "uploads"))
    with local_client(settings) as c, read_only_uploads:
        r = c.post("/datasets?id=ro", content=BODY, headers=GEOJSON)
        assert r.status_code == 507, r.text
        assert "Read-only" in r.json()["detail"]
        ready = c.get("/readyz")
        assert ready.status_code == 503 and "read-only" in " ".join(ready.json()["problems"])
        assert c.get("/datasets/ro").status_code == 404  # nothing reserved
        assert c.get("/datasets").status_code == 200  # reads go on


def test_issue_10_read_only_store_is_reported_with_what_to_do(tmp_path, built_store):
    src = tmp_path / "rw"
    src.mkdir()
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    (src / "ccsm.sqlite").write_bytes(built_store.read_bytes())
    view = tmp_path / "view"
    view.mkdir()
    with mounted("--bind", "-o", "ro", str(src), str(view)):
        with local_client(make_settings(view / "ccsm.sqlite", [], serve_sample=False)) as c:
            ready = c.get("/readyz")
            assert ready.status_code == 503, ready.text
            assert "read-only file system" in ready.json()["problems"][0]
            r = c.post("/datasets?id=ro", content=BODY, headers=GEOJSON)
            assert r.status_code == 503 and "writable" in r.json()["detail"], r.text


def _damaged_copy(built_store: Path, dest: Path, how: str) -> Path:
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = bytearray(built_store.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 3]
    else:  # flipped bytes in the contour pages only: the file still opens and its metadata reads fine
        for i in range(len(data) // 2, len(data), 997):
            data[i] ^= 0xFF
    dest.write_bytes(bytes(data))
    return dest


def test_issue_10_damaged_store_is_reported_not_served(tmp_path, built_store):
    for how in ("flipped", "truncated"):
        store = _damaged_copy(built_store, tmp_path / f"{how}.sqlite", how)
        with local_client(make_settings(store, [], serve_sample=False)) as c:
            ready = c.get("/readyz")
            assert ready.status_code == 503, (how, ready.text)
            problem = ready.json()["problems"][0]
            assert "move" in problem and store.name in problem, problem
            data = c.get("/datasets")
            assert data.status_code == 503 and "move" in data.json()["detail"], data.text
            # Liveness is not readiness (README, docs/service.md): the process runs, so /healthz says so.
            live = c.get("/healthz")
            assert (live.status_code, live.json()) == (200, {"status": "ok"}), (how, live.text)


def test_issue_10_serve_refuses_a_truncated_store_with_exit_2(tmp_path, built_store):
    store = _damaged_copy(built_store, tmp_path / "cut.sqlite", "truncated")
    out = subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", "serve", "--store", str(store), "--port", "1"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2, out
    assert "cut.sqlite" in out.stderr and "move" in out.stderr
    assert "Traceback" not in out.stderr + out.stdout


def test_issue_10_upload_files_of_killed_builds_are_removed_at_start(tmp_path, built_store, synthetic_path):
    store = tmp_path / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    uploads = tmp_path / "uploads"
    uploads.mkdir()
    stale = [uploads / "gone-0123abcd.geojson", uploads / ".incoming-999999999-0123abcd.geojson"]
    for p in stale:
        p.write_text(BODY)
    with local_client(make_settings(store, [synthetic_path])) as c:
        assert c.get("/datasets/hills").status_code == 200
        assert [p for p in stale if p.exists()] == []


def _descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = (task / "children").read_text().split()
            except OSError:
                continue
            for k in map(int, kids):
                if k not in out:
                    out.add(k)
                    todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_issue_10_stopping_the_server_mid_build_ends_the_builds(tmp_path):
    # The bundled sample builds for a while with one process per core: stop the server meanwhile.
    server = LiveServer({"CCSM_STORE_PATH": str(tmp_path / "ccsm.sqlite")}, log=tmp_path / "server.log")
    try:
        server.wait_healthy()
        deadline = time.monotonic() + 60
        kids: set[int] = set()
        while time.monotonic() < deadline and len(kids) < 2:  # the build process and its workers
            kids = _descendants(server.proc.pid)
            time.sleep(0.2)
        assert kids, "no build process started"
        assert httpx.get(server.url + "/datasets/sample").json()["state"] == "building"
        server.proc.send_signal(signal.SIGTERM)
        assert server.proc.wait(30) is not None
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and any(_alive(k) for k in kids):
            time.sleep(0.2)
        assert not [k for k in kids if _alive(k)], Path(tmp_path / "server.log").read_text()[-2000:]
        with socket.socket() as s:  # nothing holds the port any more
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(("127.0.0.1", server.port))
    finally:
        server.stop()

"""Connection limits (issue 28, item 3) against a real server on loopback: the head timeout closes a slowloris
socket, the read timeout a stalled body, and the per-client cap refuses one connection too many from an
address while another address and ``/healthz`` are still served.

The server runs with short limits (1 s, 1 s, 4 connections) so the tests stay short.
"""

from __future__ import annotations

import http.client
import json
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from engine.store.store import CCSStore
from tests.app.conftest import LiveServer

HEADER_TIMEOUT_S = 1.0
READ_TIMEOUT_S = 1.0
CAP = 4
#: A socket still open this long after its timeout was not closed by it (room for a loaded 2-core machine).
GRACE_S = 3.0


@pytest.fixture(scope="module")
def limited(tmp_path_factory: pytest.TempPathFactory, built_store: Path) -> Iterator[LiveServer]:
    """A server with short connection limits on a copy of the synthetic store (nothing built at start)."""
    d = tmp_path_factory.mktemp("limited")
    store = d / "ccsm.sqlite"
    CCSStore(built_store)._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.write_bytes(built_store.read_bytes())
    env = {
        "CCSM_STORE_PATH": str(store),
        "CCSM_SERVE_SAMPLE": "false",
        "CCSM_BUILD_ON_START": "false",
        "CCSM_RENDER_WORKERS": "1",
        "CCSM_HEADER_TIMEOUT_S": str(HEADER_TIMEOUT_S),
        "CCSM_READ_TIMEOUT_S": str(READ_TIMEOUT_S),
        "CCSM_MAX_CONNECTIONS_PER_CLIENT": str(CAP),
    }
    server = LiveServer(env, log=d / "server.log")
    try:
        server.wait_healthy()
        yield server
    finally:
        server.stop()


def _open(server: LiveServer, source: str = "127.0.0.1") -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=0.2, source_address=(source, 0))
    return sock


def _closed_by_server(sock: socket.socket) -> bool:
    """True once the server has closed the socket (EOF or reset); False while it is open and quiet."""
    try:
        return sock.recv(4096) == b""
    except TimeoutError:
        return False
    except ConnectionError:
        return True


def _trickle_until_closed(sock: socket.socket, pieces: Iterator[bytes], limit_s: float) -> float | None:
    """Send a piece every 0.3 s until the server closes the socket; seconds until then (None: never)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        try:
            sock.sendall(next(pieces))
        except (BrokenPipeError, ConnectionResetError):
            return time.monotonic() - t0
        if _closed_by_server(sock):
            return time.monotonic() - t0
        time.sleep(0.1)
    return None


def _header_lines() -> Iterator[bytes]:
    yield b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n"
    n = 0
    while True:
        n += 1
        yield f"X-Slow-{n}: a\r\n".encode()


def test_slowloris_head_is_closed_after_the_header_timeout(limited: LiveServer) -> None:
    with _open(limited) as sock:
        closed_after = _trickle_until_closed(sock, _header_lines(), HEADER_TIMEOUT_S + GRACE_S)
    assert closed_after is not None, "a head trickled a line at a time was never closed"
    assert closed_after >= HEADER_TIMEOUT_S * 0.8


def test_a_silent_connection_is_closed_after_the_header_timeout(limited: LiveServer) -> None:
    with _open(limited) as sock:
        t0 = time.monotonic()
        while not _closed_by_server(sock):
            assert time.monotonic() - t0 < HEADER_TIMEOUT_S + GRACE_S, "a connection sending nothing stayed open"


def _upload_head(server: LiveServer, length: int) -> bytes:
    return (
        f"POST /datasets?id=slow HTTP/1.1\r\nHost: localhost:{server.port}\r\n"
        f"Content-Type: application/geo+json\r\nContent-Length: {length}\r\n\r\n"
    ).encode()


def test_a_stalled_body_is_closed_after_the_read_timeout(limited: LiveServer) -> None:
    with _open(limited) as sock:
        sock.sendall(_upload_head(limited, 1000) + b'{"type": ')
        t0 = time.monotonic()
        while not _closed_by_server(sock):
            assert time.monotonic() - t0 < READ_TIMEOUT_S + GRACE_S, "a body that stopped sending stayed open"


def test_a_slow_but_steady_body_is_read_to_the_end(limited: LiveServer) -> None:
    """The read timeout is for a body that stalls, not for one that takes longer than it in all."""
    body = json.dumps({"type": "FeatureCollection", "features": []}).encode()
    with _open(limited) as sock:
        sock.sendall(_upload_head(limited, len(body)))
        for i in range(0, len(body), len(body) // 5 + 1):  # 6 pieces, 0.4 s apart: 2 s in all
            time.sleep(0.4)
            sock.sendall(body[i : i + len(body) // 5 + 1])
        sock.settimeout(10)
        answer = sock.recv(4096)
    assert answer.startswith(b"HTTP/1.1 4"), answer[:80]  # the upload was read and judged (an empty set: 4xx)


def _get(conn: http.client.HTTPConnection, path: str) -> tuple[int, dict[str, str], bytes]:
    conn.request("GET", path)
    r = conn.getresponse()
    return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()


def _client(server: LiveServer, source: str = "127.0.0.1") -> http.client.HTTPConnection:
    return http.client.HTTPConnection("127.0.0.1", server.port, timeout=10, source_address=(source, 0))


def test_one_connection_over_the_cap_is_refused_and_healthz_still_answers(limited: LiveServer) -> None:
    held = [_client(limited) for _ in range(CAP)]
    try:
        for conn in held:  # kept alive (uvicorn closes them after 5 s idle: the rest takes well under that)
            assert _get(conn, "/datasets")[0] == 200
        over = _client(limited)
        status, headers, body = _get(over, "/datasets")
        assert status == 503
        assert json.loads(body)["error"] == "too_many_connections"
        assert headers["retry-after"] and headers["connection"] == "close"
        over.close()
        health = _client(limited)
        status, headers, body = _get(health, "/healthz")
        assert status == 200 and json.loads(body)["status"] == "ok"
        assert headers["connection"] == "close"  # one answer per connection over the cap
        health.close()
        other = _client(limited, source="127.0.0.2")  # another address has its own count
        assert _get(other, "/datasets")[0] == 200
        other.close()
        held.pop().close()  # a slot freed: the next connection from the busy address is served
        time.sleep(0.2)
        again = _client(limited)
        assert _get(again, "/datasets")[0] == 200
        again.close()
    finally:
        for conn in held:
            conn.close()

"""A local HTTP file server for the terrain source tests: answers ``Range: bytes=a-b`` with 206, counts the
requests and the body bytes it sends, and binds 127.0.0.1 only (a real server, as a tile host or a COG bucket)."""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

RANGE = re.compile(r"^bytes=(\d+)-(\d*)$")


@dataclass
class Served:
    """The running server's base URL and what it answered."""

    url: str
    requests: list[tuple[str, int, int]] = field(default_factory=list)  # (path, status, body bytes)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def bytes_for(self, suffix: str) -> int:
        with self.lock:
            return sum(n for path, _, n in self.requests if path.endswith(suffix))

    def count(self, suffix: str = "") -> int:
        with self.lock:
            return sum(1 for path, _, _ in self.requests if path.endswith(suffix))


@contextmanager
def serve_folder(root: Path) -> Iterator[Served]:
    """Serve the files under ``root`` on a free port of 127.0.0.1, in a thread."""
    served = Served(url="")
    root = root.resolve()

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, format: str, *args: object) -> None:  # noqa: A002  (quiet)
            pass

        def do_HEAD(self) -> None:  # noqa: N802
            self._answer(body=False)

        def do_GET(self) -> None:  # noqa: N802
            self._answer(body=True)

        def _answer(self, body: bool) -> None:
            path = self.path.split("?")[0]
            target = (root / path.lstrip("/")).resolve()
            if root not in target.parents or not target.is_file():
                with served.lock:
                    served.requests.append((path, 404, 0))
                self.send_error(404)
                return
            size = target.stat().st_size
            m = RANGE.match(self.headers.get("Range", "").strip())
            start, end, status = 0, size - 1, 200
            if m:
                start, status = int(m.group(1)), 206
                end = min(int(m.group(2)), size - 1) if m.group(2) else size - 1
            n = max(0, end - start + 1)
            with served.lock:
                served.requests.append((path, status, n if body else 0))
            self.send_response(status)
            self.send_header("Content-Type", "application/octet-stream")
            self.send_header("Accept-Ranges", "bytes")
            self.send_header("Content-Length", str(n))
            if status == 206:
                self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
            self.end_headers()
            if body and n:
                with target.open("rb") as fh:
                    fh.seek(start)
                    self.wfile.write(fh.read(n))

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    httpd.daemon_threads = True
    served.url = f"http://127.0.0.1:{httpd.server_address[1]}"
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield served
    finally:
        httpd.shutdown()
        httpd.server_close()

"""A local HTTP file server that answers Range requests, as any static host or bucket does, for the terrain source
tests and the browser tests.

Python's ``http.server`` ignores ``Range``; PMTiles and COG readers need it. This one serves files from a few
mounted folders (URL prefix -> folder), answers ``Range: bytes=a-b``, ``bytes=a-`` and ``bytes=-n`` with
206 and ``Content-Range`` (one range per request), 416 for a range past the end, and logs every request
(path, range, status and body bytes) so a test can count them. It binds 127.0.0.1 only.
"""

from __future__ import annotations

import mimetypes
import re
import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote

RANGE = re.compile(r"^bytes=(\d*)-(\d*)$")
TYPES = {".js": "text/javascript", ".mjs": "text/javascript", ".pmtiles": "application/octet-stream"}


@dataclass
class RangeServer:
    """A running server: its base URL and the requests it answered."""

    url: str
    #: (path, Range header, status) of each request, in order.
    log: list[tuple[str, str | None, int]] = field(default_factory=list)
    #: Body bytes sent for each request of ``log``.
    sent: list[int] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def answered(self, path: str, header: str | None, status: int, body_bytes: int = 0) -> None:
        with self.lock:
            self.log.append((path, header, status))
            self.sent.append(body_bytes)

    def requests_for(self, suffix: str) -> list[tuple[str, str | None, int]]:
        with self.lock:
            return [r for r in self.log if r[0].split("?")[0].endswith(suffix)]

    def count(self, suffix: str = "") -> int:
        return len(self.requests_for(suffix))

    def bytes_for(self, suffix: str) -> int:
        with self.lock:
            return sum(
                n for (path, _, _), n in zip(self.log, self.sent, strict=True) if path.split("?")[0].endswith(suffix)
            )


def parse_range(header: str | None, size: int) -> tuple[int, int] | None | str:
    """(start, end inclusive) of a single byte range, None without a (usable) Range header, "unsatisfiable"
    for a range that starts past the end."""
    if not header:
        return None
    m = RANGE.match(header.strip())
    if not m or (not m.group(1) and not m.group(2)):
        return None
    first, last = m.group(1), m.group(2)
    if not first:  # the last n bytes
        n = int(last)
        return (max(0, size - n), size - 1) if n else "unsatisfiable"
    start = int(first)
    if start >= size:
        return "unsatisfiable"
    end = min(int(last), size - 1) if last else size - 1
    return None if end < start else (start, end)


def resolve(mounts: dict[str, Path], url_path: str) -> Path | None:
    """The file a URL path names under the longest matching mount, or None (nothing outside the folders)."""
    path = unquote(url_path.split("?")[0])  # as any static host: "%20" names a space
    for prefix in sorted(mounts, key=len, reverse=True):
        if path.startswith(prefix):
            root = mounts[prefix].resolve()
            target = (root / (path[len(prefix) :] or "index.html")).resolve()
            if target.is_dir():
                target = target / "index.html"
            if root in target.parents and target.is_file():
                return target
            return None
    return None


def _handler(mounts: dict[str, Path], server: RangeServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, format: str, *args: object) -> None:  # noqa: A002  (quiet)
            pass

        def do_HEAD(self) -> None:  # noqa: N802
            self._serve(body=False)

        def do_GET(self) -> None:  # noqa: N802
            self._serve(body=True)

        def _serve(self, body: bool) -> None:
            target = resolve(mounts, self.path)
            header = self.headers.get("Range")
            if target is None:
                server.answered(self.path, header, 404)
                self.send_error(404)
                return
            size = target.stat().st_size
            rng = parse_range(header, size)
            ctype = TYPES.get(target.suffix) or mimetypes.guess_type(target.name)[0] or "application/octet-stream"
            if rng == "unsatisfiable":
                server.answered(self.path, header, 416)
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{size}")
                self.send_header("Content-Length", "0")
                self.end_headers()
                return
            start, end = rng if isinstance(rng, tuple) else (0, size - 1)
            status = 206 if isinstance(rng, tuple) else 200
            server.answered(self.path, header, status, end - start + 1 if body and size else 0)
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Accept-Ranges", "bytes")
            self.send_header("Content-Length", str(end - start + 1))
            self.send_header("Cache-Control", "no-cache")
            if status == 206:
                self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
            self.end_headers()
            if body and size:
                with target.open("rb") as f:
                    f.seek(start)
                    self.wfile.write(f.read(end - start + 1))

    return Handler


@contextmanager
def serve_static(mounts: dict[str, Path]) -> Iterator[RangeServer]:
    """Serve ``mounts`` ({"/prefix/": folder}) on 127.0.0.1 on a free port, in a thread."""
    state = RangeServer(url="")
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _handler(mounts, state))
    httpd.daemon_threads = True
    state.url = f"http://127.0.0.1:{httpd.server_address[1]}"
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield state
    finally:
        httpd.shutdown()
        httpd.server_close()


def serve_folder(root: Path) -> AbstractContextManager[RangeServer]:
    """Serve the files under ``root`` on a free port of 127.0.0.1, in a thread (a tile host or a COG bucket)."""
    return serve_static({"/": root})

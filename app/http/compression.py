"""gzip of response bodies, shared by the routes and the render workers (no web framework here: the workers
import it).

The render workers compress what they draw (tiles, ``/simplify``'s GeoJSON) when the client accepts gzip, so
the server's event loop never spends milliseconds per MB compressing a body (docs/service.md, "Under load").
"""

from __future__ import annotations

import gzip

#: gzip level: 1 costs about 2.5x less time than 5 on 100-150 KB tiles for bodies about 4 % larger; tiles are
#: rendered per request, so the CPU is the scarce resource, not the bytes.
GZIP_LEVEL = 1
#: Bodies smaller than this are not worth compressing.
GZIP_MIN_BYTES = 512


def worth_compressing(body: bytes) -> bool:
    """True when a body is large enough for gzip to pay."""
    return len(body) >= GZIP_MIN_BYTES


def gzip_body(body: bytes) -> bytes:
    """``body`` gzipped (deterministic: no timestamp, so equal bodies give equal bytes)."""
    return gzip.compress(body, GZIP_LEVEL, mtime=0)

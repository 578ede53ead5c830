"""The base URL written into TileJSON tile URLs, never taken from the request's ``Host`` header.

A ``Host`` header is whatever the client sends: copied into TileJSON, it would let anyone make the service
(and any cache in front of it) hand out tile URLs pointing elsewhere. So the base comes from, in order:
``CCSM_PUBLIC_URL``; the ``X-Forwarded-Proto``/``X-Forwarded-Host`` headers when
``CCSM_TRUST_FORWARDED_HEADERS`` says a trusted proxy sets them; else the address the server listens on.
"""

from __future__ import annotations

import re

from starlette.requests import Request

from app.settings import Settings

#: A host[:port] as a proxy may forward it (no path, user info or spaces).
_HOST = re.compile(r"^[A-Za-z0-9.-]+(:[0-9]{1,5})?$|^\[[0-9A-Fa-f:.]+\](:[0-9]{1,5})?$")


def public_base_url(request: Request, settings: Settings) -> str:
    """The service's base URL for links in responses, without a trailing slash."""
    if settings.public_url:
        return settings.public_url.rstrip("/")
    if settings.trust_forwarded_headers:
        host = request.headers.get("x-forwarded-host", "").split(",")[0].strip()
        proto = request.headers.get("x-forwarded-proto", "").split(",")[0].strip().lower()
        if host and _HOST.match(host):
            return f"{proto if proto in ('http', 'https') else 'http'}://{host}"
    # The socket the request came in on. Plain http: `ccsm serve` does not terminate TLS, and the request's
    # scheme may have been rewritten from an X-Forwarded-Proto header, which is not trusted here.
    server = request.scope.get("server")
    if server and server[0]:
        host, port = server[0], server[1]
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}" if port in (80, None) else f"http://{host}:{port}"
    return ""

"""Who may write (POST/DELETE /datasets), and in what form (docs/service.md, "Security model").

- With ``CCSM_ADMIN_TOKEN`` set, a write needs ``Authorization: Bearer <token>`` (401 otherwise).
- Without it, writes are taken only from a loopback client that addresses the server by a loopback name
  (``localhost``, ``127.0.0.1``, ``[::1]``); anything else gets 403. The Host check stops a web page that
  re-points its own domain name at 127.0.0.1 (DNS rebinding) from writing as if it were local.
- A body must be ``application/json`` or ``application/geo+json`` (415 otherwise): a browser sends those
  cross-site only after a CORS preflight, which this service never grants to writes, so no other web page
  can make a visitor's browser write, token or not.
"""

from __future__ import annotations

import hmac
import ipaddress
import re
from typing import Annotated

from fastapi import Depends, Request

from app.errors import NotAuthenticated, UnsupportedMediaType, WriteForbidden
from app.routes.dependencies import get_settings
from app.settings import Settings

#: Media types a write body may have (neither can be sent cross-site without a preflight).
JSON_TYPES = frozenset({"application/json", "application/geo+json"})
#: Host names a tokenless local write may address the server by.
LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "[::1]"})


def _is_loopback(host: str | None) -> bool:
    if not host:
        return False
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


#: ``Host`` as RFC 9110 writes it: a bracketed IPv6 literal or a name / IPv4 address, then an optional port.
_HOST_HEADER = re.compile(r"(?:\[(?P<ipv6>[0-9a-f:.]+)\]|(?P<name>[a-z0-9.-]+))(?::(?P<port>[0-9]{1,5}))?")


def host_name(header: str) -> str | None:
    """The host a ``Host`` header names, or None when the header is not one well-formed host[:port].

    The whole value must match (no trailing junk such as ``[::1]evil.com``); an IPv6 literal is normalised
    (``[0:0:0:0:0:0:0:1]`` -> ``[::1]``).

    >>> host_name("[::1]:8000"), host_name("LOCALHOST"), host_name("[::1]evil.com")
    ('[::1]', 'localhost', None)
    """
    match = _HOST_HEADER.fullmatch(header.strip().lower())
    if match is None or (match["port"] is not None and int(match["port"]) > 65535):
        return None
    if match["ipv6"] is None:
        return match["name"]
    try:
        return f"[{ipaddress.IPv6Address(match['ipv6']).compressed}]"
    except ValueError:
        return None


def require_writer(request: Request, settings: Annotated[Settings, Depends(get_settings)]) -> None:
    """Allow the write or raise NotAuthenticated (401) / WriteForbidden (403), with the reason."""
    token = settings.admin_token.get_secret_value() if settings.admin_token else ""
    if token:
        scheme, _, given = request.headers.get("authorization", "").partition(" ")
        if scheme.lower() != "bearer" or not given:
            raise NotAuthenticated("this write needs the header 'Authorization: Bearer <CCSM_ADMIN_TOKEN>'")
        if not hmac.compare_digest(given.strip().encode(), token.encode()):
            raise NotAuthenticated("the bearer token is not CCSM_ADMIN_TOKEN")
        return
    client = request.client.host if request.client else None
    if not _is_loopback(client):
        raise WriteForbidden(
            "writes are off for remote clients: set CCSM_ADMIN_TOKEN on the server and send it as a bearer token"
        )
    if host_name(request.headers.get("host", "")) not in LOOPBACK_NAMES:
        raise WriteForbidden(
            "without CCSM_ADMIN_TOKEN, writes must address the server as localhost, 127.0.0.1 or [::1]"
        )


def require_json_body(request: Request) -> None:
    """Refuse (415) a body that is not JSON: form posts and text/plain are sent cross-site without a preflight."""
    media = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if media in JSON_TYPES:
        return
    hint = (
        " (a multipart form is not taken: send the file itself as the body, "
        "curl --data-binary @contours.geojson -H 'Content-Type: application/geo+json')"
        if media.startswith("multipart/")
        else ""
    )
    raise UnsupportedMediaType(
        f"Content-Type {media or '(none)'!r} is not accepted; send application/geo+json or application/json{hint}"
    )


Writer = Annotated[None, Depends(require_writer)]
JsonBody = Annotated[None, Depends(require_json_body)]

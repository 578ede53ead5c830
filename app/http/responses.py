"""Response helpers: ETags, conditional requests, gzip."""

from __future__ import annotations

import hashlib

from fastapi import Request, Response

from app.http.compression import gzip_body, worth_compressing


def make_etag(*parts: object) -> str:
    """A strong ETag from the values that decide a response."""
    return '"' + hashlib.blake2b("|".join(map(str, parts)).encode(), digest_size=12).hexdigest() + '"'


def etag_matches(request: Request, etag: str) -> bool:
    """True when If-None-Match names ``etag`` (or ``*``), weak or strong (RFC 9110 weak comparison)."""
    header = request.headers.get("if-none-match")
    if not header:
        return False
    tags = [t.strip() for t in header.split(",")]
    return "*" in tags or etag in tags or f"W/{etag}" in tags


def accepts_gzip(request: Request) -> bool:
    """True when the client accepts gzip."""
    return "gzip" in request.headers.get("accept-encoding", "").lower()


def body_response(
    request: Request,
    body: bytes,
    media_type: str,
    headers: dict[str, str],
    status_code: int = 200,
    *,
    gzipped: bool = False,
) -> Response:
    """A response with ``body``, gzipped when the client accepts it and it is large enough (``gzipped``: the
    render worker compressed it already, off the event loop)."""
    headers = dict(headers)
    headers["Vary"] = "Accept-Encoding"
    if gzipped:
        headers["Content-Encoding"] = "gzip"
    elif worth_compressing(body) and accepts_gzip(request):
        body = gzip_body(body)
        headers["Content-Encoding"] = "gzip"
    return Response(body, status_code=status_code, media_type=media_type, headers=headers)

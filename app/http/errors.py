"""Domain errors -> HTTP status codes, in one table; JSON error bodies that never leak internals.

The errors themselves are the engine's (:mod:`engine.errors`) and the service's (:mod:`app.errors`).

Every error answer is ``{"error": <kind>, "detail": <what is wrong>, "request_id": <id>}``. Messages pass
through :func:`public_message`, which reduces any file path to its base name. Anything unexpected is a 500
whose body says only that, with the request id; the traceback goes to the log.
"""

from __future__ import annotations

import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import (
    BuildQueueFull,
    ClientGone,
    ContourTooLong,
    DatasetExists,
    MalformedUpload,
    NotAuthenticated,
    UnsupportedMediaType,
    UploadCheckFailed,
    UploadTooLarge,
    WriteForbidden,
)
from engine.errors import (
    CCSMError,
    InvalidContour,
    InvalidParameter,
    SourceError,
    StoreBusy,
    StoreError,
    StoreNotReady,
    StoreUnwritable,
    SurfaceFitError,
    TileOutOfRange,
    UnknownLayer,
)

log = logging.getLogger("ccsm.app")


#: The one table: engine (and app) error class -> HTTP status. The first matching class in MRO order wins.
STATUS_CODES: dict[type[Exception], int] = {
    TileOutOfRange: 404,
    UnknownLayer: 404,
    InvalidParameter: 400,
    InvalidContour: 400,
    SourceError: 400,
    MalformedUpload: 400,
    NotAuthenticated: 401,
    WriteForbidden: 403,
    DatasetExists: 409,
    UploadTooLarge: 413,
    ContourTooLong: 413,  # a contour too long to build in seconds
    UnsupportedMediaType: 415,
    BuildQueueFull: 429,
    StoreUnwritable: 507,
    UploadCheckFailed: 503,
    ClientGone: 499,  # nobody reads it: the status a proxy logs for a request its client closed
    SurfaceFitError: 422,
    StoreNotReady: 503,
    StoreBusy: 503,  # another write holds the store: nothing done, Retry-After
    StoreError: 503,
    CCSMError: 400,
}

_PATH = re.compile(r"(?<![\w:/])(?:/[^\s/'\"`,;()<>]+)+/([^\s/'\"`,;()<>]+)")


def public_message(message: str) -> str:
    """An error message fit for a client: file paths cut to their base names, length bounded.

    >>> public_message("/tmp/x/upload.geojson: cannot read contours")
    'upload.geojson: cannot read contours'
    """
    return _PATH.sub(lambda m: m.group(1), message)[:1000]


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def log_safe(text: object) -> str:
    """Text from a request made safe for one log line: control characters (newlines, ANSI escapes) escaped.

    >>> log_safe("a\nb\x1b[31m")
    'a\\nb\\x1b[31m'
    """
    return _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(text))


#: Extra headers of some answers: when to retry, how to authenticate.
_HEADERS = {
    503: {"Retry-After": "5"},
    429: {"Retry-After": "30"},
    401: {"WWW-Authenticate": 'Bearer realm="ccsm"'},
}


def request_id(request: Request) -> str:
    """The id the request-id middleware gave this request."""
    return str(request.scope.get("state", {}).get("request_id", "-"))


def error_body(request: Request, kind: str, detail: Any) -> dict[str, Any]:
    """The JSON body of every error answer."""
    return {"error": kind, "detail": detail, "request_id": request_id(request)}


def status_for(exc: Exception) -> int:
    """HTTP status of an engine error (500 for anything not in the table)."""
    for cls in type(exc).__mro__:
        if cls in STATUS_CODES:
            return STATUS_CODES[cls]
    return 500


def _kind(exc: Exception) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", type(exc).__name__).lower()


#: The engine's parameter names as the HTTP API takes them (the upload's query parameters), with what to give.
HTTP_PARAMETERS: dict[str, str] = {
    "interval": "give the query parameter interval (the contour interval, in the DEM's vertical unit)",
    "elevation_field": "give the query parameter elevation_field",
}


def http_message(exc: Exception) -> str:
    """An error's message, and which query parameter to give when it is about one (``CCSMError.parameter``)."""
    hint = HTTP_PARAMETERS.get(getattr(exc, "parameter", None) or "")
    return f"{exc}; {hint}" if hint else str(exc)


async def ccsm_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """Domain errors: the status from the table, the message (paths cut) as detail."""
    status = status_for(exc)
    if status >= 500 and not isinstance(exc, (StoreNotReady, StoreError, UploadCheckFailed)):
        log.exception("request %s failed", request_id(request), exc_info=exc)
    elif status == 507:
        log.error("%s %s -> 507 %s", request.method, log_safe(request.url.path), log_safe(exc))
    else:
        log.info("%s %s -> %d %s", request.method, log_safe(request.url.path), status, log_safe(exc))
    headers = _HEADERS.get(status)
    return JSONResponse(error_body(request, _kind(exc), public_message(http_message(exc))), status, headers=headers)


async def validation_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """422 with the list of bad parameters (location, message), without echoing internals."""
    errors = exc.errors() if isinstance(exc, RequestValidationError) else []
    detail = [
        {
            "loc": [str(p) for p in e.get("loc", ())],
            "msg": public_message(str(e.get("msg", ""))),
            "type": e.get("type"),
        }
        for e in errors
    ]
    return JSONResponse(error_body(request, "invalid_request", detail), 422)


async def http_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """Starlette's own HTTP errors (unknown route, wrong method) as JSON."""
    status = getattr(exc, "status_code", 500)
    detail = getattr(exc, "detail", "error")
    headers = getattr(exc, "headers", None)
    return JSONResponse(
        error_body(request, "http_error", public_message(str(detail))), status, headers=headers
    )


async def unexpected_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """Anything else: 500, a generic message and the request id; the traceback only in the log."""
    log.error("request %s %s %s failed", request_id(request), request.method, request.url.path, exc_info=exc)
    # This handler runs outside the request-id middleware (in Starlette's ServerErrorMiddleware): set it here.
    rid = request_id(request)
    return JSONResponse(
        error_body(request, "internal_error", "internal server error"), 500, headers={"X-Request-ID": rid}
    )


def add_exception_handlers(app: FastAPI) -> None:
    """Register every handler on an app."""
    app.add_exception_handler(CCSMError, ccsm_error_handler)
    app.add_exception_handler(RequestValidationError, validation_error_handler)
    app.add_exception_handler(StarletteHTTPException, http_error_handler)
    app.add_exception_handler(Exception, unexpected_error_handler)

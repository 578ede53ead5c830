"""CORS for the read routes, with the refusal of a preflight in the service's JSON error form.

Starlette's middleware answers a refused preflight with plain text ("Disallowed CORS origin"); every other error
of the service is ``{"error", "detail", "request_id"}`` JSON, so a client parses one form only.
"""

from __future__ import annotations

from fastapi.middleware.cors import CORSMiddleware
from starlette.datastructures import Headers
from starlette.requests import Request
from starlette.responses import JSONResponse
from starlette.types import Receive, Scope, Send

from app.http.errors import error_body


class JsonCORSMiddleware(CORSMiddleware):
    """Starlette's CORS middleware whose refused preflights (400) carry a JSON error body."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Answer a refused preflight here; everything else as Starlette does."""
        if scope["type"] != "http" or scope["method"] != "OPTIONS":
            await super().__call__(scope, receive, send)
            return
        headers = Headers(scope=scope)
        is_preflight = "origin" in headers and "access-control-request-method" in headers
        if is_preflight:
            answer = self.preflight_response(request_headers=headers)
            if answer.status_code == 400:
                reason = bytes(answer.body).decode("utf-8", "replace")  # "Disallowed CORS origin, method"
                cors = {k: v for k, v in answer.headers.items() if k.lower().startswith("access-control-")}
                body = error_body(Request(scope), "cors_preflight_refused", reason)
                await JSONResponse(body, 400, headers={**cors, "Vary": "Origin"})(scope, receive, send)
                return
        await super().__call__(scope, receive, send)

"""HEAD on every GET route: the same status and headers as GET, no body (RFC 9110 section 9.3.2).

FastAPI routes declared with ``@router.get`` answer HEAD with 405. Rather than declare HEAD on each route
(which doubles every operation in the OpenAPI document), this middleware runs a HEAD request as GET and
drops the body it produces; ``Content-Length`` stays that of the GET answer.
"""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send


class HeadAsGetMiddleware:
    """Answer HEAD like GET, without the body."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Run HEAD as GET; forward only the response start and an empty end of body."""
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return
        ended = False

        async def send_headers_only(message: Message) -> None:
            nonlocal ended
            if message["type"] == "http.response.start":
                await send(message)
            elif message["type"] == "http.response.body" and not message.get("more_body", False):
                if not ended:
                    ended = True
                    await send({"type": "http.response.body", "body": b"", "more_body": False})

        await self.app({**scope, "method": "GET"}, receive, send_headers_only)

"""Connection limits the server enforces before a request reaches the app (docs/service.md, "Connections").

uvicorn closes an idle kept-alive connection, but nothing else: a connection that never finishes its request
head (slowloris: a header byte every few seconds) or stops sending its body stays open for ever, and one
client may open as many as it likes. :class:`LimitedHttpToolsProtocol` is uvicorn's httptools protocol
(what ``uvicorn[standard]`` runs) with three bounds, all settings:

- ``header_timeout_s``: a request head must be complete within that many seconds of the connection opening,
  or of its first byte on a kept-alive connection; else the connection is closed.
- ``read_timeout_s``: a request body that sends nothing for that long is dropped (the handler sees the
  client gone). Time the server itself holds the body back (flow control, or before ``100 Continue``) does
  not count.
- ``max_connections_per_client``: open connections per client address, per server process. One more
  connection is answered, once its head arrives (within :data:`REFUSED_HEAD_TIMEOUT_S`), with 503
  ``too_many_connections`` and ``Retry-After``, held back :data:`REFUSAL_DELAY_S`, and closed. ``GET
  /healthz`` is answered on it at once, so a health check from a busy address (loopback) keeps working.

The protocol is named by import path (``uvicorn.run(http=HTTP_PROTOCOL)``), so each ``--workers`` process
imports it and reads the limits from its own environment.
"""

from __future__ import annotations

import asyncio
import json
from collections import Counter
from dataclasses import dataclass
from functools import cache

from uvicorn._types import ASGIReceiveCallable, ASGISendCallable, Scope
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

#: What ``ccsm serve`` passes to ``uvicorn.run(http=...)``.
HTTP_PROTOCOL = "app.http.connection_limits:LimitedHttpToolsProtocol"
#: Seconds a connection over the per-client cap may take to send its head before it is closed without an
#: answer: an honest client sends its head right after connecting, and a refused one must not hold a socket.
REFUSED_HEAD_TIMEOUT_S = 1.0
#: Seconds a refused client is told to wait.
RETRY_AFTER_S = 5
#: Seconds the refusal is held back at most (and at most ``header_timeout_s``): a client that reconnects at
#: once, not waiting Retry-After, would otherwise keep the server accepting and refusing connections in a
#: loop, and every new connection, a health check's too, would queue behind them (at 200 connections from one
#: address: /healthz on a new connection up to 1.2-1.7 s answered at once, 0.75 s held 1 s, 38 ms held 5 s).
REFUSAL_DELAY_S = 5.0
#: Paths answered even over the cap (liveness; it touches nothing).
ALWAYS_ANSWERED = frozenset({"/healthz"})


@dataclass(frozen=True)
class ConnectionLimits:
    """The three bounds (see the module docstring); ``max_per_client`` 0 = no cap."""

    header_timeout_s: float
    read_timeout_s: float
    max_per_client: int


@cache
def limits_from_settings() -> ConnectionLimits:
    """The limits of this server process, from its settings (environment, ``.env``), read once."""
    from app.settings import Settings

    settings = Settings()
    return ConnectionLimits(settings.header_timeout_s, settings.read_timeout_s, settings.max_connections_per_client)


#: Open connections per client address in this process (refused ones not counted).
open_per_client: Counter[str] = Counter()

_REFUSAL_BODY = json.dumps(
    {
        "error": "too_many_connections",
        "detail": "too many open connections from this address; close some or retry later",
    }
).encode()


async def refuse_connection(scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable) -> None:
    """503 ``too_many_connections`` with ``Retry-After``, closing the connection (no middleware, no routing)."""
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(_REFUSAL_BODY)).encode()),
        (b"retry-after", str(RETRY_AFTER_S).encode()),
        (b"cache-control", b"no-store"),
        (b"connection", b"close"),
    ]
    await send({"type": "http.response.start", "status": 503, "headers": headers})
    await send({"type": "http.response.body", "body": _REFUSAL_BODY, "more_body": False})


def _cancelled(timer: asyncio.TimerHandle | None) -> asyncio.TimerHandle | None:
    """Cancel ``timer`` if any; None, to store in its place."""
    if timer is not None:
        timer.cancel()
    return None


class LimitedHttpToolsProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with a head timeout, a body read timeout and a per-client cap."""

    limits: ConnectionLimits | None = None  # None: from the settings (tests may set it on a subclass)

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """Count the connection against its client's cap (or mark it refused) and start the head clock."""
        super().connection_made(transport)
        self._limits = self.limits or limits_from_settings()
        self._head_timer: asyncio.TimerHandle | None = None
        self._body_timer: asyncio.TimerHandle | None = None
        self._body_seen = 0.0
        self._counted: str | None = None
        self._refused = False
        host = self.client[0] if self.client else ""
        cap = self._limits.max_per_client
        if cap and open_per_client[host] >= cap:
            self._refused = True
            self._real_app = self.app
            self.app = self._refusal_app  # on_headers_complete hands the request to self.app
            self._arm_head_timer(min(REFUSED_HEAD_TIMEOUT_S, self._limits.header_timeout_s))
            return
        open_per_client[host] += 1
        self._counted = host
        self._arm_head_timer(self._limits.header_timeout_s)

    def connection_lost(self, exc: Exception | None) -> None:
        """Stop the clocks and release the client's slot."""
        self._cancel_head_timer()
        self._cancel_body_timer()
        if self._counted is not None:
            open_per_client[self._counted] -= 1
            if open_per_client[self._counted] <= 0:
                del open_per_client[self._counted]
            self._counted = None
        super().connection_lost(exc)

    async def _refusal_app(self, scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable) -> None:
        if scope.get("method") == "GET" and scope.get("path") in ALWAYS_ANSWERED:
            await self._real_app(scope, receive, self._closing(send))
            return
        await asyncio.sleep(min(REFUSAL_DELAY_S, self._limits.header_timeout_s))
        await refuse_connection(scope, receive, send)

    @staticmethod
    def _closing(send: ASGISendCallable) -> ASGISendCallable:
        """``send`` that adds ``Connection: close``: an over-cap connection gets one answer."""

        async def send_and_close(message: dict) -> None:  # type: ignore[type-arg]
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), (b"connection", b"close")]}
            await send(message)  # type: ignore[arg-type]

        return send_and_close  # type: ignore[return-value]

    # -- the head clock ---------------------------------------------------------------------------------
    def _arm_head_timer(self, seconds: float) -> None:
        if self._head_timer is None:
            self._head_timer = self.loop.call_later(seconds, self._head_timed_out)

    def _cancel_head_timer(self) -> None:
        self._head_timer = _cancelled(self._head_timer)

    def _head_timed_out(self) -> None:
        self._head_timer = None
        if not self.transport.is_closing():
            self.transport.close()

    def on_message_begin(self) -> None:
        """A request's first byte: a kept-alive connection's next head has ``header_timeout_s`` from here."""
        super().on_message_begin()
        self._arm_head_timer(self._limits.header_timeout_s)

    def on_headers_complete(self) -> None:
        """The head is in: stop its clock and watch the body instead."""
        self._cancel_head_timer()
        super().on_headers_complete()
        self._body_seen = self.loop.time()
        self._cancel_body_timer()
        self._body_timer = self.loop.call_later(self._limits.read_timeout_s, self._body_check)

    # -- the body clock ---------------------------------------------------------------------------------
    def on_body(self, body: bytes) -> None:
        """A piece of the body: the read clock starts again."""
        self._body_seen = self.loop.time()
        super().on_body(body)

    def on_message_complete(self) -> None:
        """The body is in (or there was none)."""
        self._cancel_body_timer()
        super().on_message_complete()

    def _cancel_body_timer(self) -> None:
        self._body_timer = _cancelled(self._body_timer)

    def _body_check(self) -> None:
        self._body_timer = None
        if self.transport.is_closing():
            return
        now = self.loop.time()
        held_back = self.flow.read_paused or (self.cycle is not None and self.cycle.waiting_for_100_continue)
        if held_back:
            self._body_seen = now  # the server is not reading: the client is not late
        idle = now - self._body_seen
        if idle < self._limits.read_timeout_s:
            self._body_timer = self.loop.call_later(self._limits.read_timeout_s - idle, self._body_check)
            return
        self.transport.close()

"""Work stopped when its client hangs up.

The server does not cancel a request handler whose client went away: a render or an upload check would run
on for nobody (a check would even reserve an id and queue a build). :func:`unless_client_goes` awaits the
work and watches the connection meanwhile; once the request's body has been read, the only message the
request can still receive is ``http.disconnect``. Cancelling the work kills its process (app.render.pool,
app.datasets.uploads), so the work really stops.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable
from typing import TypeVar

from starlette.requests import Request

from app.errors import ClientGone

T = TypeVar("T")


async def unless_client_goes(request: Request, work: Awaitable[T]) -> T:
    """Await ``work`` (the request's body read already); cancel it if the client hangs up first.

    Raises
    ------
    ClientGone
        The client hung up; ``work`` was cancelled and its clean-up has run.
    """
    task = asyncio.ensure_future(work)
    watch = asyncio.ensure_future(_disconnected(request))
    try:
        await asyncio.wait({task, watch}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        watch.cancel()
        if not task.done():
            task.cancel()
            await asyncio.wait({task})  # its clean-up (killing the process) runs before we answer
    if task.cancelled():
        raise ClientGone("the client hung up before its answer was ready; the work for it was stopped")
    return task.result()


async def _disconnected(request: Request) -> None:
    while (await request.receive())["type"] != "http.disconnect":
        pass

"""Startup and shutdown: open and check the store once, queue builds of missing or changed sources, and end
every build when the server stops."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from app.service import DatasetService
from app.store_follow import open_service
from engine.errors import StoreError

log = logging.getLogger("ccsm.app")


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Keep the DatasetService on ``app.state``; builds never block startup.

    A store that cannot be opened or is damaged does not crash the process (a restart would only crash
    again): the reason is logged once, ``/readyz`` reports it and every data route answers 503 with it.
    """
    settings = app.state.settings
    app.state.store_problem = None
    try:
        service: DatasetService | None = open_service(app)  # a store link is followed (app/store_follow.py)
    except StoreError as exc:
        service = None
        app.state.store_problem = str(exc)
        log.error("the store is unusable: %s", exc)
    app.state.service = service
    if service is not None:
        if settings.build_on_start:
            service.start_builds()
        log.info("store %s: %d datasets", settings.store_path.name, len(service.store.dataset_ids()))
    try:
        yield
    finally:
        final = app.state.service  # a replica may have moved to a newer store file meanwhile
        for opened in {id(s): s for s in (service, final) if s is not None}.values():
            opened.close()

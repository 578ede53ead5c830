"""Startup and shutdown: open the store once, start background builds of missing or changed sources."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from app.store_follow import open_service

log = logging.getLogger("ccsm.app")


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Open the store and keep the DatasetService on ``app.state``; builds never block startup."""
    settings = app.state.settings
    service = open_service(app)  # a store path that is a link is followed (app/store_follow.py)
    app.state.service = service
    if settings.build_on_start:
        service.start_builds()
    log.info("store %s: %d datasets", settings.store_path.name, len(service.store.dataset_ids()))
    try:
        yield
    finally:
        app.state.service.store.close()

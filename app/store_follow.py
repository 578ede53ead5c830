"""Replicas follow a live store link (engine/store/switch.py): the hook that swaps the service when it moves.

When ``CCSM_STORE_PATH`` is a symbolic link, each worker opens the file it names and, when ``ccsm build
--publish`` points it at a new build, opens a new :class:`~app.service.DatasetService` on the new file for the
requests that start from then on. Requests already running keep the service they started with, so no request
sees two stores, and none fails during the switch.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI

from app.service import DatasetService
from app.settings import Settings
from engine.store.switch import StorePointer

log = logging.getLogger("ccsm.app")


def open_service(app: FastAPI) -> DatasetService:
    """The lifespan's service: on the file the store path names, followed later when that path is a link."""
    settings: Settings = app.state.settings
    pointer = StorePointer(settings.store_path)
    if not pointer.follows:
        return DatasetService(settings)
    app.state.store_pointer = pointer
    log.info("store %s follows the link to %s", settings.store_path.name, pointer.target.name)
    return DatasetService(settings.model_copy(update={"store_path": pointer.target}))


def follow_store(app: FastAPI) -> None:
    """Swap ``app.state.service`` for one on the new store file if the store link moved (cheap otherwise)."""
    pointer: StorePointer | None = getattr(app.state, "store_pointer", None)
    if pointer is None:
        return
    target = pointer.moved()
    if target is None:
        return
    settings: Settings = app.state.settings
    app.state.service = DatasetService(settings.model_copy(update={"store_path": target}))
    log.info("store %s switched to %s", settings.store_path.name, target.name)

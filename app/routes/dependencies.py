"""Request dependencies: the service, settings, and the documented query parameter groups."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from fastapi import Query, Request

from app.service import DatasetService
from app.settings import Settings
from app.store_follow import follow_store
from engine.errors import StoreNotReady
from engine.method_names import MethodName


def get_service(request: Request) -> DatasetService:
    """The DatasetService the lifespan put on the app (a new one after the store link moved; StoreNotReady,
    503, when the store is unusable)."""
    if request.app.state.service is not None:
        follow_store(request.app)
    service: DatasetService | None = request.app.state.service
    if service is None:
        raise StoreNotReady(request.app.state.store_problem or "the store is not open")
    return service


def get_settings(request: Request) -> Settings:
    """The app's settings (built once by create_app)."""
    return request.app.state.settings  # type: ignore[no-any-return]


@dataclass
class TileQuery:
    """Query parameters of a tile: how it is drawn."""

    zoom: Annotated[
        float | None,
        Query(
            description="Fractional zoom in [z, z+1) to draw the tile at (continuous morphing inside a zoom "
            "level); default z.",
            ge=0,
            le=31,
            allow_inf_nan=False,
        ),
    ] = None
    method: Annotated[
        MethodName,
        Query(
            description="ccsm (continuous), dp (Douglas-Peucker), wm (Wang-Mueller), vw (Visvalingam-Whyatt) "
            "at the tile's scale, or original (no simplification)."
        ),
    ] = "ccsm"
    t: Annotated[
        float | None,
        Query(
            description="Pin t in [0, 1] for every contour (method=ccsm only); default: from the tile's scale.",
            ge=0,
            le=1,
            allow_inf_nan=False,
        ),
    ] = None
    v: Annotated[
        int | None,
        Query(description="Data version the TileJSON URL carries for cache busting; ignored otherwise."),
    ] = None

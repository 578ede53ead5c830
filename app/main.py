"""The FastAPI application, built by :func:`create_app` from typed settings.

``uvicorn app.main:app`` uses the module attribute ``app``, created on first access from the environment
(``CCSM_*``). Importing this module builds nothing; the store opens in the lifespan, and sources build in
the background.
"""

from __future__ import annotations

import gc
import logging
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.datasets.uploads import upload_checker_for
from app.http.api_docs import add_api_docs
from app.http.cors import JsonCORSMiddleware
from app.http.errors import add_exception_handlers, error_body, public_message
from app.http.head_requests import HeadAsGetMiddleware
from app.lifespan import lifespan
from app.render.pool import RETRY_AFTER_S, RenderUnavailable, render_lanes_for
from app.routes import datasets, hillshade, meta, simplify, styles, tiles
from app.settings import Settings

log = logging.getLogger("ccsm.app")

DESCRIPTION = """
Terrain contour lines that generalize **continuously** as the map zooms (Qian et al. 2021, the continuous
changing surface model), as Mapbox Vector Tiles, GeoJSON at any scale, and a dataset API.

* `GET /tiles/{dataset}/tilejson.json` gives MapLibre, OpenLayers or QGIS everything from one URL.
* Tiles take `zoom=` (fractional, in [z, z+1)) to morph inside a zoom level, and `method=` to compare CCSM
  with Douglas-Peucker, Wang-Mueller, Visvalingam-Whyatt or the original lines.
"""


class RequestIdMiddleware:
    """Gives every request an id (``X-Request-ID``; kept when the client sends a sane one)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Tag the request and its response with the id."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        rid = ""
        for key, value in scope.get("headers", []):
            if key == b"x-request-id":
                text = value.decode("latin-1")
                rid = text if len(text) <= 64 and text.replace("-", "").isalnum() else ""
                break
        rid = rid or uuid.uuid4().hex[:16]
        scope.setdefault("state", {})["request_id"] = rid

        async def send_with_id(message: Message) -> None:
            if message["type"] == "http.response.start":
                message.setdefault("headers", [])
                message["headers"] = list(message["headers"]) + [(b"x-request-id", rid.encode())]
            await send(message)

        await self.app(scope, receive, send_with_id)


@asynccontextmanager
async def app_lifespan(app: FastAPI) -> AsyncIterator[None]:
    """The service's lifespan (store, builds), plus the render workers and the upload checks inside it."""
    async with lifespan(app):
        lanes = render_lanes_for(app.state.settings)
        app.state.render_lanes = lanes
        app.state.upload_checker = upload_checker_for(app.state.settings)
        await lanes.start()
        # Objects made during start-up (modules, routes, settings, the store) live as long as the server: kept
        # out of the collector's full passes, which would otherwise pause the event loop to walk them.
        gc.freeze()
        try:
            yield
        finally:
            app.state.upload_checker.close()
            await lanes.close()


async def render_unavailable_handler(request: Request, exc: Exception) -> JSONResponse:
    """503 with Retry-After: the render pool is full, or the request passed its deadline."""
    log.info("%s %s -> 503 %s", request.method, request.url.path, exc)
    body = error_body(request, "service_busy", public_message(str(exc)))
    return JSONResponse(body, 503, headers={"Retry-After": str(RETRY_AFTER_S), "Cache-Control": "no-store"})


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application from settings (read from the environment when None)."""
    settings = settings or Settings()
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    app = FastAPI(
        title="ccsm",
        description=DESCRIPTION,
        version="0.1.0",
        lifespan=app_lifespan,
        docs_url=None,  # served from local files by add_api_docs
        redoc_url=None,
    )
    app.state.settings = settings
    add_exception_handlers(app)
    app.add_exception_handler(RenderUnavailable, render_unavailable_handler)
    add_api_docs(app)
    app.include_router(tiles.router)
    app.include_router(hillshade.router)
    app.include_router(styles.router)
    app.include_router(simplify.router)
    app.include_router(datasets.router)
    app.include_router(meta.router)
    web_dir = settings.web_dir
    if web_dir.is_dir():
        vendor = web_dir / "node_modules" / "maplibre-gl" / "dist"
        if vendor.is_dir():
            app.mount("/vendor/maplibre-gl", StaticFiles(directory=vendor), name="vendor-maplibre")
        app.mount("/web", StaticFiles(directory=web_dir), name="web")
    app.add_middleware(
        JsonCORSMiddleware,
        allow_origins=settings.cors_origins,
        allow_methods=["GET", "HEAD"],
        allow_headers=["*"],
        expose_headers=["ETag", "X-Request-ID", "X-Tile-Scale"],
        max_age=600,
    )
    app.add_middleware(HeadAsGetMiddleware)
    app.add_middleware(RequestIdMiddleware)
    return app


def __getattr__(name: str) -> Any:
    # ``app`` is created lazily: importing app.main (tests, the CLI) must not read the environment or build.
    if name == "app":
        value = create_app()
        globals()["app"] = value
        return value
    raise AttributeError(name)

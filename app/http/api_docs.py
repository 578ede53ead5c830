"""The API documentation page ``/docs``, served with no outside network.

FastAPI's own page loads Swagger UI from a CDN; here its files come from the ``swagger-ui-py`` package
(Swagger UI 5, Apache-2.0 licence), mounted at ``/docs-assets``. ReDoc is not served: it has no offline
bundle among the dependencies.
"""

from __future__ import annotations

from pathlib import Path

import swagger_ui
from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

#: Swagger UI's files, as the swagger-ui-py package ships them.
SWAGGER_UI_DIR = Path(swagger_ui.__file__).parent / "static"
ASSETS = "/docs-assets"


def add_api_docs(app: FastAPI) -> None:
    """Serve ``/docs`` from local files (create the app with ``docs_url=None, redoc_url=None``)."""
    app.mount(ASSETS, StaticFiles(directory=SWAGGER_UI_DIR), name="docs-assets")
    openapi_url = app.openapi_url or "/openapi.json"

    @app.get("/docs", include_in_schema=False)
    def api_docs() -> HTMLResponse:
        """Swagger UI on this service's OpenAPI document."""
        return get_swagger_ui_html(
            openapi_url=openapi_url,
            title=f"{app.title}: API",
            swagger_js_url=f"{ASSETS}/swagger-ui-bundle.js",
            swagger_css_url=f"{ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{ASSETS}/favicon-32x32.png",
            # The validator badge would send the document to an outside service.
            swagger_ui_parameters={"validatorUrl": None},
        )

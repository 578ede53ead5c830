"""The MapLibre style of a dataset and the glyphs its labels are drawn with (docs/clients.md)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated
from urllib.parse import quote

from fastapi import APIRouter, Request, Response
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, JSONResponse

from app.http.public_url import public_base_url
from app.http.responses import etag_matches, make_etag
from app.routes.params import DatasetPath, ServiceDep, SettingsDep
from app.service import lonlat_bounds
from app.settings import Settings
from engine.cartography.glyphs import glyph_range_pbf
from engine.cartography.style import FONT_STACK, StyleSource, build_style, rank_fades
from engine.errors import InvalidParameter, UnknownLayer
from engine.serve.relief import relief_dem_path

router = APIRouter(tags=["styles"])

#: A style changes with the data version (it names the tiles' version); clients may keep it a minute.
STYLE_MAX_AGE_S = 60
#: Glyphs never change while the font file stays the same.
GLYPHS_MAX_AGE_S = 86_400
#: Glyph ranges kept in memory (each about 100 kB; MapLibre asks for one or two for Latin text).
GLYPH_CACHE_RANGES = 16


@router.get("/styles/{dataset}/style.json", name="get_style")
def get_style(
    request: Request,
    dataset: DatasetPath,
    service: ServiceDep,
    settings: SettingsDep,
) -> Response:
    """A complete MapLibre style v8 of a dataset: hillshade (with a DEM), contours by rank and index, labels."""
    version = service.require_ready(dataset)
    info, _ = service.renderer.info(dataset)
    base = public_base_url(request, settings)  # never the Host header: see app/http/public_url.py
    ds = quote(dataset, safe="")
    etag = make_etag("style", dataset, version, base)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={STYLE_MAX_AGE_S}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    cartography = service.renderer.cartography(dataset)
    west, south, east, north = lonlat_bounds(info)
    has_relief = relief_dem_path(info) is not None
    source = StyleSource(
        dataset=dataset,
        name=info.name,
        tilejson_url=f"{base}/tiles/{ds}/tilejson.json",
        glyphs_url=f"{base}/fonts/{{fontstack}}/{{range}}.pbf",
        bounds=(west, south, east, north),
        schedule=rank_fades(cartography.schedule),
        hillshade_tiles_url=f"{base}/hillshade/{ds}/{{z}}/{{x}}/{{y}}.png?v={version}" if has_relief else None,
        webfonts_url=f"{base}/fonts/webfonts/{{font-family}}/{{fontweight}}{{-fontstyle}}.css",
    )
    return JSONResponse(build_style(source), headers=headers)


def served_font(fontstack: str) -> str:
    """The font of a requested stack this service has (MapLibre joins a stack's names with commas).

    Raises
    ------
    UnknownLayer
        No name of the stack is served.
    """
    names = [n.strip() for n in fontstack.split(",")]
    if FONT_STACK not in names:
        raise UnknownLayer(f"font stack {fontstack!r} is not served; this service serves {FONT_STACK!r}")
    return FONT_STACK


def parse_range(text: str) -> tuple[int, int]:
    """``"0-255"`` -> (0, 255).

    Raises
    ------
    InvalidParameter
        Not two integers joined by "-".
    """
    start, sep, end = text.partition("-")
    if not (sep and start.isdigit() and end.isdigit()):
        raise InvalidParameter(f"glyph range {text!r} must look like 0-255")
    return int(start), int(end)


@lru_cache(maxsize=GLYPH_CACHE_RANGES)
def cached_glyphs(font_path: Path, mtime_ns: int, fontstack: str, start: int, end: int) -> bytes:
    """Glyph ranges, made on first request and kept (the font file's mtime is part of the key)."""
    return glyph_range_pbf(font_path, fontstack, start, end)


@router.get(
    "/fonts/{fontstack}/{glyph_range}.pbf",
    response_class=Response,
    responses={
        200: {"content": {"application/x-protobuf": {}}, "description": "SDF glyphs of 256 code points."},
        400: {"description": "The range is not N*256-(N*256+255)."},
        404: {"description": "The font stack is not served, or the font file is missing."},
    },
    name="get_glyphs",
)
def get_glyphs(
    request: Request,
    fontstack: Annotated[str, PathParam(description="Font stack: names joined by commas.", max_length=256)],
    glyph_range: Annotated[str, PathParam(description="Code point range, e.g. 0-255.", max_length=16)],
    settings: SettingsDep,
) -> Response:
    """Signed-distance-field glyphs (MapLibre's glyph protobuf) of the labels' font."""
    font = served_font(fontstack)
    start, end = parse_range(glyph_range)
    path = label_font_file(settings)
    mtime = path.stat().st_mtime_ns
    etag = make_etag("glyphs", path.name, mtime, font, start, end)
    headers = {"ETag": etag, "Cache-Control": f"public, max-age={GLYPHS_MAX_AGE_S}"}
    if etag_matches(request, etag):
        return Response(status_code=304, headers=headers)
    data = cached_glyphs(path, mtime, font, start, end)
    return Response(data, media_type="application/x-protobuf", headers=headers)


#: Where the label font file is served, for clients that draw text with the browser's fonts.
FONT_FILE_PATH = "/fonts/files/label-font.ttf"


def label_font_file(settings: Settings) -> Path:
    """The label font file.

    Raises
    ------
    UnknownLayer
        The file is missing on the server.
    """
    path = settings.font_path
    if not path.is_file():
        raise UnknownLayer(f"the label font {path.name} is missing on the server (set CCSM_FONT_PATH)")
    return path


@router.get(
    "/fonts/webfonts/{family}/{variant}.css",
    response_class=Response,
    responses={200: {"content": {"text/css": {}}}, 404: {"description": "Not the label font's family."}},
    name="get_webfont_css",
)
def get_webfont_css(
    request: Request,
    family: Annotated[str, PathParam(description="Font family, lower case with hyphens (dejavu-sans).")],
    variant: Annotated[str, PathParam(description="Weight and style, e.g. 400 or 400-italic (any is served).")],
    settings: SettingsDep,
) -> Response:
    """A CSS @font-face of the label font, so OpenLayers (ol-mapbox-style) draws labels in it without a CDN."""
    name = FONT_STACK.rsplit(" ", 1)[0]  # "DejaVu Sans"
    if family != name.lower().replace(" ", "-"):
        raise UnknownLayer(f"font family {family!r} is not served; this service serves {name!r}")
    label_font_file(settings)
    url = public_base_url(request, settings) + FONT_FILE_PATH
    css = (
        f"@font-face {{ font-family: '{name}'; font-style: normal; font-weight: 100 900; "
        f"src: url('{url}') format('truetype'); }}\n"
    )
    headers = {"Cache-Control": f"public, max-age={GLYPHS_MAX_AGE_S}"}
    return Response(css, media_type="text/css", headers=headers)


@router.get(FONT_FILE_PATH, response_class=FileResponse, name="get_label_font")
def get_label_font(settings: SettingsDep) -> FileResponse:
    """The label font file itself (TrueType)."""
    return FileResponse(
        label_font_file(settings),
        media_type="font/ttf",
        headers={"Cache-Control": f"public, max-age={GLYPHS_MAX_AGE_S}"},
    )

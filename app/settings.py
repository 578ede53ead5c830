"""Typed settings of the service: environment variables with the prefix ``CCSM_`` (see .env.example).

Split by concern, as the app uses them: where data comes from and goes (store, sources, build), how tiles
are cut and cached, and the HTTP API (CORS, upload limit). ``Settings`` holds all three flat, so one
``CCSM_...`` variable sets one field.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from engine.cartography.options import CartographyOptions
from engine.cartography.schedule import parse_schedule

#: The project folder (where web/ lives), so relative paths do not depend on the working directory.
PROJECT_DIR = Path(__file__).resolve().parents[1]


class Settings(BaseSettings):
    """Every setting of the service. Environment: ``CCSM_<FIELD>`` (case-insensitive), or a ``.env`` file."""

    model_config = SettingsConfigDict(
        env_prefix="CCSM_", env_file=".env", extra="ignore", env_ignore_empty=True
    )

    # -- data ---------------------------------------------------------------------------------------------
    store_path: Path = Field(
        Path("var/ccsm.sqlite"), description="The SQLite store file (created if missing)."
    )
    sources: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="Contour files or DEMs to serve, comma-separated; empty = the bundled sample.",
    )
    bbox: Annotated[tuple[float, float, float, float] | None, NoDecode] = Field(
        None,
        description="Area W,S,E,N in degrees of the sources that take one: required for a terrain tile source "
        "(ENCODING:LOCATION); a GeoTIFF (a file or a URL) is read only there. Contour files are read whole.",
    )
    dem_zoom: int | None = Field(
        None, ge=0, le=24, description="Zoom of terrain tile sources to read; unset = the one matching source_scale."
    )
    serve_sample: bool = Field(True, description="Serve the bundled sample when no source is given.")
    elevation_field: str | None = Field(
        None, description="Elevation attribute of contour files (found by name if unset)."
    )
    interval: float | None = Field(None, gt=0, description="Contour interval; required for a DEM source.")
    source_scale: float = Field(50_000.0, gt=0, description="Scale denominator of the sources (t = 0).")
    target_scale: float = Field(
        500_000.0, gt=0, description="Scale denominator of the most generalized contours (t = 1)."
    )
    build_workers: int | None = Field(None, ge=1, description="Processes per build; unset = one per core.")
    build_on_start: bool = Field(
        True, description="Build missing or changed sources at startup, in the background."
    )
    max_builds: int = Field(
        1, ge=1, le=64, description="Builds (uploads, sources) running at once per server process."
    )
    build_queue: int = Field(
        4, ge=0, le=1000, description="Builds waiting for a free slot; one more upload is refused with 429."
    )

    # -- cartography of the sources (docs/design.md section 9) -------------------------------------------
    units: Literal["m", "ft", "fm"] | None = Field(
        None, description="Vertical unit of the sources; unset = as the source states it, else m."
    )
    index_every: int = Field(5, ge=2, le=100, description="Index contours are every n-th interval.")
    attribute_names: Literal["ccsm", "maplibre-contour"] = Field(
        "ccsm", description="Tile attribute names: ccsm (elevation) or maplibre-contour (ele)."
    )
    schedule: str | None = Field(
        None, description="Interval schedule override STEP:HIDE_SCALE,...,STEP; unset = the default rule."
    )
    sea: Literal["drop", "coastline", "keep"] = Field(
        "drop", description="The 0 m line: dropped, drawn as a coastline (coastline: true), or an ordinary contour."
    )
    depth_labels: Literal["negative", "below-datum"] = Field(
        "negative", description="Negative levels labelled -200 m (negative) or 200 m (below-datum)."
    )
    label_orientation: Literal["uphill", "upright"] = Field(
        "uphill", description="Label text top toward higher ground (uphill) or always upright."
    )
    attribution: str | None = Field(
        None, description="Attribution of the sources in TileJSON; unset = the source file's name."
    )

    # -- tiles --------------------------------------------------------------------------------------------
    min_zoom: int = Field(0, ge=0, le=30, description="Smallest tile zoom served.")
    max_zoom: int = Field(16, ge=0, le=30, description="Largest tile zoom served.")
    tile_extent: int = Field(4096, ge=256, le=65536, description="MVT grid size.")
    tile_buffer: int = Field(64, ge=0, le=1024, description="MVT buffer around a tile, grid units.")
    cache_max_age: int = Field(
        3600, ge=0, description="Cache-Control max-age of tiles, TileJSON and /simplify, seconds."
    )
    contour_cache_mb: int = Field(
        512, ge=1, description="Memory for decoded contours per worker process, MB."
    )
    head_cache_mb: int = Field(
        128,
        ge=0,
        description="Memory per worker process for the contour heads (t tables) of datasets too large to hold "
        "whole, MB: 8 x (ladder + 3) bytes per contour, 55 MB for 193,000 contours; 0: read per tile.",
    )
    store_mmap_mb: int = Field(
        4096,
        ge=0,
        description="Store file read through memory mapping by each render worker, MB (SQLite mmap_size): shared "
        "file cache, not the worker's own memory; 0: none.",
    )
    baseline_cache_entries: int = Field(
        100_000, ge=1, description="Cached DP/VW/WM results per worker process."
    )

    # -- load: CPU work off the event loop (docs/service.md, "Under load") -------------------------------
    render_workers: int = Field(
        2, ge=1, le=64, description="Worker processes drawing ccsm and original tiles, per server process."
    )
    heavy_render_workers: int = Field(
        1, ge=1, le=64, description="Worker processes for baseline tiles (dp, wm, vw) and /simplify."
    )
    morph_render_workers: int = Field(
        1,
        ge=1,
        le=64,
        description="Worker processes drawing morph tiles, per server process: a lane of their own, so a plain "
        "tile never waits behind a slow morph tile.",
    )
    morph_cache_mb: int = Field(
        64, ge=0, description="Morph tiles kept per morph worker process, MB (0: none); per data version."
    )
    render_queue: int = Field(
        8, ge=0, description="Requests that may wait for a busy render worker, per lane; beyond it: 503 at once."
    )
    request_timeout_s: float = Field(
        20.0,
        gt=0,
        description="Deadline of a tile or /simplify request, seconds; then 503 and its worker is replaced.",
    )
    wm_max_vertices: int = Field(
        50_000, ge=3, description="Largest contour (vertices) method=wm simplifies; larger: 400 naming it."
    )
    public_url: str | None = Field(
        None,
        description="Base URL clients reach the service at (TileJSON tile URLs); unset = the address the "
        "server listens on. The Host header is never used.",
    )
    trust_forwarded_headers: bool = Field(
        False, description="Take the TileJSON base URL from X-Forwarded-Proto/-Host (behind a trusted proxy)."
    )

    # -- connections (app/http/connection_limits.py; per server process) ---------------------------------
    header_timeout_s: float = Field(
        10.0,
        gt=0,
        description="Seconds a request head may take, from the connection opening (or, kept alive, from the "
        "request's first byte); then the connection is closed.",
    )
    read_timeout_s: float = Field(
        30.0, gt=0, description="Seconds a request body may send nothing; then the connection is closed."
    )
    max_connections_per_client: int = Field(
        64,
        ge=0,
        description="Open connections per client address, per server process; one more is answered 503 with "
        "Retry-After and closed (GET /healthz still answered). 0: no cap. Behind a proxy this counts the proxy.",
    )

    # -- API ----------------------------------------------------------------------------------------------
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["*"], description="Origins allowed by CORS, comma-separated ('*' = any)."
    )
    max_upload_mb: float = Field(20.0, gt=0, description="Largest POST /datasets body, MB.")
    max_contour_vertices: int = Field(
        50_000,
        ge=0,
        description="Most vertices one uploaded contour (a LineString, or each part of a MultiLineString) may "
        "have; more: 413 naming it, before anything builds (0: no limit). One contour builds in one worker, "
        "in time that grows faster than its length: on 2 cores, one of 50,000 vertices built in about 1 s "
        "(the whole dataset build about 25 s, under load), one of 100,000 in 24 s (the whole build 88 s), "
        "one of 1,000,000 in about 100 s at 1.15 GB. The command line has no limit.",
    )
    upload_checks: int = Field(
        1, ge=1, le=64, description="Uploads parsed and checked at once (a process each), per server process."
    )
    upload_check_queue: int = Field(
        16, ge=0, le=1000, description="Uploads waiting (on disk) for a check; one more is refused with 429."
    )
    upload_check_timeout_s: float = Field(
        300.0, gt=0, description="Seconds an upload's check may take; then it is stopped and the upload gets 503."
    )
    admin_token: SecretStr | None = Field(
        None,
        description="Bearer token that writes (POST/DELETE /datasets) need; unset = writes only from "
        "loopback clients addressing the server as localhost.",
    )
    web_dir: Path = Field(
        Path("web"),
        description="Directory of the web map (index.html), served at /; a relative path is taken from the "
        "project folder, not from where the server was started.",
    )

    @field_validator("web_dir")
    @classmethod
    def _web_dir_from_project(cls, value: Path) -> Path:
        return value if value.is_absolute() else PROJECT_DIR / value
    font_path: Path = Field(
        Path("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"),
        description="TrueType font the service makes its label glyphs from (GET /fonts/...); DejaVu Sans by "
        "default (Debian's fonts-dejavu-core).",
    )
    log_level: str = Field("info", description="Log level of the service.")

    @field_validator("sources", "cors_origins", mode="before")
    @classmethod
    def _split(cls, value: object) -> object:
        if isinstance(value, str):
            text = value.strip()
            if text.startswith("["):
                import json

                return json.loads(text)
            return [v.strip() for v in text.split(",") if v.strip()]
        return value

    @field_validator("bbox", mode="before")
    @classmethod
    def _parse_bbox(cls, value: object) -> object:
        if isinstance(value, str):
            from engine.io.terrain_tiles import check_bbox

            parts = value.split(",")
            try:
                numbers = tuple(float(p) for p in parts)
            except ValueError:
                numbers = ()
            if len(numbers) != 4:
                raise ValueError(f"bbox {value!r}: expected W,S,E,N, four numbers in degrees")
            return check_bbox(numbers, "bbox")  # type: ignore[arg-type]
        return value

    @field_validator("schedule")
    @classmethod
    def _check_schedule(cls, value: str | None) -> str | None:
        if value is not None:
            parse_schedule(value)  # InvalidParameter (a ValueError) names the bad entry
        return value

    @model_validator(mode="after")
    def _check(self) -> Settings:
        if self.min_zoom > self.max_zoom:
            raise ValueError(f"min_zoom {self.min_zoom} > max_zoom {self.max_zoom}")
        if self.target_scale <= self.source_scale:
            raise ValueError(
                f"target_scale {self.target_scale:g} must exceed source_scale {self.source_scale:g}"
            )
        return self

    @property
    def cartography(self) -> CartographyOptions | None:
        """The sources' cartography options; None when every one is at its default (the hash of a source
        built before these options existed stays the same)."""
        options = CartographyOptions(
            self.units,
            self.index_every,
            self.attribute_names,
            self.schedule,
            self.attribution,
            self.sea,
            self.depth_labels,
            self.label_orientation,
        )
        return None if options == CartographyOptions() else options

    @property
    def max_upload_bytes(self) -> int:
        """The upload limit in bytes."""
        return int(self.max_upload_mb * 1024 * 1024)

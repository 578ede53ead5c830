"""Typed settings of the service: environment variables with the prefix ``CCSM_`` (see .env.example).

Split by concern, as the app uses them: where data comes from and goes (store, sources, build), how tiles
are cut and cached, and the HTTP API (CORS, upload limit). ``Settings`` holds all three flat, so one
``CCSM_...`` variable sets one field.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

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
    baseline_cache_entries: int = Field(
        100_000, ge=1, description="Cached DP/VW/WM results per worker process."
    )

    # -- API ----------------------------------------------------------------------------------------------
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["*"], description="Origins allowed by CORS, comma-separated ('*' = any)."
    )
    max_upload_mb: float = Field(20.0, gt=0, description="Largest POST /datasets body, MB.")
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
    def max_upload_bytes(self) -> int:
        """The upload limit in bytes."""
        return int(self.max_upload_mb * 1024 * 1024)

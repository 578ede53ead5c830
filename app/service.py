"""The datasets a running service knows: stored ones, configured sources, uploads, and their builds.

Builds run in background threads (the service answers meanwhile; a dataset that is being rebuilt keeps
serving its previous version). Their progress lives in the store's ``builds`` table, so every worker
process sees it. A file lock next to the store makes sure only one process builds at a time; the others
wait and then find the dataset current.
"""

from __future__ import annotations

import fcntl
import json
import logging
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.errors import DatasetExists, MalformedUpload, public_message
from app.settings import Settings
from engine.errors import CCSMError, StoreNotReady, UnknownLayer
from engine.serve.datasets import SourceSpec, build_and_save, build_dataset, slugify, source_hash
from engine.serve.relief import ReliefCache
from engine.serve.renderer import Renderer, TileOptions
from engine.store.sqlite import CCSStore, DatasetInfo
from engine.tiles.grid import mercator_to_lonlat
from engine.tiles.scale import zoom_for_scale

log = logging.getLogger("ccsm.service")

#: Dataset id of the bundled sample.
SAMPLE_ID = "sample"
SAMPLE_NAME = "Jacksboro, Tennessee: 20 m contours (USGS DEM, bundled sample)"


def specs_from_settings(settings: Settings) -> list[SourceSpec]:
    """The sources the settings name (the bundled sample when none is named and serve_sample is on)."""
    common = {
        "elevation_field": settings.elevation_field,
        "interval": settings.interval,
        "source_scale": settings.source_scale,
        "target_scale": settings.target_scale,
    }
    if settings.sources:
        specs = []
        seen: set[str] = set()
        for src in settings.sources:
            path = Path(src).expanduser()
            ident = slugify(path.stem)
            while ident in seen:
                ident += "-2"
            seen.add(ident)
            specs.append(SourceSpec(path=path, dataset=ident, name=path.stem, **common))  # type: ignore[arg-type]
        return specs
    if settings.serve_sample:
        from engine.io.sample import sample_dem_path
        from engine.io.source import sample_contours_path

        common["elevation_field"] = None
        common["interval"] = None
        # The sample's contours were traced from the bundled DEM: shade that under them.
        try:
            relief = {"relief_dem": sample_dem_path()}
        except CCSMError:  # no DEM beside the sample (an installed wheel): no hillshade, contours still served
            relief = {}
        return [
            SourceSpec(path=sample_contours_path(), dataset=SAMPLE_ID, name=SAMPLE_NAME, **common, **relief)  # type: ignore[arg-type]
        ]
    return []


@contextmanager
def build_lock(store_path: Path) -> Iterator[None]:
    """An exclusive lock shared by every process using the store (held while one builds)."""
    lock_path = store_path.with_name(store_path.name + ".build-lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@dataclass
class Upload:
    """A validated upload waiting to be built."""

    dataset: str
    name: str
    path: Path
    digest: str
    params: dict[str, Any]


class DatasetService:
    """Owns the store, the renderer and the background builds of one worker process."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.store = CCSStore(settings.store_path)
        self.reliefs = ReliefCache()
        self.renderer = Renderer(
            self.store,
            TileOptions(
                extent=settings.tile_extent,
                buffer_px=settings.tile_buffer,
                min_zoom=settings.min_zoom,
                max_zoom=settings.max_zoom,
            ),
            contour_cache_bytes=settings.contour_cache_mb << 20,
            baseline_cache_entries=settings.baseline_cache_entries,
        )
        self.specs = specs_from_settings(settings)
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._local_failures: dict[str, str] = {}
        self.upload_dir = settings.store_path.parent / "uploads"

    # -- builds ------------------------------------------------------------------------------------------
    def start_builds(self) -> None:
        """Build every configured source that is missing or changed, in one background thread."""
        pending = [s for s in self.specs if not self._is_current(s)]
        if not pending:
            return
        for spec in pending:
            if spec.path.exists():
                self.store.set_build_status(spec.dataset, "building", 0, 0)
        thread = threading.Thread(target=self._build_sources, args=(pending,), name="ccsm-build", daemon=True)
        self._threads.append(thread)
        thread.start()

    def _is_current(self, spec: SourceSpec) -> bool:
        try:
            return self.store.source_hash_of(spec.dataset) == source_hash(spec.path, spec.params())
        except OSError:
            return False

    def _build_sources(self, specs: list[SourceSpec]) -> None:
        with build_lock(self.settings.store_path):
            for spec in specs:
                self._build_one(spec)

    def _progress(self, dataset: str) -> Any:
        last = [0.0]

        def report(done: int, total: int) -> None:
            now = time.monotonic()
            if done in (0, total) or now - last[0] > 0.25:
                last[0] = now
                self.store.set_build_status(dataset, "building", done, total)

        return report

    def _build_one(self, spec: SourceSpec) -> None:
        try:
            self.store.set_build_status(spec.dataset, "building", 0, 0)
            info, rebuilt = build_dataset(
                self.store, spec, workers=self.settings.build_workers, progress=self._progress(spec.dataset)
            )
            self.store.clear_build_status(spec.dataset)
            self.renderer.forget(spec.dataset)
            log.info(
                "dataset %s %s (%d contours)",
                spec.dataset,
                "built" if rebuilt else "current",
                info.n_contours,
            )
        except Exception as exc:  # a failed build is reported on the dataset, the service keeps running
            message = public_message(str(exc)) if isinstance(exc, CCSMError) else "build failed (see the log)"
            log.error("building %s failed", spec.dataset, exc_info=exc)
            self.store.set_build_status(spec.dataset, "failed", 0, 0, message)

    def wait_for_builds(self, timeout: float | None = None) -> None:
        """Block until the background builds started so far are done (tests, CLI)."""
        for t in list(self._threads):
            t.join(timeout)

    # -- uploads -----------------------------------------------------------------------------------------
    def validate_upload(
        self,
        body: bytes,
        *,
        dataset: str | None,
        name: str | None,
        elevation_field: str | None,
        interval: float | None,
        source_scale: float,
        target_scale: float,
    ) -> tuple[Upload, Any]:
        """Check an uploaded GeoJSON and read its contours (raises MalformedUpload, SourceError, ...)."""
        from engine.io.source import read_source
        from engine.params import BuildParams

        BuildParams(source_scale=source_scale, target_scale=target_scale)  # validates the scales
        try:
            doc = json.loads(body)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise MalformedUpload(f"the body is not valid JSON ({exc})") from None
        if not isinstance(doc, dict) or doc.get("type") not in ("FeatureCollection", "Feature"):
            raise MalformedUpload(
                "the body must be a GeoJSON FeatureCollection (or Feature) of contour lines"
            )
        if doc["type"] == "FeatureCollection" and not isinstance(doc.get("features"), list):
            raise MalformedUpload("a FeatureCollection needs a 'features' array")
        params = {
            "elevation_field": elevation_field,
            "interval": interval,
            "source_scale": source_scale,
            "target_scale": target_scale,
        }
        digest = source_hash(None, params, data=body)
        if not dataset:
            ident = self._free_id(slugify(name) if name else f"upload-{digest[:10]}")
        elif dataset != slugify(dataset):
            raise MalformedUpload(f"dataset id {dataset!r} may contain only a-z, 0-9, '_' and '-'")
        elif self._taken(dataset):
            raise DatasetExists(f"dataset {dataset!r} exists already; DELETE it first or choose another id")
        else:
            ident = dataset
        self.upload_dir.mkdir(parents=True, exist_ok=True)
        path = self.upload_dir / f"{ident}-{uuid.uuid4().hex[:8]}.geojson"
        path.write_bytes(body)
        try:
            contour_set = read_source(path, elevation_field=elevation_field, interval=interval)
        except BaseException:
            path.unlink(missing_ok=True)
            raise
        return Upload(ident, name or ident, path, digest, params), contour_set

    def _taken(self, ident: str) -> bool:
        return self.store.data_version(ident) is not None or self._building(ident)

    def _free_id(self, base: str) -> str:
        """``base``, or ``base-2``, ``base-3``, ... for an id made from a name: uploading a file of the same
        name again makes a new dataset instead of failing (an explicit ``id`` still gets 409)."""
        base = base[:60] or "upload"
        ident, n = base, 2
        while self._taken(ident):
            ident, n = f"{base}-{n}", n + 1
        return ident

    def start_upload_build(self, upload: Upload, contour_set: Any) -> None:
        """Build a validated upload in the background (one process: the server keeps the other cores)."""
        self.store.set_build_status(upload.dataset, "building", 0, len(contour_set.contours))
        thread = threading.Thread(
            target=self._build_upload,
            args=(upload, contour_set),
            name=f"ccsm-upload-{upload.dataset}",
            daemon=True,
        )
        self._threads.append(thread)
        thread.start()

    def _build_upload(self, upload: Upload, contour_set: Any) -> None:
        try:
            build_and_save(
                self.store,
                upload.dataset,
                contour_set,
                name=upload.name,
                source="upload",
                digest=upload.digest,
                params=upload.params,
                workers=1,
                progress=self._progress(upload.dataset),
                still_wanted=lambda: self._building(upload.dataset) is not None,  # not deleted meanwhile
            )
            self.store.clear_build_status(upload.dataset)
        except Exception as exc:
            message = public_message(str(exc)) if isinstance(exc, CCSMError) else "build failed (see the log)"
            log.error("building upload %s failed", upload.dataset, exc_info=exc)
            self.store.set_build_status(upload.dataset, "failed", 0, 0, message)
        finally:
            upload.path.unlink(missing_ok=True)

    # -- queries -----------------------------------------------------------------------------------------
    def _building(self, dataset: str) -> Any:
        return self.store.build_statuses().get(dataset)

    def require_ready(self, dataset: str) -> int:
        """The data_version of a servable dataset.

        Raises
        ------
        StoreNotReady
            The dataset is being built for the first time or its build failed.
        UnknownLayer
            No such dataset.
        """
        version = self.store.data_version(dataset)
        if version is not None:
            return version
        status = self._building(dataset)
        if status is not None:
            if status.state == "failed":
                raise StoreNotReady(f"dataset {dataset!r} failed to build: {status.error}")
            raise StoreNotReady(
                f"dataset {dataset!r} is still being built ({status.done}/{status.total} contours)"
            )
        raise UnknownLayer(f"unknown dataset {dataset!r}")

    def default_dataset(self) -> str:
        """The dataset used when a request names none: the first configured source, else the first stored."""
        for spec in self.specs:
            return spec.dataset
        ids = self.store.dataset_ids()
        if not ids:
            raise UnknownLayer("no dataset is stored; name one with dataset=")
        return ids[0]

    def summaries(self) -> list[dict[str, Any]]:
        """id, name, state of every dataset (stored, configured, uploaded or building).

        A stored dataset is ``ready`` (also while a newer version of it builds: it keeps serving); one not
        stored yet is ``building`` or, when its build failed, ``failed``.
        """
        statuses = self.store.build_statuses()
        names = {s.dataset: s.name for s in self.specs}
        out: dict[str, dict[str, Any]] = {}
        for ident in self.store.dataset_ids():
            info = self.renderer.info(ident)[0]
            out[ident] = {"id": ident, "name": info.name, "state": "ready", "data_version": info.data_version}
        pending = {s.dataset for s in self.specs} | set(statuses)
        for ident in sorted(pending - set(out)):
            st = statuses.get(ident)
            state = "failed" if st is not None and st.state == "failed" else "building"
            out[ident] = {"id": ident, "name": names.get(ident, ident), "state": state, "data_version": None}
        return sorted(out.values(), key=lambda d: d["id"])

    def detail(self, dataset: str) -> dict[str, Any]:
        """Everything known about one dataset."""
        summary = next((s for s in self.summaries() if s["id"] == dataset), None)
        if summary is None:
            raise UnknownLayer(f"unknown dataset {dataset!r}")
        status = self.store.build_statuses().get(dataset)
        out = dict(summary)
        out["build"] = (
            None
            if status is None
            else {
                "state": status.state,
                "done": status.done,
                "total": status.total,
                "error": status.error,
                "started": status.started,
                "updated": status.updated,
            }
        )
        if self.store.data_version(dataset) is None:
            return out
        info, interval = self.renderer.info(dataset)
        out.update(describe(info, interval, self.settings))
        return out

    def delete(self, dataset: str) -> None:
        """Remove a dataset (raises UnknownLayer if there is none)."""
        existed = self.store.delete(dataset)
        self.renderer.forget(dataset)
        if not existed:
            raise UnknownLayer(f"unknown dataset {dataset!r}")


def lonlat_bounds(info: DatasetInfo) -> list[float]:
    """[west, south, east, north] of a dataset, degrees."""
    minx, miny, maxx, maxy = info.bounds_3857
    lon, lat = mercator_to_lonlat(np.array([minx, maxx]), np.array([miny, maxy]))
    return [
        round(float(lon[0]), 6),
        round(float(lat[0]), 6),
        round(float(lon[1]), 6),
        round(float(lat[1]), 6),
    ]


def describe(info: DatasetInfo, interval: float | None, settings: Settings) -> dict[str, Any]:
    """Extent, counts and scales of a stored dataset (the JSON of GET /datasets/{id})."""
    bounds = lonlat_bounds(info)
    lat = (bounds[1] + bounds[3]) / 2
    return {
        "source": info.source,
        "data_version": info.data_version,
        "bounds": bounds,
        "center": [round((bounds[0] + bounds[2]) / 2, 6), round(lat, 6)],
        "counts": {
            "contours": info.n_contours,
            "closed": info.n_closed,
            "vertices": info.n_vertices,
            "bad_features": len(info.bad_features),
        },
        "interval": interval,
        "scales": {
            "source_scale": info.source_scale,
            "target_scale": info.target_scale,
            "source_zoom": round(float(zoom_for_scale(info.source_scale, lat)), 3),
            "target_zoom": round(float(zoom_for_scale(info.target_scale, lat)), 3),
            "ladder": [round(float(s), 1) for s in info.ladder],
        },
        "working_crs": info.working_crs,
        "source_crs": info.source_crs if len(info.source_crs) < 200 else "(WKT)",
        "built_at": info.built_at,
        "build_seconds": round(info.build_seconds, 3),
        "bad_features": info.bad_features[:1000],
        "tilejson": f"/tiles/{info.id}/tilejson.json",
        "minzoom": settings.min_zoom,
        "maxzoom": settings.max_zoom,
    }

"""The datasets a running service knows: stored ones, configured sources, uploads, and their builds.

Builds run in processes of their own, a bounded number at a time (:mod:`app.datasets.builds`); the service answers
meanwhile, and a dataset being rebuilt keeps serving its previous version. A build's progress lives in the
store's ``builds`` table, so every worker process sees it. An upload's id is reserved in that table in one
transaction (:meth:`CCSStore.reserve`), so two requests, or two server processes, never get the same id.
"""

from __future__ import annotations

import logging
import os
import uuid
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.datasets.builds import BuildRunner
from app.datasets.sources import SAMPLE_ID, SAMPLE_NAME, configured_sources, tile_cache_dir
from app.datasets.upload_check import CheckedUpload
from app.datasets.uploads import INCOMING_PREFIX
from app.errors import BuildQueueFull, DatasetExists
from app.http.errors import log_safe
from app.settings import Settings
from engine.build.datasets import RELIEF_DEM_KEY, SourceSpec, build_lock, slugify, source_hash
from engine.build.job import BuildJob
from engine.cartography.options import PARAMS_KEY as CARTOGRAPHY_KEY
from engine.cartography.options import CartographyOptions
from engine.errors import StoreError, StoreNotReady, StoreUnwritable, UnknownLayer
from engine.io.source import source_arguments
from engine.scratch import pid_alive, remove_stale_scratch
from engine.serve.renderer import Renderer, TileOptions
from engine.store.records import DatasetInfo
from engine.store.store import CCSStore
from engine.tiles.grid import mercator_to_lonlat
from engine.tiles.scale import zoom_for_scale

__all__ = ["SAMPLE_ID", "SAMPLE_NAME", "DatasetService", "build_lock", "specs_from_settings"]

log = logging.getLogger("ccsm.service")


def specs_from_settings(settings: Settings) -> list[SourceSpec]:
    """The build specs of the sources the settings name that could be read as sources
    (:func:`app.datasets.sources.configured_sources`)."""
    return configured_sources(settings).specs


def source_job_params(spec: SourceSpec) -> dict[str, Any]:
    """A configured source's spec fields as a build process takes them (plain JSON values)."""
    params = spec.params()
    if spec.relief_dem is not None:  # not part of the content hash, but the build stores it for hillshade
        params[RELIEF_DEM_KEY] = str(spec.relief_dem)
    return params


def open_checked_store(path: Path) -> CCSStore:
    """Open the store, check it (``PRAGMA quick_check``) and checkpoint its WAL.

    Raises
    ------
    StoreError
        The file is damaged or not a ccsm store; the message says what to do.
    """
    advice = (
        f"stop the service and move {path} (and its -wal/-shm files) aside; a new store is created at the next "
        "start and configured sources are rebuilt (uploads must be uploaded again)"
    )
    try:
        store = CCSStore(path)
        problem = store.quick_check()
    except StoreError as exc:
        if _read_only(path.parent):  # not damaged: moving it aside would lose it
            raise StoreUnwritable(
                f"store {path.name} is on a read-only file system; make {path.parent} writable and restart"
            ) from exc
        raise StoreError(f"{exc}; {advice}") from exc
    if problem != "ok":
        store.close()
        raise StoreError(f"store {path.name} is damaged ({problem}); {advice}")
    store.checkpoint()
    for removed in remove_stale_scratch(path.parent):  # a killed build's; a running one's stay
        log.info("removed the stale scratch file %s", removed.name)
    leftovers = store.purge_leftovers()  # the rows a killed build staged, a replaced version's not yet removed
    if leftovers:
        log.info("removed the rows of %d stopped build(s) or replaced version(s)", len(leftovers))
    return store


@dataclass(frozen=True)
class UploadParams:
    """How an upload is read and built (part of its content hash)."""

    elevation_field: str | None
    interval: float | None
    source_scale: float
    target_scale: float
    cartography: CartographyOptions | None = None

    def as_dict(self) -> dict[str, Any]:
        """The parameters that decide the build (part of the content hash); cartography options only when
        they differ from the defaults, so hashes of uploads without them stay as they were."""
        params: dict[str, Any] = {
            "elevation_field": self.elevation_field,
            "interval": self.interval,
            "source_scale": self.source_scale,
            "target_scale": self.target_scale,
        }
        options = (self.cartography or CartographyOptions()).checked()
        if options != CartographyOptions():
            params[CARTOGRAPHY_KEY] = options.as_params()
        return params

    def stored(self, source_units: str | None) -> dict[str, Any]:
        """The parameters as stored with the dataset: the vertical unit resolved (given, else as the
        elevation property's name states it, ``source_units``, else metres)."""
        options = (self.cartography or CartographyOptions()).checked()
        units = options.units or source_units or "m"
        return {**self.as_dict(), CARTOGRAPHY_KEY: replace(options, units=units).as_params()}

    def check(self) -> None:
        """Refuse bad scales or cartography options (InvalidParameter) before anything is received."""
        from engine.params import BuildParams

        BuildParams(source_scale=self.source_scale, target_scale=self.target_scale)
        self.as_dict()


class DatasetService:
    """Owns the store, the renderer and the builds of one worker process.

    Raises
    ------
    StoreError
        The store cannot be opened or is damaged (see :func:`open_checked_store`).
    """

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.store = open_checked_store(settings.store_path)
        self.renderer = Renderer(
            self.store,
            TileOptions(
                extent=settings.tile_extent,
                buffer_px=settings.tile_buffer,
                min_zoom=settings.min_zoom,
                max_zoom=settings.max_zoom,
            ),
            contour_cache_bytes=settings.contour_cache_mb << 20,
            head_cache_bytes=settings.head_cache_mb << 20,
            baseline_cache_entries=settings.baseline_cache_entries,
        )
        configured = configured_sources(settings)
        self.specs = configured.specs
        self.source_problems = configured.problems  # dataset id -> why its source could not be read
        self.upload_dir = settings.store_path.parent / "uploads"
        self.builds = BuildRunner(settings.max_builds, settings.build_queue, self._build_ended)
        self.remove_stale_uploads()

    # -- builds ------------------------------------------------------------------------------------------
    def start_builds(self) -> None:
        """Queue a build of every configured source that is missing or changed; a source that could not be
        read as one is recorded as its dataset's failed build (GET /datasets/{id} gives the reason)."""
        for ident, why in self.source_problems.items():
            log.error("dataset %s: %s", log_safe(ident), log_safe(why))
            self.store.set_build_status(ident, "failed", error=why)
        for spec in self.specs:
            if self._is_current(spec):
                self._log_contour_issues(spec.dataset)
            if self._is_current(spec) or (isinstance(spec.path, Path) and not spec.path.exists()):
                continue
            self.store.set_build_status(spec.dataset, "building", 0, 0)
            text, bbox, dem_zoom = source_arguments(spec.path)
            job = BuildJob(
                kind="source",
                store_path=str(self.settings.store_path),
                dataset=spec.dataset,
                source_path=text,
                name=spec.name,
                params=source_job_params(spec),
                workers=self.settings.build_workers,
                bbox=bbox,
                dem_zoom=dem_zoom,
                tile_cache=str(tile_cache_dir(self.settings)),
            )
            self.builds.submit(job, limit_queue=False)

    def _is_current(self, spec: SourceSpec) -> bool:
        try:
            return self.store.source_hash_of(spec.dataset) == source_hash(spec.path, spec.params())
        except OSError:
            return False

    def _build_ended(self, job: BuildJob, returncode: int) -> None:
        """A build process ended: one killed or crashed leaves a reason (unless its dataset was deleted)."""
        if returncode != 0:
            why = f"the build process ended with status {returncode} (see the service log)"
            if self.store.fail_build(job.dataset, why):
                log.error("building %s: %s", log_safe(job.dataset), why)
        else:
            self.renderer.forget(job.dataset)
            self._log_contour_issues(job.dataset)
        if job.kind == "upload":
            Path(job.source_path).unlink(missing_ok=True)

    def _log_contour_issues(self, dataset: str) -> None:
        """Tell the service log which contours of a built dataset are served without part of their build."""
        issues, total = self.store.contour_issues(dataset)
        if total:
            shown = "; ".join(f"fid {i['fid']} ({i['id']}) {i['step']}: {i['reason']}" for i in issues[:5])
            more = f"; and {total - 5} more (GET /datasets/{dataset})" if total > 5 else ""
            log.warning(
                "dataset %s: %d contour(s) served without part of their build: %s%s",
                log_safe(dataset), total, log_safe(shown), more,
            )

    def wait_for_builds(self, timeout: float | None = None) -> None:
        """Block until the builds started or queued so far are done (tests, CLI)."""
        self.builds.wait_idle(timeout)

    def close(self) -> None:
        """End every build (the server is stopping) and close the store."""
        self.builds.shutdown()
        self.store.close()

    def remove_stale_uploads(self) -> None:
        """Remove upload files no live build needs (left by a killed server or build)."""
        if not self.upload_dir.is_dir():
            return
        statuses = self.store.build_statuses()
        live = {d for d, s in statuses.items() if s.state == "building"}
        for path in self.upload_dir.glob("*.geojson"):
            if path.name.startswith(INCOMING_PREFIX):
                pid = path.name[len(INCOMING_PREFIX) :].split("-", 1)[0]
                if pid.isdigit() and pid_alive(int(pid)):
                    continue
            elif path.name.rsplit("-", 1)[0] in live:
                continue
            path.unlink(missing_ok=True)
            log.info("removed the stale upload file %s", path.name)

    # -- uploads -----------------------------------------------------------------------------------------
    def accept_upload(
        self, incoming: Path, checked: CheckedUpload, *, dataset: str | None, name: str | None, params: UploadParams
    ) -> dict[str, Any]:
        """Reserve the id of an upload that passed its check, keep its file and queue its build; the JSON
        answer of POST /datasets. The file (streamed there by :func:`app.datasets.uploads.receive_upload`) is kept
        only if the upload is accepted.

        Raises
        ------
        DatasetExists
            ``dataset`` is taken (stored, building or failed).
        BuildQueueFull
            Too many builds wait already.
        StoreUnwritable
            The disk is full or read-only.
        """
        try:
            if dataset and self._taken(dataset):  # early answer; the reservation below decides
                raise DatasetExists(f"dataset {dataset!r} exists already; DELETE it first or choose another id")
            ident = self._reserve(dataset, name, checked.contours, checked.digest)
            path = self.upload_dir / f"{ident}-{uuid.uuid4().hex[:8]}.geojson"
            incoming.rename(path)
        except BaseException:
            incoming.unlink(missing_ok=True)
            raise
        job = BuildJob(
            kind="upload",
            store_path=str(self.settings.store_path),
            dataset=ident,
            source_path=str(path),
            name=name or ident,
            params=params.stored(checked.units),
            digest=checked.digest,
            workers=1,
        )
        try:
            self.builds.submit(job)
        except BuildQueueFull:
            self.store.delete_any(ident)
            path.unlink(missing_ok=True)
            raise
        return {
            "id": ident,
            "name": job.name,
            "state": "building",
            "contours": checked.contours,
            "bad_features": checked.bad_features,
            "bad_feature_list": checked.bad_feature_list,
            "href": f"/datasets/{ident}",
        }

    def _reserve(self, dataset: str | None, name: str | None, total: int, digest: str) -> str:
        if dataset:
            if not self.store.reserve(dataset, total):
                raise DatasetExists(
                    f"dataset {dataset!r} exists already; DELETE it first or choose another id"
                )
            return dataset
        # An id made from the name: uploading a file of the same name again makes name-2, name-3, ...
        base = (slugify(name) if name else f"upload-{digest[:10]}")[:60] or "upload"
        return self.store.reserve_free(base, total)

    def _taken(self, ident: str) -> bool:
        return self.store.data_version(ident) is not None or self._building(ident) is not None

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
        """id, name, state of every dataset (stored, uploaded or building).

        A stored dataset is ``ready`` (also while a newer version of it builds: it keeps serving); one not
        stored yet is ``building`` or, when its build failed, ``failed``. A configured source that was
        deleted is not listed (it is built again at the next start).
        """
        statuses = self.store.build_statuses()
        names = {s.dataset: s.name for s in self.specs}
        out: dict[str, dict[str, Any]] = {}
        for ident in self.store.dataset_ids():
            info = self.renderer.info(ident)[0]
            out[ident] = {"id": ident, "name": info.name, "state": "ready", "data_version": info.data_version}
        for ident in sorted(set(statuses) - set(out)):
            st = statuses[ident]
            state = "failed" if st.state == "failed" else "building"
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
        # Contours served without part of their build (no label, input geometry), each with its reason.
        out["contour_issues"], out["counts"]["contour_issues"] = self.store.contour_issues(dataset)
        return out

    def delete(self, dataset: str) -> None:
        """Remove a dataset, ready, building (its build is stopped) or failed (raises UnknownLayer if none)."""
        existed = self.store.delete_any(dataset)  # first: a build still running can no longer write it
        self.builds.cancel(dataset)
        self.renderer.forget(dataset)
        if not existed:
            raise UnknownLayer(f"unknown dataset {dataset!r}")

    def readiness(self) -> list[str]:
        """Why the service is not ready to serve and take uploads (empty when it is)."""
        problems = []
        try:
            self.store.probe_write()
        except StoreError as exc:
            problems.append(str(exc))
        if _read_only(self.upload_dir if self.upload_dir.is_dir() else self.upload_dir.parent):
            problems.append(f"the upload folder {self.upload_dir.name}/ is on a read-only file system")
        free = _free_bytes(self.settings.store_path.parent)
        if free is not None and free < self.settings.max_upload_bytes:
            problems.append(
                f"only {free >> 10} KiB free beside the store, less than one upload "
                f"({self.settings.max_upload_bytes >> 10} KiB, CCSM_MAX_UPLOAD_MB)"
            )
        for ident, st in sorted(self.store.build_statuses().items()):
            if st.state == "failed":
                problems.append(f"dataset {ident!r} failed to build: {st.error}")
            elif self.store.data_version(ident) is None:
                problems.append(f"dataset {ident!r} is being built ({st.done}/{st.total} contours)")
        return problems


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _free_bytes(folder: Path) -> int | None:
    try:
        usage = os.statvfs(folder)
    except OSError:
        return None
    return usage.f_bavail * usage.f_frsize


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

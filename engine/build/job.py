"""One dataset build in a process of its own: ``python -m engine.build.job`` reads a JSON job on stdin.

The service runs every build this way (``app/datasets/builds.py``): the memory a build takes returns to the system when
its process ends, a deleted dataset's build is stopped by ending its process group, and the server's
listening socket is never inherited (the process is started afresh, not forked from the server).

The job's dataset id was reserved in the store beforehand (a 'building' row). The build reports its progress
on that row and writes the dataset only while the row is there (:meth:`CCSStore.save` with
``only_if_building``): a dataset deleted during its build is never written.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import signal
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from engine.build.datasets import (
    RELIEF_DEM_KEY,
    SourceSpec,
    build_and_save,
    build_dataset,
    build_lock,
    read_scratch,
)
from engine.cartography.options import PARAMS_KEY, CartographyOptions
from engine.errors import BuildCancelled, CCSMError
from engine.io.source import Source, parse_source, read_source
from engine.io.tile_fetch import TileCache
from engine.parallel import lower_priority
from engine.store.store import CCSStore

log = logging.getLogger("ccsm.build")

#: Seconds between two progress writes to the store (each is a small write transaction).
PROGRESS_EVERY_S = 0.25
#: Seconds between two checks that the server that started the build is still there.
PARENT_CHECK_S = 1.0
#: Niceness a build adds to its own: when the cores are busy, the server's event loop and its map tiles (render
#: workers at 5) run first; a build is background work.
BUILD_NICENESS = 10


@dataclass(frozen=True)
class BuildJob:
    """What one build process does."""

    #: ``upload`` (a GeoJSON file written by the service, removed after the build) or ``source`` (a configured source,
    #: built under the store's build lock unless current).
    kind: str
    store_path: str
    dataset: str
    source_path: str
    name: str
    #: ``elevation_field``, ``interval``, ``source_scale``, ``target_scale``.
    params: dict[str, Any] = field(default_factory=dict)
    #: Content hash recorded with an upload (a source's is computed from its file).
    digest: str = ""
    workers: int | None = 1
    #: With ``source_path``, the source as :func:`engine.io.source.parse_source` takes it: its area and zoom
    #: (:func:`engine.io.source.source_arguments`).
    bbox: tuple[float, float, float, float] | None = None
    dem_zoom: int | None = None
    #: The folder a tile pyramid's fetched tiles are kept in (None: in memory only).
    tile_cache: str | None = None

    def to_json(self) -> str:
        """The job as the JSON line the build process reads."""
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> BuildJob:
        """Parse :meth:`to_json`'s output."""
        fields = json.loads(text)
        if fields.get("bbox") is not None:
            fields["bbox"] = tuple(fields["bbox"])
        return cls(**fields)

    def source(self) -> Source:
        """The source a ``source`` job builds."""
        return parse_source(
            self.source_path,
            bbox=self.bbox,
            dem_zoom=self.dem_zoom,
            source_scale=float(self.params.get("source_scale", 50_000.0)),
            tile_cache=TileCache(self.tile_cache) if self.tile_cache is not None else None,
        )


def _progress_reporter(store: CCSStore, dataset: str) -> Any:
    last = [0.0]

    def report(done: int, total: int) -> None:
        now = time.monotonic()
        if done in (0, total) or now - last[0] > PROGRESS_EVERY_S:
            last[0] = now
            if not store.update_build_progress(dataset, done, total):
                raise BuildCancelled(f"dataset {dataset!r} was deleted while it built")

    return report


def _client_message(job: BuildJob, exc: BaseException) -> str:
    """The error as a client may read it: the folder of the source cut away; a full disk said first."""
    text = str(exc).replace(str(Path(job.source_path).parent) + "/", "")[:1000]
    return f"disk full: {text}" if _disk_full(exc) else text


def _disk_full(exc: BaseException | None) -> bool:
    """Whether the exception, or one it was raised from, is the file system saying it has no room."""
    while exc is not None:
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if "disk is full" in str(exc).lower() or "no space left" in str(exc).lower():
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def run(job: BuildJob) -> int:
    """Build the job's dataset into the store; exit status 0 (built, current or cancelled) or 1 (failed)."""
    store = CCSStore(job.store_path)
    progress = _progress_reporter(store, job.dataset)
    try:
        if job.kind == "upload":
            with read_scratch(store) as scratch:
                contour_set = read_source(
                    Path(job.source_path),
                    elevation_field=job.params.get("elevation_field"),
                    interval=job.params.get("interval"),
                    scratch=scratch,
                )
                build_and_save(
                    store,
                    job.dataset,
                    contour_set,
                    name=job.name,
                    source="upload",
                    digest=job.digest,
                    params=job.params,
                    workers=job.workers,
                    progress=progress,
                    only_if_building=True,
                )
        else:
            fields = dict(job.params)
            if PARAMS_KEY in fields:  # the options travel as plain values; the spec takes the dataclass
                fields[PARAMS_KEY] = CartographyOptions.from_params(job.params)
            if fields.get(RELIEF_DEM_KEY):
                fields[RELIEF_DEM_KEY] = Path(fields[RELIEF_DEM_KEY])
            spec = SourceSpec(job.source(), job.dataset, job.name, **fields)
            with build_lock(Path(job.store_path)):
                progress(0, 0)  # cancelled while waiting for the lock: stop here
                _, rebuilt = build_dataset(
                    store, spec, workers=job.workers, progress=progress, only_if_building=True
                )
            if not rebuilt:  # another process built it meanwhile: drop the reservation
                store.clear_build_status(job.dataset)
        log.info("dataset %s built", job.dataset)
        return 0
    except BuildCancelled:
        log.info("build of %s stopped: the dataset was deleted", job.dataset)
        return 0
    except CCSMError as exc:
        log.warning("building %s failed: %s", job.dataset, ascii(str(exc)))
        store.fail_build(job.dataset, _client_message(job, exc))
        return 1
    except Exception as exc:
        log.exception("building %s failed", job.dataset)
        reason = _client_message(job, exc) if _disk_full(exc) else "build failed (see the service log)"
        store.fail_build(job.dataset, reason)
        return 1
    finally:
        if job.kind == "upload":
            Path(job.source_path).unlink(missing_ok=True)
        store.close()


def _die_with_parent() -> None:
    """End this build's process group once the server that started it is gone (even killed with SIGKILL).

    (Linux's PR_SET_PDEATHSIG would fire when the server *thread* that started the build ends, not the
    server, so the parent is watched instead.)
    """
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os.killpg(0, signal.SIGTERM)

    threading.Thread(target=watch, name="ccsm-parent-watch", daemon=True).start()


def main() -> None:
    """Entry point: one JSON job on stdin."""
    _die_with_parent()
    lower_priority(BUILD_NICENESS, idle=True)  # a core no map tile wants
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    sys.exit(run(BuildJob.from_json(sys.stdin.readline())))


if __name__ == "__main__":
    main()

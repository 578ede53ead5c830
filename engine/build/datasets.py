"""Building a source into the store: the one build-and-save path of ``ccsm build``, ``ccsm serve`` and uploads.

A dataset records the content hash of its source bytes and build parameters (:func:`source_hash`), so an
unchanged source is never rebuilt and a changed one always is.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import time
import unicodedata
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

from engine.build.labels import label_placer
from engine.build.records import contour_rows, dataset_meta
from engine.cartography.dataset import UPHILL_SIDE_KEY
from engine.cartography.options import PARAMS_KEY, CartographyOptions, check_schedule_fits
from engine.cartography.units import source_units
from engine.ccsm.build import BuiltSet, SpooledSet, build_into, build_pool
from engine.ccsm.ccs import CCS
from engine.ccsm.spool import surface_of
from engine.io.dem import DEM_SUFFIXES, source_uphill_side
from engine.io.source import Source, is_dem, read_source, source_file
from engine.parallel import map_ordered
from engine.params import BuildParams
from engine.payloads import FileSlice, fetched, opened
from engine.scratch import DiskSpool, ReadScratch
from engine.store.records import DatasetInfo
from engine.store.schema import STORE_FORMAT
from engine.store.shard import MergedShard, Shard, StageTarget, merge_on_worker, write_shard
from engine.store.store import CCSStore
from engine.types import Contour, ContourSet

Progress = Callable[[int, int], None]


def source_hash(
    path: str | os.PathLike[str] | Source | None, params: dict[str, Any], data: bytes | None = None
) -> str:
    """SHA-256 of a source's bytes (a file's content or ``data``), its build parameters and the store format.

    A URL or a tile pyramid is hashed by what it is (its location, area and zoom), not by its bytes: they are
    taken as unchanging (``--force`` rebuilds).
    """
    h = hashlib.sha256()
    h.update(f"ccsm-store-{STORE_FORMAT}\n".encode())
    h.update(json.dumps(params, sort_keys=True, default=str).encode())
    if path is not None and not isinstance(path, (str, os.PathLike)):
        h.update(path.identity().encode())
        path = source_file(path)
    if data is not None:
        h.update(data)
    elif path is not None:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


#: Key of the stored params that holds the path of the DEM to shade (see SourceSpec.relief_dem).
RELIEF_DEM_KEY = "relief_dem"


@dataclass(frozen=True)
class SourceSpec:
    """A source to build into the store and how to read it."""

    #: Contour file or DEM (anything :func:`engine.io.source.read_source` reads): a path, or a raster URL or tile
    #: pyramid as :func:`engine.io.source.parse_source` gives them.
    path: Source
    #: Dataset id in the store (``[a-z0-9_-]``).
    dataset: str
    #: Human name.
    name: str
    #: elevation_field, interval: passed to ``read_source`` (a DEM needs ``interval``).
    elevation_field: str | None = None
    interval: float | None = None
    #: source_scale, target_scale: scale denominators of t = 0 and t = 1.
    source_scale: float = 50_000.0
    target_scale: float = 500_000.0
    #: A DEM's window side in cells (see :func:`engine.io.dem.contours_from_dem`); None = chosen by size.
    block: int | None = None
    #: Units, index contours, attribute names and schedule override (docs/design.md section 9); None for the defaults
    #: (units then as the source states them, else metres).
    cartography: CartographyOptions | None = None
    #: A DEM to shade under the contours (docs/clients.md): the source itself when it is a DEM, or the DEM contours were
    #: traced from (the bundled sample's). Stored with the dataset as a path; not part of the content hash, since it
    #: changes no contour.
    relief_dem: Path | None = None

    def relief_path(self) -> Path | None:
        """The DEM to shade under this source's contours, or None."""
        if self.relief_dem is not None:
            return self.relief_dem
        if not isinstance(self.path, Path):
            return None  # a remote or windowed DEM: no relief is shaded from it
        return self.path if self.path.suffix.lower() in DEM_SUFFIXES else None

    def params(self) -> dict[str, Any]:
        """The parameters that decide the build (part of the content hash)."""
        params: dict[str, Any] = {
            "elevation_field": self.elevation_field,
            "interval": self.interval,
            "source_scale": self.source_scale,
            "target_scale": self.target_scale,
        }
        if self.block is not None:  # a DEM's window side decides the lines' ids; absent, older hashes hold
            params["block"] = self.block
        if self.cartography is not None:
            params[PARAMS_KEY] = self.cartography.checked().as_params()
        return params

    def stored_params(self) -> dict[str, Any]:
        """The parameters as stored with the dataset: :meth:`params` with the vertical unit resolved (given,
        else as the source states it, else metres), the side of higher ground of a DEM's traced lines
        (``uphill_side``), and the path of the DEM to shade (``relief_dem``), if any."""
        options = (self.cartography or CartographyOptions()).checked()
        if options.units is None:
            local = self.path if isinstance(self.path, Path) else source_file(self.path)
            units = (source_units(local, self.elevation_field) if local is not None else None) or "m"
            options = replace(options, units=units)
        stored = {**self.params(), PARAMS_KEY: options.as_params()}
        # Lines traced from a DEM (a file, a GeoTIFF URL, a tile pyramid) all keep higher ground on one side.
        uphill = source_uphill_side(self.path)
        if uphill is not None:
            stored[UPHILL_SIDE_KEY] = uphill
        relief = self.relief_path()
        if relief is not None:
            stored[RELIEF_DEM_KEY] = str(relief.resolve())
        return stored


_ID_CHARS = frozenset("abcdefghijklmnopqrstuvwxyz0123456789_-")


def slugify(text: str) -> str:
    """A dataset id from a name: ASCII lowercase letters, digits, ``_`` and ``-`` only (accents dropped,
    other scripts replaced), so an id is safe in a URL path and an HTTP header.

    >>> slugify("Jacksboro Contours 20m.geojson")
    'jacksboro-contours-20m-geojson'
    >>> slugify("Hügel 山")
    'hugel'
    """
    folded = unicodedata.normalize("NFKD", text.lower().strip()).encode("ascii", "ignore").decode("ascii")
    out = "".join(c if c in _ID_CHARS else "-" for c in folded)
    while "--" in out:
        out = out.replace("--", "-")
    return out.strip("-")[:64] or "dataset"


@contextmanager
def build_lock(store_path: Path) -> Iterator[None]:
    """An exclusive lock shared by every process using the store (held while a configured source builds)."""
    lock_path = store_path.with_name(store_path.name + ".build-lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@contextmanager
def read_scratch(store: CCSStore) -> Iterator[ReadScratch]:
    """A scratch file beside the store for a source being read and built, removed when the build ends (the
    contours it holds are read from it through the build: docs/design.md section 6)."""
    scratch = ReadScratch(Path(store.path).parent)
    try:
        yield scratch
    finally:
        scratch.close()


def is_current(store: CCSStore, spec: SourceSpec) -> bool:
    """True when the store holds ``spec``'s dataset built from the same bytes and parameters."""
    stored = store.source_hash_of(spec.dataset)
    return stored is not None and stored == source_hash(spec.path, spec.params())


def build_and_save(
    store: CCSStore,
    dataset: str,
    contour_set: ContourSet,
    *,
    name: str,
    source: str,
    digest: str,
    params: dict[str, Any],
    workers: int | None = None,
    progress: Progress | None = None,
    still_wanted: Callable[[], bool] | None = None,
    only_if_building: bool = False,
    executor: Executor | None = None,
) -> DatasetInfo | None:
    """Build every contour of a read source and write the dataset (made visible by one short switch).

    Parameters
    ----------
    params
        The build parameters (``source_scale``, ``target_scale``, ...), stored and part of ``digest``.
    still_wanted
        Asked once the build is done and before writing: False (the dataset was deleted meanwhile) skips the
        write and returns None.
    only_if_building
        Write only while the store still records this build (checked in the write transaction); raises
        BuildCancelled when the dataset was deleted meanwhile.
    executor
        Where the contours are built (a Dask cluster, see :mod:`engine.parallel`); None = ``workers``.

    Raises
    ------
    SourceError, InvalidParameter
        The parameters are invalid; the store is left as it was.
    """
    started = time.perf_counter()
    build_params = BuildParams(source_scale=params["source_scale"], target_scale=params["target_scale"])
    # The surfaces wait in a scratch file beside the store, not in memory (docs/design.md section 6).
    spool = DiskSpool(Path(store.path).parent)
    try:
        with build_pool(executor, workers, len(contour_set.contours)) as pool:
            built = build_into(spool, contour_set, build_params, workers=workers, progress=progress, executor=pool)
            if still_wanted is not None and not still_wanted():
                return None
            return save_built(
                store,
                dataset,
                built,
                name=name,
                source=source,
                digest=digest,
                params=params,
                build_seconds=time.perf_counter() - started,
                only_if_building=only_if_building,
                executor=pool,
            )
    finally:
        spool.close()


def save_built(
    store: CCSStore,
    dataset: str,
    built: BuiltSet | SpooledSet,
    *,
    name: str,
    source: str,
    digest: str,
    params: dict[str, Any],
    build_seconds: float = 0.0,
    only_if_building: bool = False,
    executor: Executor | None = None,
) -> DatasetInfo:
    """Write a built set as one dataset version, with its label anchors (placed for tiles up to the default
    maximum zoom, :mod:`engine.build.labels`).

    Rows are made batch by batch (:data:`SAVE_BATCH` contours) on ``executor`` (None: in this process) and
    written there into shards (:mod:`engine.store.shard`), each merged into the store in its bounded write
    transactions (:meth:`CCSStore.save`) by the worker that made it when that worker can open the store file,
    else by this process as it comes back; only a few shards are in memory at a time and no other write waits
    on the build. The label candidates are found on ``executor`` too, so that the save, like the build, goes
    faster with more workers.
    """
    meta = dataset_meta(
        built, name=name, source=source, source_hash=digest, params=params, build_seconds=build_seconds
    )
    labels = label_placer(store, executor=executor)

    def shards(target: StageTarget) -> Iterator[Shard | MergedShard]:
        return _shards_in_batches(built, None if executor is None else target, executor)

    return store.save(dataset, meta, shards, built.count, only_if_building=only_if_building, labels=labels)


#: Contours whose store rows are made, and written into one shard, by one task while a built set is written.
SAVE_BATCH = 256

#: Shard tasks in flight while a built set is written: each worker busy, few shards held.
SAVE_AHEAD = 4


def _shards_in_batches(
    built: BuiltSet | SpooledSet, target: StageTarget | None, executor: Executor | None = None
) -> Iterator[Shard | MergedShard]:
    """The store rows of ``built`` as shards of :data:`SAVE_BATCH` surfaces, written on ``executor`` and merged
    there into ``target`` when a worker can (None: all are merged by the caller), in the build's order (a
    spooled set reads only those batches of surfaces, as the spool keeps them, and of input contours; a worker
    that can read the spool's file is sent only where its surfaces lie)."""
    batches = built.payloads_in_batches(SAVE_BATCH, sliced=executor is not None)
    tasks = (
        (surfaces, built.working_crs, inputs, target, i * SAVE_BATCH) for i, (surfaces, inputs) in enumerate(batches)
    )
    yield from map_ordered(executor, batch_shard, tasks, SAVE_AHEAD, refetch=partial(_with_surfaces, built))


def _with_surfaces(built: BuiltSet | SpooledSet, task: tuple[Any, ...]) -> tuple[Any, ...]:
    """A shard's task sent again when its worker cannot read the spool's file: with the surfaces read here,
    and no task sliced from then on."""
    built.stop_slices()
    return (fetched(task[0]), *task[1:])


def batch_shard(
    payloads: Sequence[CCS | bytes | FileSlice],
    working_crs: str,
    inputs: Sequence[Contour | bytes],
    target: StageTarget | None = None,
    offset: int = 0,
) -> Shard | MergedShard:
    """One batch of surfaces as the spool keeps them, made into store rows (:func:`contour_rows`) and written
    into a shard: a task of a worker, which reads the surfaces where they lie in the spool's file when told so,
    opens them and their input contours (as the reader keeps them) itself, and merges the shard into ``target``
    when it can open the store file, as the ``offset``-th contours of the build
    (:func:`~engine.store.shard.merge_on_worker`), so the build process only counts."""
    surfaces = [surface_of(p) for p in fetched(payloads)]
    shard = write_shard(contour_rows(surfaces, working_crs, [opened(c) for c in inputs]))
    return shard if target is None else merge_on_worker(target, shard, offset)


def _reading_pool(
    spec: SourceSpec, executor: Executor | None, workers: int | None
) -> AbstractContextManager[Executor | None]:
    """Where a source is read and then built: the given executor; for a DEM without one, a local pool of
    ``workers`` processes (None: one per core) opened before the DEM is read, so that its levels or windows are
    traced in parallel and the same processes then build its contours; for a contour file, read in this
    process, None (its build opens its own pool, :func:`~engine.ccsm.build.build_pool`)."""
    if executor is not None or not is_dem(spec.path):
        return nullcontext(executor)
    return build_pool(None, workers, None)


def build_dataset(
    store: CCSStore,
    spec: SourceSpec,
    *,
    workers: int | None = None,
    progress: Progress | None = None,
    force: bool = False,
    only_if_building: bool = False,
    executor: Executor | None = None,
) -> tuple[DatasetInfo, bool]:
    """Read, build and store one source unless the store already holds it unchanged.

    ``executor`` traces a DEM and builds the contours (a Dask cluster, see :mod:`engine.parallel`); None =
    ``workers`` local processes, opened before a DEM is read (:func:`_reading_pool`). Either way the same code
    and the same stored rows.

    Returns
    -------
    (info, rebuilt)
        The stored dataset and whether it was (re)built now.

    Raises
    ------
    SourceError, InvalidParameter
        The source cannot be read or the parameters are invalid; the store is left as it was.
    """
    digest = source_hash(spec.path, spec.params())
    if not force and store.source_hash_of(spec.dataset) == digest:
        return store.dataset(spec.dataset), False
    BuildParams(source_scale=spec.source_scale, target_scale=spec.target_scale)  # bad scales fail before reading
    params = spec.stored_params()  # bad cartography options fail before reading too
    with read_scratch(store) as scratch, _reading_pool(spec, executor, workers) as executor:
        contour_set = read_source(
            spec.path,
            elevation_field=spec.elevation_field,
            interval=spec.interval,
            block=spec.block,
            executor=executor,
            scratch=scratch,
        )
        check_schedule_fits(spec.cartography, contour_set.interval, spec.source_scale)  # before anything is stored
        info = build_and_save(
            store,
            spec.dataset,
            contour_set,
            name=spec.name,
            source=spec.path.name,
            digest=digest,
            params=params,
            workers=workers,
            progress=progress,
            only_if_building=only_if_building,
            executor=executor,
        )
    assert info is not None  # no still_wanted callback: always written
    return info, True

"""Fetching the tiles of a pyramid: from a URL template, a folder template, a PMTiles or an MBTiles file;
concurrently, with retries, through a bounded cache.

Every failure is a :class:`~engine.errors.SourceError` that names the tile as ``z/x/y`` and where it was
looked for (its URL, file or archive), so a user can try that one tile by hand.
"""

from __future__ import annotations

import gzip
import hashlib
import os
import sqlite3
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol
from urllib.parse import unquote, urlparse

from engine.errors import SourceError

if TYPE_CHECKING:
    import httpx

#: Tiles fetched at once (threads: the work is waiting on the network or the disk).
FETCH_THREADS = 8

#: Tries of one tile when the network fails or the server is busy (5xx, 429), waiting 0.25 s, 0.5 s, ... between.
TRIES = 3
RETRY_WAIT_S = 0.25

#: Seconds to wait for a server to answer.
TIMEOUT_S = 30.0

#: Bytes of tiles a process keeps in memory (the most recently used); the disk cache has its own bound.
MEMORY_CACHE_BYTES = 64 << 20

#: Bytes of tiles the disk cache keeps when not told otherwise (the oldest removed first).
DISK_CACHE_BYTES = 2 << 30


class TileRef(NamedTuple):
    """A tile of a pyramid: zoom, column, row (XYZ: row 0 at the north)."""

    z: int
    x: int
    y: int


class TileReader(Protocol):
    """Where a pyramid's tiles are read from."""

    def where(self, ref: TileRef) -> str:
        """Where one tile is looked for (its URL or file), for messages."""
        ...

    def get(self, ref: TileRef) -> bytes:
        """The tile's bytes.

        Raises
        ------
        SourceError
            The tile is missing or cannot be read.
        """
        ...


def describe_tile(reader: TileReader, ref: TileRef) -> str:
    """``z/x/y (where)`` for messages."""
    return f"{ref.z}/{ref.x}/{ref.y} ({reader.where(ref)})"


def _fill(template: str, ref: TileRef) -> str:
    return template.replace("{z}", str(ref.z)).replace("{x}", str(ref.x)).replace("{y}", str(ref.y))


@dataclass(frozen=True)
class _Template:
    """Tiles each at its own place, the template's ``{z}``, ``{x}`` and ``{y}`` filled in."""

    template: str

    def where(self, ref: TileRef) -> str:
        """The tile's URL or file."""
        return _fill(self.template, ref)


class UrlTemplate(_Template):
    """Tiles at ``https://host/{z}/{x}/{y}.png``."""

    def get(self, ref: TileRef) -> bytes:
        """The tile's bytes, tried :data:`TRIES` times when the network fails or the server is busy."""
        url = self.where(ref)
        return http_get(url, f"tile {ref.z}/{ref.x}/{ref.y} ({url})")


class FolderTemplate(_Template):
    """Tiles in files at ``/path/{z}/{x}/{y}.png``."""

    def get(self, ref: TileRef) -> bytes:
        """The tile file's bytes."""
        path = self.where(ref)
        try:
            return Path(path).read_bytes()
        except FileNotFoundError:
            raise SourceError(f"tile {ref.z}/{ref.x}/{ref.y} ({path}): no such tile file") from None
        except OSError as exc:
            raise SourceError(f"tile {ref.z}/{ref.x}/{ref.y} ({path}): cannot read ({exc.strerror or exc})") from exc


@dataclass(frozen=True)
class _TileArchive:
    """A single file holding a pyramid's tiles: every tile is looked for in it, so messages name the archive."""

    location: str

    def where(self, ref: TileRef) -> str:
        """The archive."""
        return self.location

    def _label(self, ref: TileRef) -> str:
        return f"tile {ref.z}/{ref.x}/{ref.y} ({self.location})"


class PMTilesArchive(_TileArchive):
    """Tiles in a PMTiles v3 archive, a local file or a URL read by HTTP range requests."""

    def get(self, ref: TileRef) -> bytes:
        """The tile's bytes from the archive (decompressed when the archive says they are gzipped)."""
        from pmtiles.reader import Reader
        from pmtiles.tile import Compression

        label = self._label(ref)
        try:
            reader = Reader(_archive_bytes(self.location, label))
            data = reader.get(ref.z, ref.x, ref.y)
            compression = reader.header()["tile_compression"]
        except SourceError:
            raise
        except Exception as exc:  # the pmtiles reader raises bare exceptions on a damaged or foreign file
            raise SourceError(f"{label}: not a readable PMTiles archive ({exc})") from exc
        if data is None:
            raise SourceError(f"{label}: no such tile in the archive")
        return gzip.decompress(data) if compression == Compression.GZIP else bytes(data)


def _archive_bytes(location: str, label: str) -> Callable[[int, int], bytes]:
    """A byte-range reader of a local file or a URL (what the pmtiles reader asks for)."""
    if location.startswith(("http://", "https://")):

        def get_range(offset: int, length: int) -> bytes:
            return http_get(location, label, byte_range=(offset, offset + length - 1))

        return get_range
    path = _local_path(location)

    def read_range(offset: int, length: int) -> bytes:
        try:
            with open(path, "rb") as fh:
                fh.seek(offset)
                return fh.read(length)
        except OSError as exc:
            raise SourceError(f"{label}: cannot read ({exc.strerror or exc})") from exc

    return read_range


class MBTilesArchive(_TileArchive):
    """Tiles in an MBTiles (SQLite) file; its rows count from the south (TMS)."""

    def get(self, ref: TileRef) -> bytes:
        """The tile's bytes from the archive."""
        label = self._label(ref)
        path = _local_path(self.location)
        if not path.is_file():
            raise SourceError(f"{label}: no such MBTiles file")
        try:
            con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
            try:
                row = con.execute(
                    "SELECT tile_data FROM tiles WHERE zoom_level = ? AND tile_column = ? AND tile_row = ?",
                    (ref.z, ref.x, (1 << ref.z) - 1 - ref.y),
                ).fetchone()
            finally:
                con.close()
        except sqlite3.DatabaseError as exc:
            raise SourceError(f"{label}: not a readable MBTiles file ({exc})") from exc
        if row is None:
            raise SourceError(f"{label}: no such tile in the archive")
        data = bytes(row[0])
        return gzip.decompress(data) if data[:2] == b"\x1f\x8b" else data


def _local_path(location: str) -> Path:
    if location.startswith("file://"):
        return Path(unquote(urlparse(location).path))
    return Path(location).expanduser()


def open_tile_reader(location: str) -> TileReader:
    """The reader of a location: a PMTiles or MBTiles archive by its extension, else a ``{z}/{x}/{y}``
    template (a URL, or a folder, ``file://`` or a plain path).

    Raises
    ------
    SourceError
        A template without ``{z}``, ``{x}`` and ``{y}``.
    """
    lowered = location.lower().split("?")[0]
    if lowered.endswith(".pmtiles"):
        return PMTilesArchive(location)
    if lowered.endswith(".mbtiles"):
        return MBTilesArchive(location)
    if not all(part in location for part in ("{z}", "{x}", "{y}")):
        raise SourceError(
            f"{location!r}: a tile location is a template with {{z}}, {{x}} and {{y}}, or a .pmtiles or .mbtiles file"
        )
    if location.startswith(("http://", "https://")):
        return UrlTemplate(location)
    if location.startswith("file://"):
        return FolderTemplate(str(_local_path(location)))
    return FolderTemplate(str(Path(location).expanduser()))


_clients: dict[int, httpx.Client] = {}  # httpx is imported by the first fetch: a build from a file never needs it
_clients_lock = threading.Lock()


def _client() -> httpx.Client:
    """One HTTP client per process (it pools connections; worker processes make their own)."""
    import httpx

    pid = os.getpid()
    with _clients_lock:
        if pid not in _clients:
            _clients[pid] = httpx.Client(timeout=TIMEOUT_S, follow_redirects=True, headers={"User-Agent": "ccsm"})
        return _clients[pid]


def http_get(url: str, label: str, *, byte_range: tuple[int, int] | None = None) -> bytes:
    """The body of a GET (of a byte range when given), tried :data:`TRIES` times on network errors, 429 and 5xx.

    Raises
    ------
    SourceError
        Not found, refused, or still failing after the last try; the message starts with ``label``.
    """
    import httpx

    headers = {"Range": f"bytes={byte_range[0]}-{byte_range[1]}"} if byte_range is not None else {}
    problem = ""
    for attempt in range(TRIES):
        if attempt:
            time.sleep(RETRY_WAIT_S * 2 ** (attempt - 1))
        try:
            response = _client().get(url, headers=headers)
        except httpx.HTTPError as exc:
            problem = f"cannot fetch ({type(exc).__name__}: {exc})"
            continue
        if response.status_code in (200, 206):
            return response.content
        problem = f"HTTP {response.status_code} {response.reason_phrase}"
        if response.status_code != 429 and response.status_code < 500:
            break  # 404, 403...: asking again gives the same answer
    raise SourceError(f"{label}: {problem}" + (f" after {TRIES} tries" if "cannot fetch" in problem else ""))


class TileCache:
    """Tiles already fetched: the most recent :data:`MEMORY_CACHE_BYTES` in memory, and all of them in a folder
    when one is given, trimmed to ``disk_bytes`` (oldest first) by :meth:`trim`.

    Copied to a worker process as its folder only (each process keeps its own memory part).
    """

    def __init__(self, directory: str | os.PathLike[str] | None = None, disk_bytes: int = DISK_CACHE_BYTES) -> None:
        self.directory = Path(directory) if directory is not None else None
        self.disk_bytes = disk_bytes
        self._memory: OrderedDict[tuple[str, TileRef], bytes] = OrderedDict()
        self._held = 0
        self._lock = threading.Lock()

    def __getstate__(self) -> dict[str, Any]:
        return {"directory": self.directory, "disk_bytes": self.disk_bytes}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["directory"], state["disk_bytes"])  # type: ignore[misc]

    def _file(self, where: str) -> Path | None:
        if self.directory is None:
            return None
        digest = hashlib.sha256(where.encode()).hexdigest()
        return self.directory / digest[:2] / digest

    def get(self, reader: TileReader, ref: TileRef) -> bytes | None:
        """The tile when it was fetched before, else None."""
        key = (reader.where(ref) + f"#{ref.z}/{ref.x}/{ref.y}", ref)
        with self._lock:
            if key in self._memory:
                self._memory.move_to_end(key)
                return self._memory[key]
        path = self._file(key[0])
        if path is not None and path.is_file():
            data = path.read_bytes()
            self._remember(key, data)
            return data
        return None

    def put(self, reader: TileReader, ref: TileRef, data: bytes) -> None:
        """Keep a fetched tile (on disk atomically: a reader never sees half a tile)."""
        key = (reader.where(ref) + f"#{ref.z}/{ref.x}/{ref.y}", ref)
        self._remember(key, data)
        path = self._file(key[0])
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            part = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.part")
            part.write_bytes(data)
            part.replace(path)

    def _remember(self, key: tuple[str, TileRef], data: bytes) -> None:
        with self._lock:
            if key not in self._memory:
                self._memory[key] = data
                self._held += len(data)
            while self._held > MEMORY_CACHE_BYTES and len(self._memory) > 1:
                _, old = self._memory.popitem(last=False)
                self._held -= len(old)

    def trim(self) -> None:
        """Remove the oldest tile files until the folder holds at most ``disk_bytes``."""
        if self.directory is None or not self.directory.is_dir():
            return
        files = [(p.stat().st_mtime, p.stat().st_size, p) for p in self.directory.glob("*/*") if p.is_file()]
        total = sum(size for _, size, _ in files)
        for _, size, path in sorted(files):
            if total <= self.disk_bytes:
                break
            path.unlink(missing_ok=True)
            total -= size


def fetch_tiles(
    reader: TileReader,
    refs: Sequence[TileRef],
    *,
    cache: TileCache | None = None,
    threads: int = FETCH_THREADS,
    progress: Callable[[int, int], None] | None = None,
) -> dict[TileRef, bytes]:
    """The bytes of every tile, fetched ``threads`` at a time (those in ``cache`` are not fetched again).

    Raises
    ------
    SourceError
        The first tile that cannot be had (the others still running are let finish, none started after).
    """
    found: dict[TileRef, bytes] = {}
    wanted: list[TileRef] = []
    for ref in dict.fromkeys(refs):
        data = cache.get(reader, ref) if cache is not None else None
        if data is None:
            wanted.append(ref)
        else:
            found[ref] = data
    total, done = len(found) + len(wanted), len(found)
    if progress is not None:
        progress(done, total)

    def one(ref: TileRef) -> tuple[TileRef, bytes]:
        data = reader.get(ref)
        if cache is not None:
            cache.put(reader, ref, data)
        return ref, data

    for ref, data in _concurrently(one, wanted, threads):
        found[ref] = data
        done += 1
        if progress is not None:
            progress(done, total)
    return found


def _concurrently(
    task: Callable[[TileRef], tuple[TileRef, bytes]], refs: list[TileRef], threads: int
) -> Iterator[tuple[TileRef, bytes]]:
    """``task`` of every tile on ``threads`` threads, results as they finish; the first error stops the rest."""
    if len(refs) <= 1 or threads <= 1:
        yield from (task(ref) for ref in refs)
        return
    with ThreadPoolExecutor(max_workers=min(threads, len(refs))) as pool:
        pending = {pool.submit(task, ref) for ref in refs}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield future.result()  # raises the tile's error
        finally:
            for future in pending:
                future.cancel()

"""Static tile archives: PMTiles v3 and MBTiles 1.3 files of gzip-compressed vector tiles.

Both writers take tiles one at a time (``add``), already gzip-compressed, and write the archive to a temporary
file beside the target; ``commit`` renames it over the target, ``abort`` removes it. A failed or interrupted
export therefore never leaves a half-written archive, nor touches a file already at the target path.

- **PMTiles v3** through the ``pmtiles`` package's writer: tiles should arrive in tile-id order (Hilbert
  order within a zoom, :func:`tile_id`) so the archive is *clustered*; identical tiles are stored once.
  Bounds and centre go into the header in E7 units, the TileJSON-like metadata into its gzip JSON section.
- **MBTiles 1.3**: SQLite with the ``metadata`` (name/value) and ``tiles`` tables; rows are TMS, so the XYZ
  row ``y`` is stored as ``2^z - 1 - y``; the vector layers go into the ``json`` metadata row.
"""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, Protocol, cast

from pmtiles.tile import Compression, HeaderDict, TileType, serialize_header, zxy_to_tileid
from pmtiles.writer import Writer

from engine.errors import InvalidParameter

#: Archive formats by file extension.
FORMATS = {".pmtiles": "pmtiles", ".mbtiles": "mbtiles"}


@dataclass(frozen=True)
class ArchiveMeta:
    """What a tile archive says about its tiles (TileJSON terms)."""

    name: str
    minzoom: int
    maxzoom: int
    #: (west, south, east, north), degrees.
    bounds: tuple[float, float, float, float]
    #: (longitude, latitude, zoom).
    center: tuple[float, float, int]
    #: TileJSON ``vector_layers`` entries.
    vector_layers: list[dict[str, Any]]
    description: str = ""
    attribution: str = ""
    version: str = "1.0.0"
    format: str = "pbf"
    #: More members of the JSON metadata (e.g. ``ccsm_morph``).
    extra: dict[str, Any] = field(default_factory=dict)

    def tilejson(self) -> dict[str, Any]:
        """The metadata as one JSON object (PMTiles' metadata section)."""
        return {
            "name": self.name,
            "description": self.description,
            "attribution": self.attribution,
            "version": self.version,
            "type": "overlay",
            "format": self.format,
            "minzoom": self.minzoom,
            "maxzoom": self.maxzoom,
            "bounds": list(self.bounds),
            "center": list(self.center),
            "vector_layers": self.vector_layers,
            **self.extra,
        }


def archive_format(path: str | os.PathLike[str]) -> str:
    """``pmtiles`` or ``mbtiles`` from a file name's extension.

    >>> archive_format("out/alps.PMTiles")
    'pmtiles'

    Raises
    ------
    InvalidParameter
        Any other extension.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InvalidParameter(
            f"{Path(path).name}: unknown archive extension {suffix or '(none)'!r}; use .pmtiles or .mbtiles"
        )
    return FORMATS[suffix]


def tile_id(z: int, x: int, y: int) -> int:
    """PMTiles tile id of an XYZ tile: zoom by zoom, Hilbert order inside a zoom (the order to add tiles in)."""
    return int(zxy_to_tileid(z, x, y))


def e7(degrees: float) -> int:
    """Degrees as the integer 1e-7 degree units of a PMTiles header."""
    return int(round(degrees * 10_000_000))


class TileArchive(Protocol):
    """A tile archive being written: ``add`` every tile, then ``commit`` (or ``abort``)."""

    path: Path
    tiles: int

    def add(self, z: int, x: int, y: int, data: bytes) -> None:
        """Add one gzip-compressed MVT."""

    def commit(self, meta: ArchiveMeta) -> int:
        """Finish the archive, rename it to ``path``; returns its size in bytes."""

    def abort(self) -> None:
        """Drop the partial archive; ``path`` is left as it was."""


def _temporary_beside(path: Path) -> Path:
    """A temporary file name in the target's directory (so the final rename is atomic)."""
    return path.with_name(f".{path.name}.{os.getpid()}.part")


def _fsync(path: Path) -> None:
    """Flush a closed file to the disk before it is renamed into place."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _check_target(path: Path) -> Path:
    """The directory exists (created if need be) and the target is not a directory; raises InvalidParameter."""
    if path.is_dir():
        raise InvalidParameter(f"cannot write {path}: it is a directory")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidParameter(f"cannot write {path}: {exc.strerror or exc}") from None
    return _temporary_beside(path)


def check_writable(path: str | os.PathLike[str]) -> None:
    """Fail early, before any work, when an archive cannot be written at ``path`` (nothing is left behind).

    Raises
    ------
    InvalidParameter
        Unknown extension, a directory, or the directory cannot be created or written.
    """
    archive_format(path)
    tmp = _check_target(Path(path))
    try:
        with open(tmp, "wb"):
            pass
    except OSError as exc:
        raise InvalidParameter(f"cannot write {path}: {exc.strerror or exc}") from None
    tmp.unlink(missing_ok=True)


class _ArchiveWriter:
    """What both archive writers do alike: count the tiles added, refuse to commit none, give the size.

    A writer puts a tile with ``_put`` and finishes the temporary file and renames it over ``path`` with
    ``_finish`` (calling ``abort`` itself if that fails).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.tmp = _check_target(self.path)
        self.tiles = 0

    def add(self, z: int, x: int, y: int, data: bytes) -> None:
        """Add one gzip-compressed MVT (in tile-id order for a clustered PMTiles archive)."""
        self._put(z, x, y, data)
        self.tiles += 1

    def commit(self, meta: ArchiveMeta) -> int:
        """Write what the format keeps beside the tiles, then rename over ``path``; returns the size in bytes."""
        if self.tiles == 0:
            self.abort()
            raise InvalidParameter(f"nothing to write to {self.path.name}: every tile is empty")
        self._finish(meta)
        return self.path.stat().st_size

    def abort(self) -> None:
        """Close and remove the temporary file."""
        raise NotImplementedError

    def _put(self, z: int, x: int, y: int, data: bytes) -> None:
        raise NotImplementedError

    def _finish(self, meta: ArchiveMeta) -> None:
        raise NotImplementedError


class PMTilesArchive(_ArchiveWriter):
    """A PMTiles v3 archive being written (see the module docstring): gzip-compressed MVT tiles, or with
    ``png=True`` PNG images as they are (PNG is compressed already)."""

    def __init__(self, path: str | os.PathLike[str], *, png: bool = False) -> None:
        super().__init__(path)
        self.png = png
        try:
            self._file: BinaryIO = open(self.tmp, "wb")  # noqa: SIM115 - closed by commit/abort
        except OSError as exc:
            raise InvalidParameter(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._writer = Writer(self._file)

    def _put(self, z: int, x: int, y: int, data: bytes) -> None:
        self._writer.write_tile(tile_id(z, x, y), data)

    def _finish(self, meta: ArchiveMeta) -> None:
        # Directories, metadata and header.
        west, south, east, north = meta.bounds
        header: dict[str, Any] = {
            "tile_type": TileType.PNG if self.png else TileType.MVT,
            "tile_compression": Compression.NONE if self.png else Compression.GZIP,
            "min_lon_e7": e7(west),
            "min_lat_e7": e7(south),
            "max_lon_e7": e7(east),
            "max_lat_e7": e7(north),
            "center_zoom": int(meta.center[2]),
            "center_lon_e7": e7(meta.center[0]),
            "center_lat_e7": e7(meta.center[1]),
        }
        try:
            self._writer.finalize(header, meta.tilejson())
            # The writer sets the zoom range to that of the tiles it got; the header states the range exported
            # (the MBTiles metadata and TileJSON do too), so write it again with that range.
            header["min_zoom"], header["max_zoom"] = meta.minzoom, meta.maxzoom
            self._file.seek(0)
            self._file.write(serialize_header(cast(HeaderDict, header)))
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            os.replace(self.tmp, self.path)
        except OSError as exc:
            self.abort()
            raise InvalidParameter(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def abort(self) -> None:
        """Close and remove the temporary file."""
        with contextlib.suppress(OSError):
            self._file.close()
        with contextlib.suppress(OSError):
            self._writer.tile_f.close()
        self.tmp.unlink(missing_ok=True)


_MBTILES_SCHEMA = """
CREATE TABLE metadata (name TEXT NOT NULL, value TEXT);
CREATE UNIQUE INDEX metadata_name ON metadata (name);
CREATE TABLE tiles (zoom_level INTEGER NOT NULL, tile_column INTEGER NOT NULL, tile_row INTEGER NOT NULL,
                    tile_data BLOB NOT NULL);
CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row);
"""


def tms_row(z: int, y: int) -> int:
    """The TMS row of MBTiles (row 0 at the south edge) of an XYZ row ``y`` (row 0 at the north edge).

    >>> tms_row(3, 0), tms_row(3, 7)
    (7, 0)
    """
    return (1 << z) - 1 - y


class MBTilesArchive(_ArchiveWriter):
    """An MBTiles 1.3 file of gzip-compressed MVT tiles being written (see the module docstring)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(path)
        try:
            self.tmp.unlink(missing_ok=True)
            self._con = sqlite3.connect(self.tmp, isolation_level=None)
            self._con.execute("PRAGMA journal_mode=OFF")  # a new temporary file: nothing to roll back to
            self._con.execute("PRAGMA synchronous=OFF")
            self._con.executescript(_MBTILES_SCHEMA)
            self._con.execute("BEGIN")
        except (OSError, sqlite3.Error) as exc:
            self.tmp.unlink(missing_ok=True)
            raise InvalidParameter(f"cannot write {self.path}: {exc}") from None

    def _put(self, z: int, x: int, y: int, data: bytes) -> None:
        self._con.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x, tms_row(z, y), data))  # its TMS row

    def _finish(self, meta: ArchiveMeta) -> None:
        # The metadata table, then close.
        west, south, east, north = meta.bounds
        rows = {
            "name": meta.name,
            "format": "pbf",
            "type": "overlay",
            "version": meta.version,
            "description": meta.description,
            "attribution": meta.attribution,
            "bounds": f"{west},{south},{east},{north}",
            "center": f"{meta.center[0]},{meta.center[1]},{meta.center[2]}",
            "minzoom": str(meta.minzoom),
            "maxzoom": str(meta.maxzoom),
            "json": json.dumps({"vector_layers": meta.vector_layers, **meta.extra}, separators=(",", ":")),
        }
        try:
            self._con.executemany("INSERT INTO metadata VALUES (?, ?)", rows.items())
            self._con.execute("COMMIT")
            self._con.close()
            _fsync(self.tmp)
            os.replace(self.tmp, self.path)
        except (OSError, sqlite3.Error) as exc:
            self.abort()
            raise InvalidParameter(f"cannot write {self.path}: {exc}") from None

    def abort(self) -> None:
        """Close and remove the temporary file."""
        with contextlib.suppress(sqlite3.Error):
            self._con.close()
        self.tmp.unlink(missing_ok=True)


def open_archive(path: str | os.PathLike[str]) -> TileArchive:
    """A new archive writer for ``path``, PMTiles or MBTiles by its extension.

    Raises
    ------
    InvalidParameter
        Unknown extension, or the target cannot be written.
    """
    if archive_format(path) == "pmtiles":
        return PMTilesArchive(path)
    return MBTilesArchive(path)

"""Scratch files of a build in progress: files beside the store that hold what the build has read or made
until it is written, so a build's memory does not grow with the dataset (docs/design.md section 6).

This is the one home of the mechanism. A SQLite scratch file holds **named lists of pickled objects** by
position (:class:`ReadScratch`); a reader appends to its lists and reads them back in order (a DEM's traced
levels, a vector source's checked batches, the usable contours as :class:`ScratchContours`). A build keeps its
surfaces by number in a file of their pickles, appended and read back where they lie (:class:`DiskSpool`, the
on-disk form of ``engine.ccsm.spool.Spool``): the crossing repair reads each surface a few times, at random.
What stays elsewhere is not a second copy: ``engine.ccsm.spool`` holds only the method's protocol and its
in-memory form (the method may not touch files), and opens what :meth:`DiskSpool.get_payloads` sends.

A scratch file is not the store: no server reads it, it is written without a journal or fsync (a killed build
only leaves it to be removed) and it is deleted when the build ends. Its name carries the host and process
id of the build that writes it, so the next build in that directory removes one whose build no longer runs.
"""

from __future__ import annotations

import os
import pickle
import sqlite3
import tempfile
from array import array
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, overload

from engine.errors import StoreError
from engine.payloads import FileSlice, pickled
from engine.types import Contour

#: Name prefix of scratch files, followed by the host and the process id of the build that writes it.
SCRATCH_PREFIX = ".ccsm-spool-"
#: Rows read per SQL statement (SQLite's default limit on bound parameters is 32,766).
READ_BATCH = 500


def host_name() -> str:
    """This machine's name, as builds record it."""
    return os.uname().nodename if hasattr(os, "uname") else "localhost"


def pid_alive(pid: int) -> bool:
    """Whether a process of this id runs on this machine (one we may not signal counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


#: Endings of scratch files: a SQLite file of lists (:class:`ReadScratch`), a file of surfaces (:class:`DiskSpool`).
SCRATCH_SUFFIXES = (".sqlite", ".spool")


def remove_stale_scratch(directory: str | os.PathLike[str]) -> list[Path]:
    """Remove the scratch files of this host's builds that no longer run; the paths removed."""
    removed = []
    for path in sorted(Path(directory).glob(f"{SCRATCH_PREFIX}{host_name()}-*")):
        pid = path.name[len(SCRATCH_PREFIX) + len(host_name()) + 1 :].split("-", 1)[0]
        if path.suffix in SCRATCH_SUFFIXES and pid.isdigit() and not pid_alive(int(pid)):
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def new_scratch_file(directory: str | os.PathLike[str], suffix: str) -> tuple[int, Path]:
    """A new empty scratch file in ``directory`` (stale ones removed first), open for reading and writing: its
    descriptor and path.

    Raises
    ------
    StoreError
        The file cannot be made there (a missing or read-only directory, a full disk).
    """
    remove_stale_scratch(directory)
    prefix = f"{SCRATCH_PREFIX}{host_name()}-{os.getpid()}-"
    try:
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=directory)
    except OSError as exc:
        raise StoreError(f"cannot make the build's scratch file in {directory}: {exc.strerror}") from exc
    return fd, Path(name)


def open_scratch(directory: str | os.PathLike[str], schema: str) -> tuple[Path, sqlite3.Connection]:
    """A new scratch file in ``directory`` with the tables of ``schema`` (stale ones removed first).

    Raises
    ------
    StoreError
        The file cannot be made there (a missing or read-only directory, a full disk).
    """
    fd, name = new_scratch_file(directory, ".sqlite")
    os.close(fd)
    con = sqlite3.connect(name)
    # Scratch data: no journal, no fsync. A crash loses only this file, which nothing else reads.
    con.executescript(f"PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF; PRAGMA cache_size=-16000; {schema}")
    return Path(name), con


class ReadScratch:
    """A scratch file in ``directory`` of named lists of objects (pickled) by position: appended to, and read
    back in order or at given positions.

    Raises
    ------
    StoreError
        The file cannot be made or written (a read-only directory, a full disk).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     scratch = ReadScratch(d)
    ...     scratch.extend("a", ["x", "y", "z"])
    ...     scratch.extend("a", ["w"])
    ...     list(scratch.read("a")), scratch.count("a"), scratch.read_range("a", 1, 3), scratch.count("b")
    ...     scratch.close()
    (['x', 'y', 'z', 'w'], 4, ['y', 'z'], 0)
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.path: Path
        self.path, self._con = open_scratch(
            directory, "CREATE TABLE items (list TEXT, seq INTEGER, blob BLOB NOT NULL, PRIMARY KEY (list, seq));"
        )
        self._counts: dict[str, int] = {}

    def _insert(self, rows: list[tuple[str, int, bytes]]) -> None:
        try:
            self._con.executemany("INSERT OR REPLACE INTO items VALUES (?, ?, ?)", rows)
        except sqlite3.OperationalError as exc:  # a full disk, mostly
            raise StoreError(f"the build's scratch file {self.path.name}: {exc}") from exc

    def extend(self, name: str, objects: Iterable[Any]) -> None:
        """Append ``objects`` to list ``name``."""
        start = self._counts.get(name, 0)
        rows = [(name, start + k, pickled(o)) for k, o in enumerate(objects)]
        self._insert(rows)
        self._counts[name] = start + len(rows)

    def count(self, name: str) -> int:
        """One past the last position of list ``name`` (its length when filled in order)."""
        return self._counts.get(name, 0)

    def read_range(self, name: str, start: int, stop: int) -> list[Any]:
        """Objects ``start`` .. ``stop`` - 1 of list ``name``."""
        return [pickle.loads(blob) for blob in self.range_payloads(name, start, stop)]

    def range_payloads(self, name: str, start: int, stop: int) -> list[bytes]:
        """Objects ``start`` .. ``stop`` - 1 of list ``name`` as stored (pickles, for a worker to open)."""
        rows = self._con.execute(
            "SELECT blob FROM items WHERE list = ? AND seq >= ? AND seq < ? ORDER BY seq", (name, start, stop)
        )
        return [blob for (blob,) in rows]

    def read(self, name: str, batch: int = READ_BATCH) -> Iterator[Any]:
        """Every object of list ``name`` in order, ``batch`` read at a time (1 for big objects)."""
        for start in range(0, self.count(name), batch):
            yield from self.read_range(name, start, start + batch)

    def payloads(self, name: str, positions: Sequence[int]) -> list[bytes]:
        """The objects at ``positions`` of list ``name`` as stored (pickles), in that order.

        Raises
        ------
        KeyError
            A position holds nothing.
        """
        wanted = [int(i) for i in positions]
        found: dict[int, bytes] = {}
        for start in range(0, len(wanted), READ_BATCH):
            batch = sorted(set(wanted[start : start + READ_BATCH]) - found.keys())
            marks = ",".join("?" * len(batch))
            sql = f"SELECT seq, blob FROM items WHERE list = ? AND seq IN ({marks})"
            for i, blob in self._con.execute(sql, (name, *batch)):
                found[int(i)] = blob
        missing = [i for i in wanted if i not in found]
        if missing:
            raise KeyError(f"not in the scratch list {name!r}: {missing[:5]}")
        return [found[i] for i in wanted]

    def drop(self, name: str) -> None:
        """Forget list ``name`` (its space is reused by later lists)."""
        self._con.execute("DELETE FROM items WHERE list = ?", (name,))
        self._counts.pop(name, None)

    def close(self) -> None:
        """Delete the file."""
        self._con.close()
        self.path.unlink(missing_ok=True)


class ScratchContours(Sequence[Contour]):
    """The contours of list ``name`` of a :class:`ReadScratch`, as a read-only sequence: each read when asked
    (a slice in one statement), iterated a batch at a time."""

    def __init__(self, scratch: ReadScratch, name: str) -> None:
        self.scratch = scratch
        self.name = name

    def __len__(self) -> int:
        return self.scratch.count(self.name)

    @overload
    def __getitem__(self, index: int) -> Contour: ...

    @overload
    def __getitem__(self, index: slice) -> list[Contour]: ...

    def __getitem__(self, index: int | slice) -> Contour | list[Contour]:
        n = len(self)
        if isinstance(index, slice):
            start, stop, step = index.indices(n)
            items = self.scratch.read_range(self.name, start, stop) if step > 0 and start < stop else []
            return items[::step] if step != 1 else items
        k = index + n if index < 0 else index
        if not 0 <= k < n:
            raise IndexError(f"contour {index} of {n}")
        return self.scratch.read_range(self.name, k, k + 1)[0]

    def __iter__(self) -> Iterator[Contour]:
        return self.scratch.read(self.name)

    def payloads(self, indices: Sequence[int]) -> list[bytes]:
        """Contours ``indices`` as stored (pickles): what a task takes to a worker unopened
        (``engine.types.contour_payloads``); a run of consecutive ones in one range read."""
        wanted = [int(i) for i in indices]
        if not wanted:
            return []
        if wanted == list(range(wanted[0], wanted[0] + len(wanted))):
            return self.scratch.range_payloads(self.name, wanted[0], wanted[-1] + 1)
        return self.scratch.payloads(self.name, wanted)


#: Surfaces written by one ``pwritev`` call (Linux takes at most 1,024 buffers a call).
WRITE_BUFFERS = 512


class DiskSpool:
    """A build's surfaces by number, in a scratch file in ``directory`` (the store's, so on the same disk): the
    ``engine.ccsm.spool.Spool`` protocol. Each surface's pickle is appended to the file and where it lies
    (offset, length) is kept in memory, 16 bytes a surface; a surface put again is appended anew (the repair
    rebuilds a few per cent of the surfaces, whose old bytes stay unread until the file goes). Read back one
    ``pread`` a surface: the repair reads each surface a few times, and a blob read from SQLite had cost three
    times as much (its pages walked and copied).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     spool = DiskSpool(d)
    ...     spool.put(3, "surface")
    ...     spool.get([3, 3]), spool.path.exists()
    ...     spool.close()
    ...     spool.path.exists()
    (['surface', 'surface'], True)
    False
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self._fd, self.path = new_scratch_file(directory, ".spool")
        self._end = 0  # bytes written
        # Where each number's pickle lies; length -1: nothing kept under that number.
        self._offset = array("q")
        self._length = array("q")
        self._sliced = True  # workers are sent where surfaces lie until one cannot read the file

    def put(self, index: int, surface: Any) -> None:  # noqa: D102
        self.put_many([(index, surface)])

    def put_many(self, items: Iterable[tuple[int, Any]]) -> None:
        """Keep several surfaces in one write."""
        self.put_payloads((i, pickled(s)) for i, s in items)

    #: Surfaces are kept as pickles: a worker sends them back pickled (``engine.payloads.pickled``).
    keeps_pickles = True

    def put_payloads(self, items: Iterable[tuple[int, Any]]) -> None:
        """Keep several surfaces a worker has pickled (bytes), as they are, in one write."""
        pairs = [(int(i), blob) for i, blob in items]
        at = self._end
        for k in range(0, len(pairs), WRITE_BUFFERS):  # pwritev takes at most IOV_MAX buffers
            blobs = [blob for _, blob in pairs[k : k + WRITE_BUFFERS]]
            size = sum(len(b) for b in blobs)
            try:
                written = os.pwritev(self._fd, blobs, at)
            except OSError as exc:  # a full disk, mostly
                raise StoreError(f"the build's scratch file {self.path.name}: {exc.strerror}") from exc
            if written != size:
                raise StoreError(f"the build's scratch file {self.path.name}: {written} of {size} bytes written")
            at += size
        top = max((i for i, _ in pairs), default=-1) + 1
        if top > len(self._length):
            self._offset.extend([0] * (top - len(self._offset)))
            self._length.extend([-1] * (top - len(self._length)))
        for i, blob in pairs:
            self._offset[i], self._length[i] = self._end, len(blob)
            self._end += len(blob)

    def get(self, indices: Sequence[int]) -> list[Any]:  # noqa: D102
        return [pickle.loads(blob) for blob in self.get_payloads(indices)]

    def get_payloads(self, indices: Sequence[int]) -> list[bytes]:
        """The surfaces numbered ``indices`` as stored (pickles): sent to a worker as they are, so this process
        neither unpickles nor pickles them again (``engine.ccsm.spool.surface_of`` opens them there).

        Raises
        ------
        KeyError
            A number holds nothing.
        """
        wanted = [int(i) for i in indices]
        kept = len(self._length)
        missing = [i for i in wanted if not 0 <= i < kept or self._length[i] < 0]
        if missing:
            raise KeyError(f"not in the spool: {missing[:5]}")
        return [os.pread(self._fd, self._length[i], self._offset[i]) for i in wanted]

    def get_slices(self, indices: Sequence[int]) -> list[FileSlice] | None:
        """Where the surfaces numbered ``indices`` lie in the file (each pickle is written once and never
        moved, so a slice stays valid after its number is put again), for a worker on this machine or disk to
        read them itself (``engine.payloads.fetched``): this process then reads and sends none of their bytes.
        None after :meth:`stop_slices`.

        Raises
        ------
        KeyError
            A number holds nothing.
        """
        if not self._sliced:
            return None
        wanted = [int(i) for i in indices]
        kept = len(self._length)
        missing = [i for i in wanted if not 0 <= i < kept or self._length[i] < 0]
        if missing:
            raise KeyError(f"not in the spool: {missing[:5]}")
        path = os.path.abspath(self.path)  # a worker may run in another directory
        return [FileSlice(path, self._offset[i], self._length[i]) for i in wanted]

    def stop_slices(self) -> None:
        """Send the surfaces themselves from now on (a worker could not read the file)."""
        self._sliced = False

    def close(self) -> None:
        """Delete the file."""
        os.close(self._fd)
        self.path.unlink(missing_ok=True)

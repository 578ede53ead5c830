"""Where a big source waits while it is read: lists of pickled objects in a scratch file (:mod:`engine.scratch`),
appended in order and read back in order or by position.

A DEM traced window by window keeps each level's pieces here until the level is joined, the joined and
checked lines wait here until the working CRS is chosen from all of them, and the usable contours stay here
through the build (:class:`ScratchContours`), so reading holds one level or batch at a time, not the source.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, overload

from engine.scratch import open_scratch
from engine.types import Contour

#: Rows read per SQL statement.
READ_BATCH = 512


class ReadScratch:
    """A scratch file of named lists of objects (pickled), each appended to and read back in order.

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

    def extend(self, name: str, objects: Iterable[Any]) -> None:
        """Append ``objects`` to list ``name``."""
        start = self._counts.get(name, 0)
        rows = [(name, start + k, pickle.dumps(o, protocol=pickle.HIGHEST_PROTOCOL)) for k, o in enumerate(objects)]
        self._con.executemany("INSERT INTO items VALUES (?, ?, ?)", rows)
        self._counts[name] = start + len(rows)

    def count(self, name: str) -> int:
        """Objects in list ``name``."""
        return self._counts.get(name, 0)

    def read_range(self, name: str, start: int, stop: int) -> list[Any]:
        """Objects ``start`` .. ``stop`` - 1 of list ``name``."""
        rows = self._con.execute(
            "SELECT blob FROM items WHERE list = ? AND seq >= ? AND seq < ? ORDER BY seq", (name, start, stop)
        )
        return [pickle.loads(blob) for (blob,) in rows]

    def read(self, name: str, batch: int = READ_BATCH) -> Iterator[Any]:
        """Every object of list ``name`` in order, ``batch`` read at a time (1 for big objects)."""
        for start in range(0, self.count(name), batch):
            yield from self.read_range(name, start, start + batch)

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

"""A scratch file for the surfaces of a build in progress (a :class:`~engine.ccsm.spool.Spool` on disk).

The build writes each surface here as it is made and reads back one block or batch at a time, so its memory
does not grow with the dataset (docs/design.md section 6). It is a scratch file of :mod:`engine.scratch`:
no journal, no fsync, deleted when the build ends, and removed by the next build if its own was killed.
"""

from __future__ import annotations

import os
import pickle
import sqlite3
from collections.abc import Iterable, Sequence

from engine.ccsm.ccs import CCS
from engine.errors import StoreError
from engine.scratch import open_scratch

#: Surfaces read per SQL statement (SQLite's default limit on bound parameters is 32,766).
READ_BATCH = 500


class DiskSpool:
    """Surfaces pickled into a scratch SQLite file in ``directory`` (the store's, so it is on the same disk);
    scratch files of builds that no longer run are removed first.

    >>> import numpy as np, tempfile
    >>> s = CCS("a", 10.0, False, np.zeros((2, 2)), np.ones((2, 2)), np.zeros(1), np.ones(1), 1.0, 2, 2)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     spool = DiskSpool(d)
    ...     spool.put(3, s)
    ...     [c.contour_id for c in spool.get([3, 3])], spool.path.exists()
    ...     spool.close()
    ...     spool.path.exists()
    (['a', 'a'], True)
    False
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.path, self._con = open_scratch(
            directory, "CREATE TABLE surfaces (i INTEGER PRIMARY KEY, blob BLOB NOT NULL);"
        )

    def put(self, index: int, surface: CCS) -> None:  # noqa: D102
        self.put_many([(index, surface)])

    def put_many(self, items: Iterable[tuple[int, CCS]]) -> None:
        """Keep several surfaces in one statement."""
        try:
            self._con.executemany(
                "INSERT OR REPLACE INTO surfaces VALUES (?, ?)",
                ((int(i), pickle.dumps(s, protocol=pickle.HIGHEST_PROTOCOL)) for i, s in items),
            )
        except sqlite3.OperationalError as exc:  # a full disk, mostly
            raise StoreError(f"the build's scratch file {self.path.name}: {exc}") from exc

    def get(self, indices: Sequence[int]) -> list[CCS]:  # noqa: D102
        return [pickle.loads(blob) for blob in self.get_payloads(indices)]

    def get_payloads(self, indices: Sequence[int]) -> list[bytes]:
        """The surfaces numbered ``indices`` as stored (pickles): sent to a worker as they are, so this process
        neither unpickles nor pickles them again (``engine.ccsm.spool.surface_of`` opens them there)."""
        wanted = [int(i) for i in indices]
        found: dict[int, bytes] = {}
        for start in range(0, len(wanted), READ_BATCH):
            batch = sorted(set(wanted[start : start + READ_BATCH]) - found.keys())
            marks = ",".join("?" * len(batch))
            for i, blob in self._con.execute(f"SELECT i, blob FROM surfaces WHERE i IN ({marks})", batch):
                found[int(i)] = blob
        missing = [i for i in wanted if i not in found]
        if missing:
            raise KeyError(f"surfaces not in the spool: {missing[:5]}")
        return [found[i] for i in wanted]

    def close(self) -> None:  # noqa: D102
        self._con.close()
        self.path.unlink(missing_ok=True)

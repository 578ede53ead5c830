"""Where a build keeps the surfaces it has made until they are written (docs/design.md section 6).

A small build keeps them in memory (:class:`MemorySpool`). A big one keeps them in a scratch file beside the
store (``engine.scratch.DiskSpool``), so the build's memory holds only the surfaces of the chunk, block or
batch at hand, whatever the size of the set: the crossing repair reads back one block's surfaces at a time,
and the store is written batch by batch from the spool. The method only knows the :class:`Spool` protocol.

Only the protocol and the in-memory form live here: the disk form is a list of the one scratch-file mechanism
(:mod:`engine.scratch`), which the method may not import (it touches no SQLite; an import contract says so).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Protocol

from engine.ccsm.ccs import CCS
from engine.payloads import FileSlice, opened


class Spool(Protocol):
    """Built surfaces by their index in the build (0, 1, ... in input order)."""

    def put(self, index: int, surface: CCS) -> None:
        """Keep ``surface`` as number ``index``, replacing any surface kept under that number."""

    def put_many(self, items: Iterable[tuple[int, CCS]]) -> None:
        """Keep several (number, surface) at once."""

    def get(self, indices: Sequence[int]) -> list[CCS]:
        """The surfaces numbered ``indices``, in that order."""

    def get_payloads(self, indices: Sequence[int]) -> Sequence[CCS | bytes]:
        """The same surfaces in the form they are kept, for a worker to open with :func:`surface_of`."""

    #: Whether the spool keeps pickles: then a worker sends its surfaces back pickled
    #: (``engine.payloads.pickled``) and :meth:`put_payloads` keeps them as they come.
    keeps_pickles: bool

    def put_payloads(self, items: Iterable[tuple[int, CCS | bytes]]) -> None:
        """Keep several (number, surface) in the form the spool keeps them (see :attr:`keeps_pickles`)."""

    def get_slices(self, indices: Sequence[int]) -> list[FileSlice] | None:
        """Where the surfaces ``indices`` lie in the spool's file, for a worker to read them itself; None when
        they are in no file, or after :meth:`stop_slices`."""

    def stop_slices(self) -> None:
        """From now on :meth:`get_slices` gives None: a worker could not read the file (another machine)."""

    def close(self) -> None:
        """Free what the spool holds."""


class MemorySpool:
    """Surfaces held in memory: for sets small enough to hold (simplify, evaluate, tests)."""

    def __init__(self) -> None:
        self._surfaces: dict[int, CCS] = {}

    def put(self, index: int, surface: CCS) -> None:  # noqa: D102
        self._surfaces[index] = surface

    def put_many(self, items: Iterable[tuple[int, CCS]]) -> None:  # noqa: D102
        self._surfaces.update(items)

    def get(self, indices: Sequence[int]) -> list[CCS]:  # noqa: D102
        return [self._surfaces[int(i)] for i in indices]

    def get_payloads(self, indices: Sequence[int]) -> list[CCS]:  # noqa: D102
        return self.get(indices)

    keeps_pickles = False

    def put_payloads(self, items: Iterable[tuple[int, CCS | bytes]]) -> None:  # noqa: D102
        self._surfaces.update((i, surface_of(p)) for i, p in items)

    def get_slices(self, indices: Sequence[int]) -> None:  # noqa: D102
        return None

    def stop_slices(self) -> None:  # noqa: D102
        pass

    def close(self) -> None:  # noqa: D102
        self._surfaces.clear()


def surface_of(payload: CCS | bytes) -> CCS:
    """A surface from what :meth:`Spool.get_payloads` gave (a pickle from a spool on disk)."""
    return opened(payload)

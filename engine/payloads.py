"""What a build forwards without opening: an object's pickle, opened where it is used.

The build process is the hub of a build's data: it reads contours from the reader's scratch file and sends
them to workers, and it keeps the surfaces the workers send back in a spool on disk. Where it only forwards an
object, opening it (unpickling) and pickling it again for the next hop was a serial cost of a second core's
worth (issue 26): so a contour waiting on disk travels as the pickle it is kept as, a worker opens it, and a
worker sends a surface back already pickled for a spool on disk. A worker that can read the spool's file (a
local pool, a cluster on the same disk) is not even sent the pickle: only where it lies (:class:`FileSlice`).
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Sequence
from typing import Any, NamedTuple, TypeVar

T = TypeVar("T")


def pickled(obj: Any) -> bytes:
    """``obj`` as a payload: its pickle, as the scratch file and the spool keep it."""
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def opened(payload: T | bytes) -> T:
    """The object a payload holds: a pickle is opened, anything else is the object itself (a set in memory
    forwards its objects as they are)."""
    return pickle.loads(payload) if isinstance(payload, bytes) else payload


class FileSlice(NamedTuple):
    """Where a payload lies in a file of the build process (its spool): sent in its place to a worker that can
    read the file itself, so the build process neither reads the payload nor sends its bytes."""

    path: str
    offset: int
    length: int


class FileUnreachable(Exception):
    """A worker cannot read a file of the build process (it runs on another machine): the task must be sent
    again with its payloads (:func:`engine.parallel.map_ordered`'s ``refetch``)."""


def fetched(items: Sequence[T | bytes | FileSlice]) -> list[T | bytes]:
    """``items`` with every :class:`FileSlice` replaced by the bytes it names, each file opened once.

    Raises
    ------
    FileUnreachable
        A file cannot be opened here, or is shorter than a slice of it (not the build process's file).
    """
    out: list[T | bytes] = []
    fds: dict[str, int] = {}
    try:
        for item in items:
            if not isinstance(item, FileSlice):
                out.append(item)
                continue
            fd = fds.get(item.path)
            if fd is None:
                try:
                    fd = fds[item.path] = os.open(item.path, os.O_RDONLY)
                except OSError as exc:
                    raise FileUnreachable(f"{item.path}: {exc.strerror}") from exc
            blob = os.pread(fd, item.length, item.offset)
            if len(blob) != item.length:
                raise FileUnreachable(f"{item.path}: {len(blob)} of {item.length} bytes at {item.offset}")
            out.append(blob)
    finally:
        for fd in fds.values():
            os.close(fd)
    return out

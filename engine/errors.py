"""Domain errors of the engine. The web layer maps them to HTTP status codes in one table."""

from __future__ import annotations


class CCSMError(Exception):
    """Base class of every error the engine raises on purpose.

    ``parameter`` is the engine's name of the input parameter the error is about (``"interval"``,
    ``"elevation_field"``) or None: the message does not spell it, as each front end names it in its own
    words (the CLI's ``--interval``, the upload's query parameter ``interval``).
    """

    parameter: str | None = None

    def __init__(self, *args: object, parameter: str | None = None) -> None:
        super().__init__(*args)
        if parameter is not None:
            self.parameter = parameter  # in the instance's __dict__, which pickling keeps (process pools)


class InvalidContour(CCSMError, ValueError):
    """A contour cannot be simplified (too few points, NaN coordinates, zero length...)."""


class SurfaceFitError(CCSMError):
    """The CCS could not be fitted (singular collocation system)."""


class InvalidParameter(CCSMError, ValueError):
    """A parameter is out of its range (scale <= 0, t outside [0, 1], ...); the message names it."""


class SourceError(CCSMError):
    """A source file cannot be read: missing, unreadable, unknown format or CRS."""


class TileOutOfRange(CCSMError):
    """A tile index lies outside the tile matrix of its zoom."""


class UnknownLayer(CCSMError):
    """An unknown dataset or layer was asked for."""


class StoreNotReady(CCSMError):
    """The store is still being built or failed to build."""


class StoreError(CCSMError):
    """The store file is missing, corrupt or of another version."""


class StoreFormatError(StoreError):
    """The store was written by a version of ccsm with another store format."""


class StoreUnwritable(StoreError):
    """The store (or the folder of uploads beside it) cannot be written: a full disk, a read-only file system."""


class StoreBusy(StoreError):
    """Another write holds the store longer than a request waits: nothing was written; try again shortly."""


class BuildCancelled(CCSMError):
    """A build's dataset was deleted while it built: nothing is written."""


class NothingToServe(CCSMError):
    """No contour of a source could be built: the message names a contour, the step that failed and why."""


def short_reason(exc: BaseException) -> str:
    """One line for a user: the exception's type and the start of its message (the traceback goes to a log)."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}"[:300] if text else type(exc).__name__

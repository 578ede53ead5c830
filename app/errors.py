"""The service's own errors (the engine's are :mod:`engine.errors`); :mod:`app.http.errors` maps each to an HTTP
status.

No web framework is imported here: the upload check raises :class:`MalformedUpload` in a process without one.
"""

from __future__ import annotations

from engine.errors import CCSMError


class MalformedUpload(CCSMError):
    """An upload is not a GeoJSON FeatureCollection of contour lines."""


class UploadTooLarge(CCSMError):
    """A request body exceeds CCSM_MAX_UPLOAD_MB."""


class ContourTooLong(UploadTooLarge):
    """An upload holds a contour of more vertices than CCSM_MAX_CONTOUR_VERTICES (413): it would hold a build
    worker for minutes."""


class DatasetExists(CCSMError):
    """A dataset of that id exists already."""


class BuildQueueFull(CCSMError):
    """Every build slot is busy and the queue of builds is full: try again later."""


class UploadQueueFull(BuildQueueFull):
    """Every upload check slot is busy and the queue of checks is full: try again later (429)."""


class UploadCheckFailed(CCSMError):
    """An upload's check passed its deadline or its process died: 503, try again later."""


class ClientGone(CCSMError):
    """The client hung up before its answer was ready; the work for it was stopped (logged as 499)."""


class NotAuthenticated(CCSMError):
    """A write without the bearer token CCSM_ADMIN_TOKEN asks for (or with a wrong one)."""


class WriteForbidden(CCSMError):
    """A write from a client that may not write (no token is configured and the client is not local)."""


class UnsupportedMediaType(CCSMError):
    """A write whose Content-Type is not JSON (a browser could send it cross-site without asking)."""

"""What an upload check process does: parse and check the GeoJSON file an upload was streamed to.

The server never parses an upload itself (docs/service.md, "Uploads"): parsing a 20 MB document holds the
interpreter for seconds and takes hundreds of MB, which would stall the event loop (``/healthz`` included)
and keep the server's memory high. :mod:`app.datasets.uploads` runs :func:`check_upload` in a short-lived child
process per upload and awaits its answer. This module imports no web framework, and the fork server that
forks those processes imports it (with the readers) beforehand, so a check starts in milliseconds.
"""

from __future__ import annotations

import json
import os
import signal
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from app.errors import ContourTooLong, MalformedUpload
from app.render.jobs import HEAVY_NICENESS, lower_priority
from engine.build.datasets import source_hash
from engine.cartography.options import CartographyOptions, check_schedule_fits
from engine.ccsm.contour_size import OversizedContour, oversized_contours
from engine.errors import CCSMError
from engine.io.source import read_source
from engine.io.vertical_units import elevation_units

#: Bad features listed in the answer to an upload (all of them are in GET /datasets/{id} once built).
BAD_FEATURES_SHOWN = 20


@dataclass(frozen=True)
class UploadCheck:
    """One upload to check: the file it was streamed to and how to read it."""

    path: Path
    elevation_field: str | None
    interval: float | None
    #: The build parameters that go into the upload's content hash (``UploadParams.as_dict()``).
    hash_params: dict[str, Any]
    cartography: CartographyOptions | None = None
    source_scale: float | None = None
    #: The most vertices one contour may have (``CCSM_MAX_CONTOUR_VERTICES``); None = no limit.
    max_contour_vertices: int | None = None


@dataclass(frozen=True)
class CheckedUpload:
    """What the check found: enough for the server to reserve an id, queue the build and answer 202."""

    contours: int
    bad_features: int
    bad_feature_list: list[dict[str, str | int]]  # {id, reason} of the first BAD_FEATURES_SHOWN
    digest: str
    units: str | None  # the vertical unit as the elevation property's name states it, or None
    checker_pid: int  # the process that parsed the file (never the server's)


def check_document(path: Path) -> None:
    """Refuse a file that is not a GeoJSON FeatureCollection (or Feature) object (MalformedUpload)."""
    try:
        with open(path, "rb") as fh:
            doc = json.load(fh)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MalformedUpload(f"the body is not valid JSON ({exc})") from None
    except RecursionError:
        raise MalformedUpload("the body's JSON is nested too deeply to be GeoJSON") from None
    if not isinstance(doc, dict) or doc.get("type") not in ("FeatureCollection", "Feature"):
        raise MalformedUpload("the body must be a GeoJSON FeatureCollection (or Feature) of contour lines")
    if doc["type"] == "FeatureCollection" and not isinstance(doc.get("features"), list):
        raise MalformedUpload("a FeatureCollection needs a 'features' array")


def check_upload(job: UploadCheck) -> CheckedUpload:
    """Parse and check the upload as its build will read it.

    Raises
    ------
    MalformedUpload, SourceError, InvalidParameter
        The document or its contours are unusable (the message names the features and parameters).
    ContourTooLong
        A contour has more than ``job.max_contour_vertices`` vertices (the message names it, its count and
        the limit).
    """
    check_document(job.path)
    contour_set = read_source(job.path, elevation_field=job.elevation_field, interval=job.interval)
    oversized = oversized_contours(contour_set.contours, job.max_contour_vertices)
    if oversized:
        raise contour_too_long(oversized, job.max_contour_vertices or 0)
    if job.source_scale is not None:  # a schedule override must fit the data's interval (docs/design.md section 9)
        check_schedule_fits(job.cartography, contour_set.interval, job.source_scale)
    shown = contour_set.bad_features[:BAD_FEATURES_SHOWN]
    bad: list[dict[str, str | int]] = [{"id": b.id, "reason": b.reason} for b in shown]
    return CheckedUpload(
        contours=len(contour_set.contours),
        bad_features=len(contour_set.bad_features),
        bad_feature_list=bad,
        digest=source_hash(job.path, job.hash_params),  # the same hash as of the body's bytes
        units=elevation_units(job.path, job.elevation_field),
        checker_pid=os.getpid(),
    )


def contour_too_long(oversized: list[OversizedContour], limit: int) -> ContourTooLong:
    """The 413 for contours over the limit: the first one named with its count, how many more there are."""
    first = oversized[0]
    more = f"; {len(oversized) - 1} more contours exceed it too" if len(oversized) > 1 else ""
    return ContourTooLong(
        f"feature {first.id!r} has {first.vertices} vertices, more than the {limit} one contour may have "
        f"(CCSM_MAX_CONTOUR_VERTICES={limit}){more}; split long lines (a MultiLineString's parts count "
        "one by one) or simplify them before uploading"
    )


def checker_main(conn: Connection, job: UploadCheck) -> None:
    """The check process: one check, its answer ``("ok", CheckedUpload)`` or ``("error", exception)`` on
    the pipe, then exit (its memory returns to the system). SIGINT is left to the server."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    lower_priority(HEAVY_NICENESS)  # the event loop and map tiles first when the cores are busy
    try:
        answer: tuple[str, Any] = ("ok", check_upload(job))
    except CCSMError as exc:  # bad input: the server answers 4xx with the message
        answer = ("error", exc)
    except Exception as exc:  # a bug: the server answers 500; the traceback goes to this process's stderr
        import traceback

        traceback.print_exc()
        answer = ("error", RuntimeError(f"the upload check failed: {type(exc).__name__}"))
    try:
        conn.send(answer)
    except Exception as exc:  # an exception that does not pickle: send what it says instead
        conn.send(("error", MalformedUpload(f"{type(exc).__name__}: {exc}")))
    conn.close()

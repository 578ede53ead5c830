"""The pass over every contour before any is built: which contours can carry a CCS (the others with the reason),
and the size and shape the scale model groups the usable ones by.

It runs in chunks on the build's workers: the build process only forwards each contour as the pickle the reader
keeps it as, and gets back a few numbers a contour. Checking and measuring 42,645 contours there had cost 4.2 s
of its CPU on the 16x terrain, an eighth of all it did under the profiler (docs/design.md section 10).
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.ccs import check_contour
from engine.ccsm.regression import contour_features
from engine.errors import CCSMError
from engine.parallel import map_ordered
from engine.payloads import opened
from engine.types import BadFeature, Contour, contour_payloads

#: Contours per survey task: checking one costs about 40 µs, so a task of 512 is worth sending.
SURVEY_CHUNK = 512


@dataclass(frozen=True)
class Survey:
    """What the build knows of a set's contours before it builds any.

    Attributes
    ----------
    usable
        Positions (increasing) of the contours a CCS can be built from.
    rejected
        The others, in input order, each with the reason (``ccs.check_contour``'s message).
    features
        (len(usable), 2) size and shape of each usable contour (``regression.contour_features``).
    """

    usable: list[int]
    rejected: list[BadFeature]
    features: NDArray[np.float64]


def survey_chunk(contours: Sequence[Contour | bytes]) -> Survey:
    """:class:`Survey` of some contours as the reader keeps them (opened here, on a worker); positions count
    from the first of them."""
    usable: list[int] = []
    rejected: list[BadFeature] = []
    features: list[tuple[float, float]] = []
    for k, payload in enumerate(contours):
        contour: Contour = opened(payload)
        try:
            check_contour(contour)
        except CCSMError as exc:
            rejected.append(BadFeature(contour.id, str(exc)))
        else:
            usable.append(k)
            features.append(contour_features(contour))
    return Survey(usable, rejected, np.array(features, dtype=np.float64).reshape(-1, 2))


def survey_contours(contours: Sequence[Contour], executor: Executor | None) -> Survey:
    """:class:`Survey` of every contour of a set, :data:`SURVEY_CHUNK` per task on ``executor`` (None: in this
    process). Checked before anything is built: one unusable contour must not break the grouping of the others.
    """
    starts = range(0, len(contours), SURVEY_CHUNK)
    tasks = ((contour_payloads(contours, range(i, min(i + SURVEY_CHUNK, len(contours)))),) for i in starts)
    usable: list[int] = []
    rejected: list[BadFeature] = []
    features: list[NDArray[np.float64]] = [np.empty((0, 2))]
    for start, chunk in zip(starts, map_ordered(executor, survey_chunk, tasks), strict=True):
        usable.extend(start + k for k in chunk.usable)
        rejected.extend(chunk.rejected)
        features.append(chunk.features)
    return Survey(usable, rejected, np.concatenate(features))

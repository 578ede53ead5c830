"""Checks of the parameters every entry point shares (method names, scale denominators, t, bboxes).

Each raises :class:`engine.errors.InvalidParameter` with a message naming the parameter and its value; the
CLI turns it into exit status 2 and the service into a 400.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

from engine.errors import InvalidParameter
from engine.method_names import METHODS
from engine.types import Bounds

#: Largest scale denominator accepted (1:10 billion is already smaller than a whole-earth map).
MAX_SCALE = 1e10


def check_method(method: object, allowed: Sequence[str] = METHODS) -> str:
    """Return ``method`` if it is one of ``allowed`` (default: every method), else raise naming it."""
    if not isinstance(method, str) or method not in allowed:
        raise InvalidParameter(f"unknown method {method!r}; expected one of {', '.join(allowed)}")
    return method


def check_scale(scale: object, name: str = "scale") -> float:
    """Return ``scale`` as a float if it is a finite scale denominator in (0, MAX_SCALE]."""
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real):
        raise InvalidParameter(f"{name} must be a number > 0, got {scale!r}")
    value = float(scale)
    if not math.isfinite(value) or value <= 0 or value > MAX_SCALE:
        raise InvalidParameter(f"{name} {scale!r} must be a positive scale denominator up to {MAX_SCALE:g}")
    return value


def check_t(t: float | None) -> float | None:
    """A hand-pinned t in [0, 1], or None (t then follows the scale)."""
    if t is None:
        return None
    value = float(t)
    if not math.isfinite(value) or not 0.0 <= value <= 1.0:
        raise InvalidParameter(f"t {t} must lie in [0, 1]")
    return value


def check_bbox(bbox: Sequence[float]) -> Bounds:
    """A (west, south, east, north) box in degrees, checked."""
    if len(bbox) != 4:
        raise InvalidParameter(f"bbox needs 4 numbers west,south,east,north; got {len(bbox)}")
    w, s, e, n = (float(v) for v in bbox)
    if not all(math.isfinite(v) for v in (w, s, e, n)):
        raise InvalidParameter("bbox values must be finite numbers")
    if not (-180 <= w <= 180 and -180 <= e <= 180 and -90 <= s <= 90 and -90 <= n <= 90):
        raise InvalidParameter(f"bbox {w},{s},{e},{n} lies outside longitude [-180, 180] / latitude [-90, 90]")
    if w > e or s > n:
        raise InvalidParameter(f"bbox {w},{s},{e},{n} has min > max (expected west,south,east,north)")
    return Bounds(w, s, e, n)

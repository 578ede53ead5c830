"""The vertical unit of a contour file, as the name of its elevation attribute states it ("ELEV_FT", "height_m")."""

from __future__ import annotations

import os
from pathlib import Path

from pyogrio import list_layers, read_info
from pyogrio.errors import DataLayerError, DataSourceError

from engine.errors import SourceError
from engine.io.unreadable import unreadable_message
from engine.io.vector_reader import find_elevation_field

#: Words in an elevation attribute's name that give its unit ("ELEV_FT", "contour_feet", "height_m").
UNIT_WORDS: dict[str, str] = {
    "ft": "ft",
    "feet": "ft",
    "foot": "ft",
    "m": "m",
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
    "fm": "fm",
    "fathom": "fm",
    "fathoms": "fm",
}


def units_from_field_name(name: str) -> str | None:
    """The vertical unit an elevation attribute's name states ("ft", "m" or "fm"), or None.

    >>> units_from_field_name("ELEV_FT"), units_from_field_name("depth fathoms"), units_from_field_name("ele")
    ('ft', 'fm', None)
    """
    words = [w for w in "".join(c if c.isalnum() else " " for c in name.lower()).split() if w]
    found = {UNIT_WORDS[w] for w in words[1:] if w in UNIT_WORDS}  # the first word is the quantity
    return found.pop() if len(found) == 1 else None


def elevation_units(path: str | os.PathLike[str], elevation_field: str | None = None) -> str | None:
    """The vertical unit of a contour file as its elevation attribute's name states it, or None.

    Raises
    ------
    SourceError
        The file cannot be read, or has no such elevation field.
    """
    path = Path(path)
    try:
        meta = read_info(path, layer=str(list_layers(path)[0][0]))
    except (DataLayerError, DataSourceError, RuntimeError, IndexError) as exc:
        raise SourceError(unreadable_message(path, "contour lines", exc)) from exc
    if meta["features"] == 0:  # an empty file has no fields either: say so, not which fields it lacks
        raise SourceError(f"{path}: the file has no features")
    names = [str(n) for n in meta["fields"]]
    return units_from_field_name(names[find_elevation_field(names, elevation_field, path)])

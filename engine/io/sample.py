"""Paths of the bundled sample data (20 m contours and the DEM they come from, near Jacksboro, Tennessee)."""

from __future__ import annotations

from pathlib import Path

from engine.errors import SourceError

#: ``data/sample`` of the repository (the engine package sits next to ``data/``).
SAMPLE_DIR = Path(__file__).resolve().parents[2] / "data" / "sample"

SAMPLE_CONTOURS = "jacksboro_contours_20m.geojson"
SAMPLE_DEM = "jacksboro_fault_dem.npz"

#: Contour interval of the bundled contours, in metres.
SAMPLE_INTERVAL_M = 20.0


def sample_contours_path() -> Path:
    """The bundled sample contours: 20 m lines from the Jacksboro DEM, GeoJSON in EPSG:4326.

    Raises
    ------
    SourceError
        The file is missing (an installed wheel does not ship ``data/``; run ``data/sample/make_sample.py``).
    """
    path = SAMPLE_DIR / SAMPLE_CONTOURS
    if not path.is_file():
        raise SourceError(f"{path}: sample contours not found; run data/sample/make_sample.py to make them")
    return path


def sample_dem_path() -> Path:
    """The bundled sample DEM (``.npz`` layout; USGS, public domain), or matplotlib's own copy of it.

    Raises
    ------
    SourceError
        Neither the bundled copy nor matplotlib's sample data is available.
    """
    path = SAMPLE_DIR / SAMPLE_DEM
    if path.is_file():
        return path
    try:
        from matplotlib import cbook

        mpl_path = Path(str(cbook.get_sample_data(SAMPLE_DEM, asfileobj=False)))
    except (ImportError, OSError, ValueError) as exc:
        raise SourceError(
            f"{path}: sample DEM not found and matplotlib's copy is unavailable ({exc})"
        ) from exc
    if not mpl_path.is_file():
        raise SourceError(f"{path}: sample DEM not found (nor at {mpl_path})")
    return mpl_path

"""Make the bundled sample: 20 m contours of matplotlib's Jacksboro DEM, as GeoJSON in EPSG:4326.

Run from the repository root: ``python data/sample/make_sample.py``. It copies the DEM from matplotlib's
sample data next to this script (if not there yet), traces the contours with the engine's public API
(``contours_from_dem``, then ``write_geojson``), writes them with 6 decimals (RFC 7946's advice, about
10 cm) and prints the counts quoted in README.md. The output is deterministic.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))  # run as a script from a checkout, without installing

from engine.io.source import contours_from_dem, read_source, write_geojson  # noqa: E402

DEM = HERE / "jacksboro_fault_dem.npz"
OUT = HERE / "jacksboro_contours_20m.geojson"
INTERVAL_M = 20.0
DECIMALS = 6


def main() -> None:
    """Copy the DEM, write the contours, print their counts."""
    if not DEM.exists():
        from matplotlib import cbook

        shutil.copyfile(cbook.get_sample_data(DEM.name, asfileobj=False), DEM)
    contour_set = contours_from_dem(DEM, interval=INTERVAL_M)
    features = ((c.coords, c.closed, {"id": c.id, "elevation": c.elevation}) for c in contour_set.contours)
    write_geojson(OUT, features, from_crs=contour_set.working_crs, to_crs="EPSG:4326", decimals=DECIMALS)

    n_closed = sum(c.closed for c in contour_set.contours)
    n_vertices = sum(c.n_vertices for c in contour_set.contours)
    print(f"working CRS {contour_set.working_crs}, interval {INTERVAL_M:g} m")
    print(
        f"lines {len(contour_set.contours)}, closed {n_closed}, open {len(contour_set.contours) - n_closed}"
    )
    print(f"vertices {n_vertices} stored, {n_vertices + n_closed} written (rings repeat their first vertex)")
    print(f"bad features {len(contour_set.bad_features)}")
    print(f"{OUT.name}: {OUT.stat().st_size / 1e6:.2f} MB")

    back = read_source(OUT)
    back_closed = sum(c.closed for c in back.contours)
    back_vertices = sum(c.n_vertices for c in back.contours)
    print(
        f"read back: lines {len(back.contours)}, closed {back_closed}, vertices {back_vertices}, "
        f"bad {len(back.bad_features)}"
    )


if __name__ == "__main__":
    main()

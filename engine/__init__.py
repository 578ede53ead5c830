"""ccsm engine: continuous contour generalization with the continuous changing surface model (CCSM).

Pure algorithm code: no web framework, no environment variables. See :mod:`engine.types` for the meaning of
``t``. A six-line tour::

    from engine import BuildParams, build_contour_set, read_source, sample_contours_path, t_for_scale
    contours = read_source(sample_contours_path())            # metres, in a UTM zone chosen for the data
    built = build_contour_set(contours, BuildParams())        # one CCS per contour, on all cores
    ccs = built.surfaces[0]
    t = t_for_scale(built.model.ladder, ccs.t_at_scale, 250_000)
    line = ccs.at(t)                                          # (M, 2) metres: the contour at 1:250,000
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from engine.ccsm.build import BuiltSet, build_contour_set
    from engine.ccsm.ccs import CCS, build_ccs
    from engine.ccsm.regression import ScaleModel, t_for_scale
    from engine.ccsm.similarity import similarity
    from engine.errors import (
        CCSMError,
        InvalidContour,
        InvalidParameter,
        SourceError,
        StoreError,
        StoreNotReady,
        SurfaceFitError,
        TileOutOfRange,
        UnknownLayer,
    )
    from engine.geom.douglas_peucker import douglas_peucker
    from engine.io.source import make_transformer, read_source, sample_contours_path, sample_dem_path, write_geojson
    from engine.params import BuildParams
    from engine.tiles.scale import scale_for_zoom, zoom_for_scale
    from engine.types import BadFeature, Contour, ContourSet

# Each name is imported from its module when first asked for: a process that serves tiles or writes an archive
# imports the engine's package on the way to its own modules, and importing the whole build with it (SciPy's
# splines, the DEM readers, the crossing repair) cost every such process about half a second at start.
_HOME = {
    "BuiltSet": "engine.ccsm.build",
    "build_contour_set": "engine.ccsm.build",
    "CCS": "engine.ccsm.ccs",
    "build_ccs": "engine.ccsm.ccs",
    "ScaleModel": "engine.ccsm.regression",
    "t_for_scale": "engine.ccsm.regression",
    "similarity": "engine.ccsm.similarity",
    "CCSMError": "engine.errors",
    "InvalidContour": "engine.errors",
    "InvalidParameter": "engine.errors",
    "SourceError": "engine.errors",
    "StoreError": "engine.errors",
    "StoreNotReady": "engine.errors",
    "SurfaceFitError": "engine.errors",
    "TileOutOfRange": "engine.errors",
    "UnknownLayer": "engine.errors",
    "douglas_peucker": "engine.geom.douglas_peucker",
    "make_transformer": "engine.io.source",
    "read_source": "engine.io.source",
    "sample_contours_path": "engine.io.source",
    "sample_dem_path": "engine.io.source",
    "write_geojson": "engine.io.source",
    "BuildParams": "engine.params",
    "scale_for_zoom": "engine.tiles.scale",
    "zoom_for_scale": "engine.tiles.scale",
    "BadFeature": "engine.types",
    "Contour": "engine.types",
    "ContourSet": "engine.types",
}


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


__all__ = [
    "BadFeature",
    "BuildParams",
    "BuiltSet",
    "CCS",
    "CCSMError",
    "Contour",
    "ContourSet",
    "InvalidContour",
    "InvalidParameter",
    "ScaleModel",
    "SourceError",
    "StoreError",
    "StoreNotReady",
    "SurfaceFitError",
    "TileOutOfRange",
    "UnknownLayer",
    "build_ccs",
    "build_contour_set",
    "douglas_peucker",
    "make_transformer",
    "read_source",
    "sample_contours_path",
    "sample_dem_path",
    "scale_for_zoom",
    "similarity",
    "t_for_scale",
    "write_geojson",
    "zoom_for_scale",
]

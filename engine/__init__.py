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

__all__ = [
    "CCS",
    "BadFeature",
    "BuildParams",
    "BuiltSet",
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

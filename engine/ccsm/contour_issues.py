"""A failure stays with its contour: one contour whose surface or repair cannot be built is kept as its input
geometry, with the reason, instead of stopping the build of every other contour.

A surface whose two rows are both the input line (Ln = L0) never moves, so it meets no neighbour it did not
meet in the input: the fallback is always safe for the crossing repair too.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from engine.ccsm.ccs import CCS, build_ccs
from engine.ccsm.regression import ScaleModel
from engine.errors import InvalidContour, NothingToServe, short_reason
from engine.geom.polyline import closed_path, path_length
from engine.params import BuildParams
from engine.types import BadFeature, Contour

log = logging.getLogger("ccsm.build")

#: The step of a build at a tolerance factor: the first build ("surface") or a rebuild of the repair.
SURFACE_STEP, REPAIR_STEP = "surface", "repair"


def still_surface(contour: Contour) -> CCS:
    """The surface of a contour that stays its input line at every scale (both rows are L0, Sim = 1)."""
    path = closed_path(contour.coords) if contour.closed else np.array(contour.coords, dtype=np.float64)
    return CCS(
        contour_id=contour.id,
        elevation=contour.elevation,
        closed=contour.closed,
        base=path.copy(),
        top=path.copy(),
        sim_t=np.array([0.0, 1.0]),
        sim=np.array([1.0, 1.0]),
        length_m=path_length(contour.coords, contour.closed),
        n_input_vertices=contour.n_vertices,
        target_vertices=contour.n_vertices,
        tolerance_factor=0.0,
    )


def finish(ccs: CCS, group: int, model: ScaleModel) -> CCS:
    """A built surface with its regression group, t table and vanishing scale."""
    from engine.ccsm.build import vanish_scale  # the build module imports this one

    ccs.group = int(group)
    ccs.t_at_scale = model.t_table(ccs.group, ccs.sim_t, ccs.sim)
    ccs.vanish_scale = vanish_scale(ccs, model)
    return ccs


def build_or_keep_input(
    contour: Contour, group: int, params: BuildParams, model: ScaleModel, factor: float
) -> CCS | BadFeature:
    """The contour's surface at ``factor``; when that cannot be built, its input geometry (:func:`still_surface`)
    with the step and reason in ``issues``; a :class:`BadFeature` (left out, with the reason) when the contour
    cannot carry a surface at all."""
    try:
        return finish(build_ccs(contour, params, factor), group, model)
    except InvalidContour as exc:
        return BadFeature(contour.id, str(exc))
    except Exception as exc:  # the per-contour boundary: this contour alone falls back
        step = SURFACE_STEP if factor >= 1.0 else REPAIR_STEP
        reason = short_reason(exc)
        log.warning("contour %r is served as its input geometry (%s step failed: %s)", contour.id, step, reason)
        log.debug("the %s step of contour %r", step, contour.id, exc_info=True)
    try:
        kept = finish(still_surface(contour), group, model)
    except Exception as again:  # not even the input line: the contour is left out, with both reasons
        log.debug("the input geometry of contour %r", contour.id, exc_info=True)
        return BadFeature(contour.id, f"{step} step failed: {reason}; as its input line: {short_reason(again)}")
    kept.issues = ((step, reason),)
    return kept


def nothing_to_serve(left_out: Sequence[BadFeature], total: int) -> NothingToServe:
    """The error of a build none of whose ``total`` contours could be built: it names the first one and why."""
    first = left_out[0] if left_out else BadFeature("?", "no reason recorded")
    more = f" (and {len(left_out) - 1} more)" if len(left_out) > 1 else ""
    return NothingToServe(
        f"nothing to serve: none of the {total} contour(s) could be built; contour {first.id!r}: {first.reason}{more}"
    )

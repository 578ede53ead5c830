"""Frozen parameters of a CCS build, with the defaults docs/design.md explains."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from engine.errors import InvalidParameter
from engine.tolerances import DEFAULT_TOLERANCES, Tolerances, tolerance_for_scale

#: How the target contour Ln is made: DP at the target scale's tolerance, DP down to a point count, or the
#: paper's extreme case (an open line's two end points; a ring's minimal triangle).
TargetMode = Literal["scale", "points", "extreme"]


@dataclass(frozen=True)
class BuildParams:
    """Everything that decides the CCS of a contour set.

    Attributes
    ----------
    source_scale
        Scale denominator of the input contours (t = 0). Default 1:50,000.
    target_scale
        Scale denominator of the target contours (t = 1). Default 1:500,000.
    target_mode
        ``"scale"``: Ln = DP(L0, 0.1 mm x target_scale); ``"points"``: DP down to ``target_points`` vertices;
        ``"extreme"``: the paper's 2-point target (a ring keeps its minimal triangle).
    target_points
        Vertex count for ``target_mode="points"``.
    resample_spacing_m
        Largest gap between correspondence samples on L0, metres; None = 1 mm at the source scale (50 m at
        1:50,000). L0's own vertices are always samples; this only decides how finely long edges are split, i.e.
        how smoothly a long straight piece of Ln bends back into L0's detail (1 mm on the map at most).
    tessellation_per_span
        Extra u samples between two data parameters when the CCS is tessellated into the CCS-mesh (the
        paper's mesh parameter). 0, the default, tessellates at the paper's parameter grid [u_i, v_j] (eq. 5):
        the mesh vertices are the wireframe points themselves, so t = 0 reproduces L0 exactly; more samples
        add the spline's curvature between them, which rounds L0's corners by up to a few metres.
    similarity_levels
        Number of t values (0..1) at which Sim(t) is computed per contour (docs/design.md section 3).
    similarity_spacing_m
        Resampling spacing of the improved Fréchet distance, metres.
    scale_levels
        Number of log-spaced scales between source and target where each contour's t is tabulated.
    groups
        Number of contour groups (by size and shape) that each get their own similarity-scale regression.
    scale_mapping
        ``"regression"`` (the paper's exponential regression per group) or ``"log"`` (t linear in log scale).
    resolve_crossings
        With ``target_mode="scale"``: check the slices of all contours for crossings at a ladder of scales
        and rebuild the contours involved with a finer target (half the tolerance, up to four times, then
        Ln = L0), so that no two contours cross where the input's did not (docs/design.md section 5).
    """

    source_scale: float = 50_000.0
    target_scale: float = 500_000.0
    target_mode: TargetMode = "scale"
    target_points: int | None = None
    resample_spacing_m: float | None = None
    tessellation_per_span: int = 0
    similarity_levels: int = 11
    similarity_spacing_m: float = 10.0
    scale_levels: int = 33
    groups: int = 5
    scale_mapping: Literal["regression", "log"] = "regression"
    resolve_crossings: bool = True
    tolerances: Tolerances = field(default=DEFAULT_TOLERANCES)

    def __post_init__(self) -> None:
        for name in ("source_scale", "target_scale"):
            value = getattr(self, name)
            if not (value > 0 and value < 1e12):
                raise InvalidParameter(f"{name} must be a positive finite scale denominator, got {value}")
        if self.target_scale <= self.source_scale:
            raise InvalidParameter(
                f"target_scale ({self.target_scale:g}) must be smaller-scale (a larger denominator) than "
                f"source_scale ({self.source_scale:g})"
            )
        if self.target_mode not in ("scale", "points", "extreme"):
            raise InvalidParameter(f"target_mode must be scale, points or extreme, got {self.target_mode!r}")
        if self.target_mode == "points" and (self.target_points is None or self.target_points < 2):
            raise InvalidParameter(
                f"target_points must be >= 2 with target_mode='points', got {self.target_points}"
            )
        if self.resample_spacing_m is not None and not self.resample_spacing_m > 0:
            raise InvalidParameter(f"resample_spacing_m must be > 0, got {self.resample_spacing_m}")
        if self.similarity_levels < 2 or self.scale_levels < 2:
            raise InvalidParameter("similarity_levels and scale_levels must be >= 2")
        if self.scale_mapping not in ("regression", "log"):
            raise InvalidParameter(f"scale_mapping must be regression or log, got {self.scale_mapping!r}")

    @property
    def spacing_m(self) -> float:
        """Correspondence sample spacing in metres."""
        if self.resample_spacing_m is not None:
            return self.resample_spacing_m
        return 10 * tolerance_for_scale(self.source_scale)

    @property
    def target_tolerance_m(self) -> float:
        """Douglas–Peucker tolerance of the target contour (0.1 mm at the target scale), metres."""
        return tolerance_for_scale(self.target_scale)

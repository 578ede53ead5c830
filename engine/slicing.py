"""Cutting the CCS-mesh with the horizontal plane at height t.

The CCS is a ruled surface whose height is its v parameter, so the plane at height t meets the tessellated
mesh along one iso-v line: the slice is ``(1 - t) * base + t * top`` of the two stored boundary rows. That
closed form is exact for the mesh, costs one weighted sum, and needs no segment chaining. ``section_with_trimesh``
does the same cut the general way (trimesh's plane section plus path chaining) and serves as the test oracle.
"""

from __future__ import annotations

import numpy as np
import trimesh

from engine.errors import InvalidParameter
from engine.types import Coords


def check_t(t: float) -> float:
    """Validate a simplification parameter; returns it as a float."""
    value = float(t)
    if not 0.0 <= value <= 1.0:
        raise InvalidParameter(f"t must lie in [0, 1], got {t}")
    return value


def slice_rows(base: Coords, top: Coords, t: float) -> Coords:
    """The contour at height ``t`` of the ruled CCS-mesh spanned by two rows of (M, 2) points, metres."""
    value = check_t(t)
    return (1.0 - value) * base + value * top


def ccs_mesh(base: Coords, top: Coords, heights: int = 4) -> trimesh.Trimesh:
    """Tessellate the CCS into a triangle mesh in (x, y, t).

    Parameters
    ----------
    base, top
        (M, 2) rows of the surface at t = 0 and t = 1 (for a ring the closed path, first point repeated).
    heights
        Number of rows in t (>= 2); the surface is ruled, so extra rows add triangles but no shape.
    """
    if heights < 2:
        raise InvalidParameter(f"heights must be >= 2, got {heights}")
    m = len(base)
    ts = np.linspace(0.0, 1.0, heights)
    rows = [np.column_stack([(1 - t) * base + t * top, np.full(m, t)]) for t in ts]
    vertices = np.concatenate(rows)
    faces = []
    for r in range(heights - 1):
        a = r * m + np.arange(m - 1)
        b = a + 1
        c = a + m
        d = b + m
        faces.append(np.column_stack([a, b, d]))
        faces.append(np.column_stack([a, d, c]))
    return trimesh.Trimesh(vertices=vertices, faces=np.concatenate(faces), process=False)


def section_with_trimesh(mesh: trimesh.Trimesh, t: float) -> list[Coords]:
    """Cut a CCS-mesh with the plane at height ``t`` using trimesh, returning the chained polylines (x, y)."""
    check_t(t)
    section = mesh.section(plane_origin=[0.0, 0.0, t], plane_normal=[0.0, 0.0, 1.0])
    if section is None:
        return []
    return [np.asarray(line)[:, :2] for line in section.discrete]

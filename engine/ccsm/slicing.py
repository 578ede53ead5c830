"""Cutting the CCS-mesh with the horizontal plane at height t.

The CCS is a ruled surface whose height is its v parameter, so the plane at height t meets it along one
iso-v line: the slice is ``(1 - t) * base + t * top`` of the two stored boundary rows. That closed form costs
one weighted sum and needs no segment chaining. ``section_with_trimesh`` does the same cut the general way
(trimesh's plane section of the triangulated CCS-mesh, plus path chaining) and serves as the test oracle.

The two differ only by the triangulation: between two mesh rows each quad is split by a diagonal, and the
plane crosses that diagonal off the straight iso-line by at most ``f (1 - f) / (rows - 1) * |d_{i+1} - d_i|``
(``d = top - base`` the link vectors, ``f`` where t falls between the rows). ``mesh_rows`` picks enough rows
to keep that under ``MESH_DEVIATION_M``; at the rows themselves the two agree exactly.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from engine.errors import InvalidParameter
from engine.types import Coords

if TYPE_CHECKING:
    import trimesh  # the oracle's only: imported where used, since it costs every process half a second


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


#: Largest distance, metres, the default CCS-mesh may stray from the exact ruled surface between its rows.
MESH_DEVIATION_M = 0.01
#: Row count cap: the paper's finest mesh parameter, 0.001, is a thousand divisions.
MAX_MESH_ROWS = 1001


def mesh_rows(base: Coords, top: Coords, deviation_m: float = MESH_DEVIATION_M) -> int:
    """Rows in t that keep the triangulated mesh within ``deviation_m`` of the ruled surface (>= 2)."""
    links = top - base
    spread = float(np.max(np.hypot(*np.diff(links, axis=0).T))) if len(links) > 1 else 0.0
    rows = int(np.ceil(0.25 * spread / deviation_m)) + 1
    return int(min(max(rows, 2), MAX_MESH_ROWS))


def ccs_mesh(base: Coords, top: Coords, heights: int | None = None) -> trimesh.Trimesh:
    """Tessellate the CCS into a triangle mesh in (x, y, t).

    Parameters
    ----------
    base, top
        (M, 2) rows of the surface at t = 0 and t = 1 (for a ring the closed path, first point repeated).
    heights
        Number of rows in t (>= 2); None picks enough rows (``mesh_rows``) to stay within MESH_DEVIATION_M of
        the exact surface.
    """
    if heights is None:
        heights = mesh_rows(base, top)
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
    import trimesh

    return trimesh.Trimesh(vertices=vertices, faces=np.concatenate(faces), process=False)


def section_with_trimesh(mesh: trimesh.Trimesh, t: float) -> list[Coords]:
    """Cut a CCS-mesh with the plane at height ``t`` using trimesh, returning the chained polylines (x, y)."""
    check_t(t)
    section = mesh.section(plane_origin=[0.0, 0.0, t], plane_normal=[0.0, 0.0, 1.0])
    if section is None:
        return []
    # Entity by entity: ``Path3D.discrete`` would leave out open polylines (contours cut by the data's edge).
    return [np.asarray(entity.discrete(section.vertices))[:, :2] for entity in section.entities]

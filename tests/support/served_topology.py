"""What a served map must never show, checked independently of the engine: pairs of contours that meet where
they did not in the input, in slices, tiles and morph tiles drawn as a client draws them (docs/morph-tiles.md).

Shared by the served-topology tests and the any-terrain tests.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from engine.ccsm.topology import INPUT_TOUCH_M, crossing_pairs
from engine.serve.renderer import Renderer
from engine.serve.simplify import simplify
from engine.tiles.scale import zoom_for_scale

LARGEST_SCALE, SMALLEST_SCALE = 40_000.0, 1_000_000.0


def input_lines(renderer: Renderer, dataset: str) -> dict[int, np.ndarray]:
    return {c.fid: c.coords_3857 for c in simplify(renderer, dataset, 1.0, method="original").contours}


def met_in_input(renderer: Renderer, dataset: str) -> set[tuple[int, int]]:
    lines = input_lines(renderer, dataset)
    fids = list(lines)
    return {(fids[a], fids[b]) for a, b in crossing_pairs([lines[f] for f in fids], within=INPUT_TOUCH_M)}


def new_pairs(found: set[tuple[int, int]], allowed: set[tuple[int, int]]) -> set[tuple[int, int]]:
    return {(min(p), max(p)) for p in found} - {(min(p), max(p)) for p in allowed}


def tile_lines(layer: dict) -> dict[int, list[np.ndarray]]:
    out: dict[int, list[np.ndarray]] = {}
    for feat in layer.get("features", []):
        geometry = feat["geometry"]
        parts = [geometry["coordinates"]] if geometry["type"] == "LineString" else geometry["coordinates"]
        out[feat["id"]] = [np.asarray(p, dtype=float) for p in parts]
    return out


def proper_new_crossings(lines: dict[int, list[np.ndarray]], allowed: set[tuple[int, int]]) -> set[tuple[int, int]]:
    return new_pairs(properly_crossing_contours(lines), allowed)


def properly_crossing_contours(lines: dict[int, list[np.ndarray]]) -> set[tuple[int, int]]:
    """Pairs of contours (fid order) with two segments that cross at a point inside both: this test's own
    check, independent of the engine's. Every segment of the drawing at once: candidate pairs from a shapely
    tree of the segments, then the four orientation signs (touching gives a zero sign, never a crossing)."""
    owners, segments = [], []
    for fid, parts in lines.items():
        for part in parts:
            if len(part) >= 2:
                segments.append(np.stack([part[:-1], part[1:]], axis=1))
                owners.append(np.full(len(part) - 1, fid))
    if len(segments) < 2:
        return set()
    seg, owner = np.concatenate(segments), np.concatenate(owners)
    i, j = shapely.STRtree(shapely.linestrings(seg)).query(shapely.linestrings(seg), predicate="intersects")
    keep = owner[i] < owner[j]
    i, j = i[keep], j[keep]
    p1, p2, q1, q2 = seg[i, 0], seg[i, 1], seg[j, 0], seg[j, 1]

    def turn(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.sign((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    proper = (turn(p1, p2, q1) * turn(p1, p2, q2) < 0) & (turn(q1, q2, p1) * turn(q1, q2, p2) < 0)
    return {(int(a), int(b)) for a, b in zip(owner[i][proper], owner[j][proper], strict=True)}


def zooms_to_check(renderer: Renderer, dataset: str) -> list[tuple[int, float]]:
    """Every integer zoom whose scales meet [1:40,000, 1:1,000,000], each at three fractions."""
    info = renderer.info(dataset)[0]
    lat = math.degrees(math.atan(math.sinh((info.bounds_3857[1] + info.bounds_3857[3]) / 2 / 6378137.0)))
    low = math.floor(float(zoom_for_scale(SMALLEST_SCALE, lat)))
    high = math.floor(float(zoom_for_scale(LARGEST_SCALE, lat)))
    return [(z, z + f) for z in range(low, high + 1) for f in (0.0, 0.3, 0.7)]


def morph_drawing(morph: dict, z: int, f: float) -> dict[int, list[np.ndarray]]:
    """The contours of a decoded morph tile of zoom z drawn at z + f."""
    if not morph:
        return {}
    start = morph["contours"]
    end = tile_lines(morph["contours_end"])
    props = {f["id"]: f["properties"] for f in start["features"]}
    lines = {}
    for fid, parts in tile_lines(start).items():
        p = props[fid]
        if z + f <= p.get("min_zoom", -1.0):
            continue
        w = 0.0 if p["t8"] == p["t"] else (morph_t(p, f) - p["t"]) / (p["t8"] - p["t"])
        lines[fid] = [a + w * (b - a) for a, b in zip(parts, end[fid], strict=True)]
    return lines


def morph_t(props: dict, f: float) -> float:
    """docs/morph-tiles.md: t at z + f, piecewise linear between the nine samples t, t1 ... t8."""
    samples = [props["t"]] + [props[f"t{k}"] for k in range(1, 9)]
    k = min(int(8 * f), 7)
    return samples[k] + (8 * f - k) * (samples[k + 1] - samples[k])

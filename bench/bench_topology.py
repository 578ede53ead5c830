"""Crossings between different contours across scales: ccsm's build against per-scale simplifiers.

Prints, for a ladder of scales between the source and the target scale, how many pairs of different contours
meet or cross that did not already meet in the input: ccsm as served (target at the target scale, crossing
repair on), ccsm without the repair, and Douglas–Peucker / Visvalingam–Whyatt / Wang–Müller run at each scale
the way per-zoom tile tools do. Rings too small for a scale are left out for every method alike.

    python bench/bench_topology.py [SOURCE] [--scales 20]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from engine import BuildParams, build_contour_set, read_source, sample_contours_path
from engine.baselines import simplify_at_scale
from engine.ccsm.regression import t_for_scale
from engine.ccsm.topology import crossing_pairs
from engine.geom.polyline import closed_path


def new_pairs(lines: list[np.ndarray], ids: list[object], allowed: set[tuple[object, object]]) -> int:
    found = {(ids[a], ids[b]) for a, b in crossing_pairs(lines)}
    return len({p for p in found if p not in allowed and (p[1], p[0]) not in allowed})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", nargs="?", default=str(sample_contours_path()))
    parser.add_argument("--scales", type=int, default=20)
    args = parser.parse_args()

    contours = read_source(args.source)
    start = time.perf_counter()
    repaired = build_contour_set(contours, BuildParams())
    built_s = time.perf_counter() - start
    plain = build_contour_set(contours, BuildParams(resolve_crossings=False))
    by_id = {c.id: c for c in contours.contours}
    ids = [s.contour_id for s in repaired.surfaces]
    inputs = [by_id[i] for i in ids]
    met = crossing_pairs([closed_path(c.coords) if c.closed else c.coords for c in inputs])
    allowed = {(ids[a], ids[b]) for a, b in met}
    print(f"{len(ids)} contours; input pairs already meeting (left out): {len(allowed)}")
    print(f"build with repair {built_s:.1f} s, {repaired.repaired} contours got a finer target\n")
    print(f"{'scale':>10} {'ccsm':>6} {'ccsm-norepair':>14} {'dp':>6} {'vw':>6} {'wm':>6}")
    totals = dict.fromkeys(("ccsm", "plain", "dp", "vw", "wm"), 0)
    for scale in np.geomspace(repaired.model.source_scale, repaired.model.target_scale, args.scales):
        row = {}
        for key, built in (("ccsm", repaired), ("plain", plain)):
            visible = [s for s in built.surfaces if s.vanish_scale > scale]
            lines = [s.at(t_for_scale(built.model.ladder, s.t_at_scale, float(scale))) for s in visible]
            row[key] = new_pairs(lines, [s.contour_id for s in visible], allowed)
        visible_ids = [s.contour_id for s in repaired.surfaces if s.vanish_scale > scale]
        for method in ("dp", "vw", "wm"):
            lines = []
            for cid in visible_ids:
                c = by_id[cid]
                out = simplify_at_scale(method, c.coords, c.closed, float(scale))
                lines.append(closed_path(out) if c.closed else out)
            row[method] = new_pairs(lines, visible_ids, allowed)
        for key, value in row.items():
            totals[key] += value
        print(
            f"{scale:>10.0f} {row['ccsm']:>6} {row['plain']:>14} {row['dp']:>6} {row['vw']:>6} {row['wm']:>6}"
        )
    print(
        f"{'sum':>10} {totals['ccsm']:>6} {totals['plain']:>14} {totals['dp']:>6} {totals['vw']:>6} {totals['wm']:>6}"
    )


if __name__ == "__main__":
    main()

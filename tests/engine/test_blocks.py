"""The crossing repair block by block (issue 12 item 2): the same contacts, the same decisions as over the whole set."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from numpy.testing import assert_array_equal

import engine.ccsm.blocks as blocks
from engine.ccsm.blocks import find_crossings_by_block, spatial_blocks, surface_boxes
from engine.ccsm.build import BuiltSet, build_contour_set, checked_ladder_steps
from engine.ccsm.spool import MemorySpool
from engine.ccsm.topology import InputTouches, find_new_crossings
from engine.params import BuildParams
from engine.types import Contour, ContourSet


def ring_clusters(side: int = 3, rings: int = 5, seed: int = 7) -> ContourSet:
    """``side`` x ``side`` clusters of nested noisy rings 20 m apart (their DP targets cross), 2.1 km apart
    so the boxes of neighbouring clusters' outer rings overlap: many blocks, and contours reaching into others."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 2 * np.pi, 160, endpoint=False)
    contours = []
    for cx in range(side):
        for cy in range(side):
            centre = np.array([500_000.0 + 2_100.0 * cx, 4_000_000.0 + 1_300.0 * cy])
            for k in range(rings):
                r = 1_000.0 + 20.0 * k + rng.uniform(-6.0, 6.0, len(s))
                xy = np.column_stack([r * np.cos(s), 0.6 * r * np.sin(s)]) + centre
                contours.append(Contour(len(contours), 100.0 + 20 * k, xy, closed=True))
    return ContourSet(contours, "EPSG:32616", "EPSG:32616")


@pytest.fixture(scope="module")
def clusters() -> ContourSet:
    return ring_clusters()


@pytest.fixture(scope="module")
def unrepaired(clusters: ContourSet) -> BuiltSet:
    return build_contour_set(clusters, BuildParams(resolve_crossings=False), workers=1)


def test_every_contour_is_owned_once_and_its_block_holds_every_contour_whose_box_meets_it() -> None:
    rng = np.random.default_rng(1)
    lo = rng.uniform(0, 1_000, (300, 2))
    boxes = np.column_stack([lo, lo + rng.uniform(1, 120, (300, 2))])
    found = spatial_blocks(boxes, per_block=8)
    assert len(found) > 10
    owners = np.concatenate([b.own for b in found])
    assert sorted(owners.tolist()) == list(range(300))
    geoms = shapely.box(*boxes.T)
    for b in found:
        for i in b.own:
            meets = np.flatnonzero(shapely.intersects(geoms[i], geoms))
            assert set(meets.tolist()) <= set(b.near.tolist())


def test_blocks_find_the_same_contacts_as_the_whole_set(unrepaired: BuiltSet) -> None:
    surfaces = unrepaired.surfaces
    ladder = unrepaired.model.ladder
    steps = checked_ladder_steps(unrepaired.model)
    whole = find_new_crossings(surfaces, ladder, steps, InputTouches([s.at(0.0) for s in surfaces]))
    assert len(whole) > 10  # the DP targets of the rings cross: there is something to find
    spool = MemorySpool()
    for i, s in enumerate(surfaces):
        spool.put(i, s)
    boxes = surface_boxes(surfaces)
    assert find_crossings_by_block(spool, boxes, ladder, steps, per_block=4) == whole
    only = set(range(0, len(surfaces), 3))
    with_only = find_new_crossings(surfaces, ladder, steps, InputTouches([s.at(0.0) for s in surfaces]), only)
    assert find_crossings_by_block(spool, boxes, ladder, steps, only, per_block=4) == with_only


@pytest.fixture(scope="module")
def repaired_whole(clusters: ContourSet) -> BuiltSet:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(blocks, "BLOCK_CONTOURS", 10**9)  # one block: the whole set at once
        return build_contour_set(clusters, BuildParams(), workers=1)


@pytest.mark.parametrize("workers", [1, 2])
def test_repair_by_small_blocks_makes_the_surfaces_of_the_repair_over_the_whole_set(
    clusters: ContourSet, repaired_whole: BuiltSet, workers: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(blocks, "BLOCK_CONTOURS", 4)
    by_block = build_contour_set(clusters, BuildParams(), workers=workers)
    assert repaired_whole.repaired > 10
    assert by_block.repaired == repaired_whole.repaired
    for a, b in zip(by_block.surfaces, repaired_whole.surfaces, strict=True):
        assert_array_equal(a.base, b.base)
        assert_array_equal(a.top, b.top)
        assert_array_equal(a.t_at_scale, b.t_at_scale)
    surfaces, model = by_block.surfaces, by_block.model
    left = find_new_crossings(
        surfaces, model.ladder, checked_ladder_steps(model), InputTouches([s.at(0.0) for s in surfaces])
    )
    assert left == set()

"""Which lane a tile goes to is decided by its method, not by its name."""

from typing import Any, cast

from app.render.pool import RenderLanes, RenderPool
from engine.method_names import BASELINE_METHODS
from engine.serve.methods import make_methods


def test_only_the_per_request_simplifiers_take_the_heavy_lane():
    light, heavy, morph = (cast(RenderPool, object()) for _ in range(3))
    lanes = RenderLanes(light=light, heavy=heavy, morph=morph)
    lane_of: dict[str, Any] = {name: lanes.for_tile(m) for name, m in make_methods(8).items()}
    assert {name for name, lane in lane_of.items() if lane is heavy} == set(BASELINE_METHODS)
    assert {name for name, lane in lane_of.items() if lane is light} == {"ccsm", "original"}

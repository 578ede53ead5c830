"""The MapLibre style generator: layers per rank with their fade, index weight, labels, glyphs, hillshade; and
the style is valid by MapLibre's own style-spec validator."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from engine.cartography.style import FONT_STACK, RankFade, StyleSource, build_style, fade_opacity
from engine.errors import InvalidParameter

REPO = Path(__file__).resolve().parents[3]
VALIDATOR = REPO / "web" / "node_modules" / "@maplibre" / "maplibre-gl-style-spec" / "dist" / "gl-style-validate.mjs"
BASE = "http://127.0.0.1:8000"
#: Three ranks as a schedule of 20 m contours would give them (the top one never hides).
SCHEDULE = (RankFade(0, 12.2, 10.9), RankFade(1, 10.9, 9.6), RankFade(2, 9.6, None))


def source(**kw) -> StyleSource:
    args = {
        "dataset": "sample",
        "name": "Jacksboro",
        "tilejson_url": f"{BASE}/tiles/sample/tilejson.json",
        "glyphs_url": f"{BASE}/fonts/{{fontstack}}/{{range}}.pbf",
        "bounds": (-84.41, 36.45, -84.08, 36.73),
        "schedule": SCHEDULE,
        "hillshade_tiles_url": f"{BASE}/hillshade/sample/{{z}}/{{x}}/{{y}}.png",
    }
    args.update(kw)
    return StyleSource(**args)


def layers_by_id(style):
    return {layer["id"]: layer for layer in style["layers"]}


def test_layers_bottom_to_top_hillshade_lines_coastline_labels():
    ids = [layer["id"] for layer in build_style(source())["layers"]]
    assert ids == [
        "background",
        "hillshade",
        "contours-rank-0",
        "contours-rank-1",
        "contours-rank-2",
        "coastline",
        "contour-labels-rank-0",
        "contour-labels-rank-1",
        "contour-labels-rank-2",
    ]


def test_no_hillshade_without_a_dem():
    style = build_style(source(hillshade_tiles_url=None))
    assert "hillshade" not in layers_by_id(style)
    assert list(style["sources"]) == ["ccsm-contours"]


def test_each_rank_fades_between_its_own_zooms_with_base_2():
    lines = layers_by_id(build_style(source()))
    assert lines["contours-rank-0"]["paint"]["line-opacity"] == [
        "interpolate",
        ["exponential", 2],
        ["zoom"],
        10.9,
        0,
        12.2,
        1,
    ]
    assert lines["contours-rank-1"]["filter"] == ["==", ["to-number", ["get", "rank"]], 1]
    assert lines["contours-rank-1"]["paint"]["line-opacity"][3:] == [9.6, 0, 10.9, 1]
    assert lines["contours-rank-2"]["paint"]["line-opacity"] == 1  # the top rank never hides


@pytest.mark.parametrize("rank", [0, 1, 2])
def test_index_contours_are_heavier_and_thin_as_the_base_interval_fades_out(rank):
    width = layers_by_id(build_style(source()))[f"contours-rank-{rank}"]["paint"]["line-width"]
    # Every rank's lines follow rank 0's fade range (10.9 to 12.2 in source()): index lines are heavy while the
    # intermediate lines are drawn, lighter (still heavier than an intermediate line) once they are gone.
    interpolate, how, zoom, z_alone, alone, z_heavy, heavy = width
    assert (interpolate, how, zoom, z_alone, z_heavy) == ("interpolate", ["exponential", 2], ["zoom"], 10.9, 12.2)
    for case in (alone, heavy):
        assert case[:2] == ["case", ["==", ["to-number", ["get", "level"]], 1]]
    assert heavy[2] > 2 * heavy[3] and heavy[3] < alone[2] < heavy[2] and alone[3] == heavy[3]


def test_a_schedule_of_one_rank_has_fixed_widths():
    one = StyleSource("d", "d", BASE + "/t.json", BASE + "/g", (0, 0, 1, 1), [RankFade(0, 3.0, None)])
    width = layers_by_id(build_style(one))["contours-rank-0"]["paint"]["line-width"]
    assert width[0] == "case" and width[2] > 2 * width[3]


def test_labels_read_label_and_angle_on_the_map_plane_with_a_halo():
    label = layers_by_id(build_style(source()))["contour-labels-rank-1"]
    assert label["source-layer"] == "contour_labels"
    layout = label["layout"]
    assert layout["text-field"] == ["to-string", ["get", "label"]]
    assert layout["text-rotate"] == ["to-number", ["get", "angle"]]
    assert layout["text-rotation-alignment"] == "map"
    assert layout["text-allow-overlap"] is False
    assert layout["text-font"] == [FONT_STACK]
    assert label["paint"]["text-halo-width"] > 0


def test_every_url_is_the_services_own():
    style = build_style(source())
    text = json.dumps(style)
    urls = [style["glyphs"], style["sources"]["ccsm-contours"]["url"], *style["sources"]["ccsm-hillshade"]["tiles"]]
    assert all(u.startswith(BASE + "/") for u in urls)
    assert text.count("http") == len(urls)


@pytest.mark.parametrize(
    "schedule, message",
    [((), "empty"), ((RankFade(0, 12, 11), RankFade(0, 11, 10)), "repeats a rank")],
)
def test_a_bad_schedule_is_refused_with_the_reason(schedule, message):
    with pytest.raises(InvalidParameter, match=message):
        build_style(source(schedule=schedule))


def test_a_fade_range_the_wrong_way_round_is_refused():
    with pytest.raises(InvalidParameter, match="rank 2: hide_zoom 12.0 must be below fade_zoom 11.0"):
        RankFade(2, 11.0, 12.0)
    assert fade_opacity(RankFade(1, 11.0, None)) == 1


def test_maplibre_style_spec_validates_the_style(tmp_path):
    node = shutil.which("node")
    assert node, "node is needed to run MapLibre's style validator"
    assert VALIDATOR.is_file(), f"{VALIDATOR} missing: run `npm ci` in web/"
    path = tmp_path / "style.json"
    path.write_text(json.dumps(build_style(source())))
    result = subprocess.run([node, str(VALIDATOR), str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.strip() == ""


def evaluate_label_opacity(expr, zoom: float, min_zoom: float) -> float:
    """Evaluate the style's label opacity as MapLibre does: linear between the zoom stops, each stop's output
    an arithmetic expression of the feature's min_zoom."""

    def ev(e):
        if not isinstance(e, list):
            return e
        op, *args = e
        if op == "get":
            return min_zoom
        if op == "to-number":
            return ev(args[0])
        vals = [ev(a) for a in args]
        return (
            {"max": max, "min": min}[op](*vals)
            if op in ("max", "min")
            else {"*": lambda a, b: a * b, "/": lambda a, b: a / b, "-": lambda a, b: a - b}[op](*vals)
        )

    assert expr[:3] == ["interpolate", ["linear"], ["zoom"]]
    stops = expr[3:]
    zs, outs = stops[0::2], stops[1::2]
    if zoom <= zs[0]:
        return ev(outs[0])
    for z0, z1, o0, o1 in zip(zs, zs[1:], outs, outs[1:], strict=False):
        if z0 <= zoom <= z1:
            return ev(o0) + (ev(o1) - ev(o0)) * (zoom - z0) / (z1 - z0)
    return ev(outs[-1])


@pytest.mark.parametrize(
    "zoom, min_zoom, expected",
    [
        (12.5, 11.0, 1.0),  # above both ramps
        (11.0, 11.0, 0.0),  # at its own first zoom: not yet shown
        (11.25, 11.0, 0.5),  # half way in
    ],
)
def test_a_label_fades_in_above_its_own_first_zoom(zoom, min_zoom, expected):
    expr = layers_by_id(build_style(source()))["contour-labels-rank-2"]["paint"]["text-opacity"]
    assert evaluate_label_opacity(expr, zoom, min_zoom) == pytest.approx(expected, abs=0.02)


def test_a_label_fades_out_with_its_rank():
    expr = layers_by_id(build_style(source()))["contour-labels-rank-1"]["paint"]["text-opacity"]
    for zoom in (9.6, 9.9, 10.2, 10.6, 10.9, 11.5):
        exact = 0 if zoom <= 9.6 else min(1.0, (2 ** (zoom - 9.6) - 1) / (2**1.3 - 1))
        assert evaluate_label_opacity(expr, zoom, min_zoom=5.0) == pytest.approx(exact, abs=0.03), zoom


def test_the_coastline_layer_draws_only_coastline_features():
    coast = layers_by_id(build_style(source()))["coastline"]
    assert coast["source-layer"] == "contours" and coast["filter"] == ["==", ["get", "coastline"], True]

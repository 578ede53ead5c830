"""``ccsm export -o FOLDER``: the whole map as static files. The style is the service's, with every source and
the glyphs in the folder; the archive's features carry every attribute the style reads; the hillshade of a
DEM is a PNG archive; the page's import map and every relative import of its modules resolve inside the folder.
(tests/browser/test_export_map.py opens the folder in Chromium.)"""

from __future__ import annotations

import gzip
import json
import re
from pathlib import Path
from typing import Any

import mapbox_vector_tile
import pytest
from pmtiles.reader import MmapSource, Reader, all_tiles
from pmtiles.tile import Compression, TileType
from typer.testing import CliRunner

from app.cli import _register_commands, app
from engine.cartography.style import FONT_STACK, HILLSHADE_SOURCE
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore

_register_commands()
runner = CliRunner()

DATA = Path(__file__).resolve().parents[1] / "data"
#: A 1.2 km cone: few tiles at every zoom, labels on its index contours from zoom 13 or so.
CONE = DATA / "cone_utm16n.asc"
MAXZOOM = 15


def run(*args: object):  # type: ignore[no-untyped-def]
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def cone_map(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(folder, cache store) of the cone exported as a map."""
    tmp = tmp_path_factory.mktemp("map")
    cache, folder = tmp / "cache.sqlite", tmp / "site"
    args = ["export", CONE, "--interval", "20", "--store", cache, "-o", folder, "--maxzoom", MAXZOOM, "--workers", "1"]
    result = run(*args)
    assert result.exit_code == 0, result.output
    assert "index.html, style.json" in " ".join(result.stdout.split()), result.stdout
    return folder, cache


def gets(expr: Any) -> set[str]:
    """The feature properties a style expression reads (``["get", name]``)."""
    if not isinstance(expr, list):
        return set()
    found = {expr[1]} if len(expr) == 2 and expr[0] == "get" and isinstance(expr[1], str) else set()
    for part in expr:
        found |= gets(part)
    return found


def test_the_style_is_the_services_with_its_sources_in_the_folder(cone_map: tuple[Path, Path]) -> None:
    folder, cache = cone_map
    style = json.loads((folder / "style.json").read_text())
    (dataset,) = CCSStore(cache, readonly=True).dataset_ids()
    ranks = Renderer(CCSStore(cache, readonly=True)).cartography(dataset).schedule.ranks
    ids = [layer["id"] for layer in style["layers"]]
    assert ids == [
        "background",
        "hillshade",
        *(f"contours-rank-{r.rank}" for r in ranks),
        "coastline",
        *(f"contour-labels-rank-{r.rank}" for r in ranks),
    ]
    assert style["sources"]["ccsm-contours"] == {"type": "vector", "url": "pmtiles://contours.pmtiles"}
    assert style["sources"][HILLSHADE_SOURCE]["tiles"] == ["pmtiles://contours-hillshade.pmtiles/{z}/{x}/{y}"]
    assert style["glyphs"] == "fonts/{fontstack}/{range}.pbf"
    faded = [layer for layer in style["layers"] if layer["id"].startswith("contours-rank-")]
    assert any(isinstance(layer["paint"]["line-opacity"], list) for layer in faded), "no rank fades"
    for layer in style["layers"]:
        for name in ("url", "tiles"):
            source = style["sources"].get(layer.get("source", ""), {})
            for url in [source[name]] if name == "url" and name in source else source.get(name, []):
                assert (folder / re.sub(r"^pmtiles://([^/]+).*$", r"\1", url)).is_file(), url


def test_the_archive_carries_every_attribute_the_style_reads(cone_map: tuple[Path, Path]) -> None:
    folder, _ = cone_map
    style = json.loads((folder / "style.json").read_text())
    seen: dict[str, set[str]] = {}
    with open(folder / "contours.pmtiles", "rb") as f:
        for _, data in all_tiles(MmapSource(f)):
            for name, layer in mapbox_vector_tile.decode(gzip.decompress(data)).items():
                for feature in layer["features"]:
                    seen.setdefault(name, set()).update(feature["properties"])
    assert seen.get("contour_labels"), "the archive has no label"
    for layer in style["layers"]:
        if layer.get("source") != "ccsm-contours" or layer["id"] == "coastline":  # coastline: sea="coastline" only
            continue
        read = gets(layer.get("filter")) | gets(list(layer.get("paint", {}).values()))
        read |= gets(list(layer.get("layout", {}).values()))
        assert read and read <= seen[layer["source-layer"]], (layer["id"], read - seen[layer["source-layer"]])


def test_glyphs_and_hillshade_beside_the_style(cone_map: tuple[Path, Path]) -> None:
    folder, _ = cone_map
    glyphs = sorted(p.name for p in (folder / "fonts" / FONT_STACK).iterdir())
    assert glyphs == ["0-255.pbf", "8704-8959.pbf"]  # digits, "m" and space; the minus of depths
    assert all((folder / "fonts" / FONT_STACK / g).stat().st_size > 1000 for g in glyphs)
    with open(folder / "contours-hillshade.pmtiles", "rb") as f:
        reader = Reader(MmapSource(f))
        header = reader.header()
        assert header["tile_type"] == TileType.PNG and header["tile_compression"] == Compression.NONE
        assert (header["min_zoom"], header["max_zoom"]) == (0, MAXZOOM + 1)
        tiles = list(all_tiles(MmapSource(f)))
    assert tiles and all(data.startswith(b"\x89PNG") for _, data in tiles)


def test_the_page_and_every_module_it_imports_are_in_the_folder(cone_map: tuple[Path, Path]) -> None:
    folder, _ = cone_map
    html = (folder / "index.html").read_text()
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', html, re.S).group(1))["imports"]  # type: ignore[union-attr]
    bare = set(imports)
    targets = [folder / path for path in imports.values()]
    targets += [folder / m for m in re.findall(r'(?:href|from) *=? *"(\./[^"]+)"', html)]
    targets += [folder / m for m in re.findall(r"from '(\./[^']+)'", html)]
    assert (folder / "js" / "maplibre-gl" / "maplibre-gl.css") in targets
    missing = [t for t in targets if not t.is_file()]
    assert not missing, missing
    # Inside the modules: relative imports resolve beside them, bare ones through the import map.
    for module in (folder / "js").rglob("*.js"):
        text = module.read_text()
        for spec in re.findall(r"""(?:^|[;\s])(?:import|export)\b[^'"]*?from\s*['"]([^'"]+)['"]""", text, re.M):
            assert spec in bare or (module.parent / spec).is_file(), (module, spec)
    assert (folder / "js" / "maplibre-gl" / "maplibre-gl-worker.mjs").is_file()  # loaded beside maplibre-gl.mjs


def test_a_map_without_the_pages_modules_exits_2_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CCSM_WEB_DIR", str(tmp_path / "web"))
    result = run("export", CONE, "--interval", "20", "--store", tmp_path / "c.sqlite", "-o", tmp_path / "site")
    assert result.exit_code == 2, result.output
    assert "run `npm ci` in" in " ".join(result.stderr.split()), result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []

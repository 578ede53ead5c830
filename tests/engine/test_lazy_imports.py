"""What a process imports to start: the engine's package names its API without importing it, and the modules a
tile server or an archive export loads leave the build's heavy dependencies (SciPy's splines, k-means and curve
fitting, the HTTP client of the terrain tile fetcher) to the processes that use them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("scipy.interpolate", "scipy.cluster", "scipy.optimize", "httpx")


def modules_after(imports: str, watched: tuple[str, ...] = HEAVY) -> list[str]:
    """The ``watched`` modules loaded by a fresh interpreter after ``imports``."""
    code = f"import json, sys\n{imports}\nprint(json.dumps(sorted(m for m in {watched!r} if m in sys.modules)))\n"
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_the_engine_package_imports_none_of_the_build() -> None:
    assert modules_after("import engine, engine.params, engine.types", (*HEAVY, "engine.ccsm.build")) == []


def test_an_archive_export_and_a_tile_server_start_without_the_builds_dependencies() -> None:
    loaded = modules_after(
        "import engine.serve.export, engine.serve.static_page, engine.tiles.archives, engine.serve.renderer"
    )
    assert loaded == []


def test_a_build_from_a_file_leaves_the_http_client_and_splines_unloaded() -> None:
    assert "httpx" not in modules_after("import engine.build.datasets, engine.io.source")
    assert "scipy.interpolate" not in modules_after("import engine.build.datasets, engine.io.source")


@pytest.mark.parametrize("name", __import__("engine").__all__)
def test_every_name_of_the_engine_api_is_there_when_asked_for(name: str) -> None:
    import engine

    value = getattr(engine, name)
    assert getattr(value, "__name__", name) == name or not callable(value)


def test_a_name_the_engine_does_not_have_is_an_attribute_error() -> None:
    import engine

    with pytest.raises(AttributeError, match="no attribute 'simplify_everything'"):
        engine.simplify_everything  # noqa: B018


def test_telling_a_dataset_id_from_a_source_loads_no_tile_reader() -> None:
    loaded = modules_after(
        "from app.cli.terrain_options import names_a_source\n"
        "assert not names_a_source('bench') and names_a_source('terrarium:https://example.org/{z}/{x}/{y}.png')",
        ("PIL.Image",),
    )
    assert loaded == ["PIL.Image"]  # asked about a tile source, it loads the reader; not for 'bench' alone
    bench_only = "from app.cli.terrain_options import names_a_source\nnames_a_source('bench')"
    assert modules_after(bench_only, ("PIL.Image",)) == []

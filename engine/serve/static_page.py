"""The page of an exported map: ``web/export/index.html`` and the ES modules it imports, copied from the project's
``web/`` folder (its ``npm ci`` installs them) into ``js/`` beside it, so the folder needs no CDN and no build.

The page reads ``style.json`` beside it and draws the contour lines through the ccsm-morph plugin with the
style's own line layers, as the service's page does (``web/js/stylerules.js``, copied too).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from engine.errors import InvalidParameter

#: The page, in the project's web folder.
PAGE = Path("export") / "index.html"
#: Module files the page's import map names: (under web/, into js/). MapLibre's main module loads its worker
#: from beside itself.
MODULES: tuple[tuple[str, str], ...] = (
    ("node_modules/maplibre-gl/dist/maplibre-gl.mjs", "maplibre-gl/maplibre-gl.mjs"),
    ("node_modules/maplibre-gl/dist/maplibre-gl-worker.mjs", "maplibre-gl/maplibre-gl-worker.mjs"),
    ("node_modules/maplibre-gl/dist/maplibre-gl.css", "maplibre-gl/maplibre-gl.css"),
    ("node_modules/maplibre-gl/LICENSE.txt", "maplibre-gl/LICENSE.txt"),
    ("node_modules/pmtiles/dist/esm/index.js", "pmtiles/index.js"),
    ("node_modules/fflate/esm/browser.js", "fflate/browser.js"),
    ("node_modules/fflate/LICENSE", "fflate/LICENSE"),
    ("node_modules/pbf/index.js", "pbf/index.js"),
    ("node_modules/pbf/LICENSE", "pbf/LICENSE"),
    ("node_modules/@mapbox/vector-tile/index.js", "vector-tile/index.js"),
    ("node_modules/@mapbox/vector-tile/LICENSE.txt", "vector-tile/LICENSE.txt"),
    ("node_modules/@mapbox/point-geometry/index.js", "point-geometry/index.js"),
    ("node_modules/@mapbox/point-geometry/LICENSE", "point-geometry/LICENSE"),
    ("js/stylerules.js", "stylerules.js"),
)
#: The plugin's modules (every file of web/plugin/src/ but its type declarations), into js/ccsm-morph/.
PLUGIN_SRC = Path("plugin") / "src"
#: The folder of modules beside the page.
JS_DIR = "js"


def page_files(web_dir: Path) -> list[tuple[Path, str]]:
    """(source file, path under the export folder) of the page and every module it loads.

    Raises
    ------
    InvalidParameter
        A file is missing (the page's modules are installed by ``npm ci`` in web/).
    """
    files = [(web_dir / PAGE, "index.html")]
    files += [(web_dir / src, f"{JS_DIR}/{dest}") for src, dest in MODULES]
    plugin = sorted((web_dir / PLUGIN_SRC).glob("*.js"))
    files += [(p, f"{JS_DIR}/ccsm-morph/{p.name}") for p in plugin]
    missing = [str(src) for src, _ in files if not src.is_file()]
    if not plugin:
        missing.append(str(web_dir / PLUGIN_SRC / "*.js"))
    if missing:
        raise InvalidParameter(
            f"the map page needs {missing[0]}"
            + (f" and {len(missing) - 1} more files" if len(missing) > 1 else "")
            + f": run `npm ci` in {web_dir}, or give -o FILE.pmtiles for the archive alone"
        )
    return files


def write_page(folder: Path, web_dir: Path) -> list[Path]:
    """Copy the page and its modules into ``folder``; the paths written.

    Raises
    ------
    InvalidParameter
        A file is missing (see :func:`page_files`) or cannot be written.
    """
    written = []
    for src, dest in page_files(web_dir):
        target = folder / dest
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, target)
        except OSError as exc:
            raise InvalidParameter(f"cannot write {target}: {exc.strerror or exc}") from None
        written.append(target)
    return written

"""``ccsm export``: a static PMTiles or MBTiles archive of a dataset's morph tiles (docs/morph-tiles.md), or the
whole map as a folder for a static host: the archive, the service's style, glyphs, hillshade and a page.

The work is :func:`engine.serve.export.export_dataset` (and :mod:`engine.serve.static_map`,
:mod:`engine.serve.static_page` for a folder); this module resolves what to export (a source file,
built into the cache store by content hash as ``ccsm simplify`` does, or a dataset of a store), checks the
options and shows progress. Bad input ends with a one-line message and exit status 2 (app/cli/__init__.py).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.progress import Progress

from app.cli import app
from app.cli.commands_engine import (
    AttributeNamesOption,
    AttributionOption,
    DepthLabelsOption,
    ElevationFieldOption,
    IndexEveryOption,
    IntervalOption,
    LabelOrientationOption,
    ReportOption,
    ScheduleOption,
    SeaOption,
    SourceScaleOption,
    TargetScaleOption,
    UnitsOption,
    bad_input_exits,
    build_into_cache,
    cartography_options,
    check_report,
    check_scale,
    console,
    err_console,
    fail,
)
from app.cli.contour_issues import issues_phrase, report_contour_issues, report_skipped_features, write_report
from app.cli.lazy_progress import LazyProgress, progress_bar
from app.cli.terrain_options import BboxOption, DemZoomOption, names_a_source, open_source

if TYPE_CHECKING:
    from app.settings import Settings


def _progress() -> Progress:
    return progress_bar(err_console, time_left=True)


def _settings() -> Settings:
    """The service's settings (env CCSM_*), or exit 2 naming the bad one."""
    from pydantic import ValidationError

    from app.settings import Settings

    try:
        return Settings()
    except ValidationError as exc:
        fail(f"invalid settings: {exc.errors()[0].get('msg', exc)}")


def _service_store() -> Path:
    """The store ``ccsm build`` and ``ccsm serve`` use [env CCSM_STORE_PATH; var/ccsm.sqlite]."""
    return _settings().store_path


def _stored_dataset(store: Path, dataset: str, what: str) -> None:
    """Exit 2 unless ``store`` holds ``dataset`` (``what`` names it in the message)."""
    from engine.store.store import CCSStore

    if not store.is_file():
        fail(f"{what}: no such file, and no store at {store} to look it up in (give --store PATH)")
    ids = CCSStore(store, readonly=True).dataset_ids()
    if dataset not in ids:
        held = ", ".join(ids[:10]) + (", ..." if len(ids) > 10 else "") if ids else "none"
        fail(f"{what}: no such file, nor a dataset of {store} (datasets: {held})")


#: The morph archive's name in an exported map folder.
MAP_ARCHIVE = "contours.pmtiles"


def _write_map(store_path: Path, dataset: str, folder: Path, archive: Path, minzoom: int, maxzoom: int) -> str:
    """Write the rest of the map beside ``archive`` (style, glyphs, hillshade, page); a phrase saying what."""
    from engine.serve.renderer import Renderer
    from engine.serve.static_map import write_static_map
    from engine.serve.static_page import write_page
    from engine.store.store import CCSStore

    renderer = Renderer(CCSStore(store_path, readonly=True))
    info, _ = renderer.info(dataset)
    settings = _settings()
    with LazyProgress(_progress, "hillshade tiles") as progress:
        static = write_static_map(
            info, renderer.cartography(dataset), archive, minzoom, maxzoom, settings.font_path, progress.update
        )
    write_page(folder, settings.web_dir)
    shade = f", hillshade {static.hillshade_tiles} tiles" if static.hillshade else ""
    return f"\n{folder}: index.html, style.json, {len(static.glyphs)} glyph ranges{shade}; serve the folder as it is"


@app.command()
def export(
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="Output: FILE.pmtiles (PMTiles v3) or FILE.mbtiles, or a FOLDER (no extension) for the whole "
            "map: contours.pmtiles, style.json, index.html, fonts/, js/ and, from a DEM, contours-hillshade.pmtiles.",
            show_default=False,
        ),
    ],
    source: Annotated[
        str | None,
        typer.Argument(
            help="Contour file or DEM (built into the cache store by content hash), or a dataset id of --store.",
            metavar="SOURCE|DATASET",
            show_default=False,
        ),
    ] = None,
    store: Annotated[
        Path | None,
        typer.Option(
            "--store",
            help="Store to read --dataset from [CCSM_STORE_PATH; var/ccsm.sqlite], or to build SOURCE into "
            "[$XDG_CACHE_HOME/ccsm/sources.ccsm.sqlite].",
        ),
    ] = None,
    dataset: Annotated[
        str | None, typer.Option("--dataset", help="Dataset id of the store to export (instead of SOURCE).")
    ] = None,
    minzoom: Annotated[int, typer.Option("--minzoom", help="Smallest zoom exported.")] = 0,
    maxzoom: Annotated[int, typer.Option("--maxzoom", help="Largest zoom exported (at most 16).")] = 14,
    workers: Annotated[
        int | None, typer.Option("--workers", help="Processes building and rendering (default: one per core).")
    ] = None,
    source_scale: SourceScaleOption = 50_000.0,
    target_scale: TargetScaleOption = 500_000.0,
    elevation_field: ElevationFieldOption = None,
    interval: IntervalOption = None,
    bbox: BboxOption = None,
    dem_zoom: DemZoomOption = None,
    units: UnitsOption = None,
    index_every: IndexEveryOption = 5,
    attribute_names: AttributeNamesOption = "ccsm",
    schedule: ScheduleOption = None,
    attribution: AttributionOption = None,
    report: ReportOption = None,
    sea: SeaOption = "drop",
    depth_labels: DepthLabelsOption = "negative",
    label_orientation: LabelOrientationOption = "uphill",
) -> None:
    """Write the morph tiles of a source or stored dataset to a PMTiles or MBTiles archive (gzip MVT), or the
    whole map to a folder that any Range-capable static host serves (README.md, "Static hosting").

    Every tile of --minzoom .. --maxzoom over the dataset's bounds is rendered on every core, exactly as
    ``GET /morph/{dataset}/{z}/{x}/{y}.mvt`` serves it; empty tiles are left out. The archive is written to a
    temporary file and renamed when complete, so a failed export leaves an existing file as it was. A folder
    gets the archive as contours.pmtiles and beside it the service's style (style.json), the label glyphs
    (fonts/), the hillshade of a DEM as PNG tiles (contours-hillshade.pmtiles) and index.html with the modules
    it loads (js/, copied from web/ and its npm packages).
    """
    from engine.serve.export import check_zoom_range, export_dataset
    from engine.serve.static_page import page_files
    from engine.tiles.archives import FORMATS, check_writable

    started = time.perf_counter()
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    source_scale = check_scale("--source-scale", source_scale)
    target_scale = check_scale("--target-scale", target_scale)
    check_report(report)
    suffix = out.suffix.lower()
    if suffix and suffix not in FORMATS:
        fail(f"{out.name}: unknown archive extension {suffix!r}; use .pmtiles, .mbtiles, or a folder for the whole map")
    folder = out if not suffix else None
    if folder is not None:
        out = folder / MAP_ARCHIVE
    with bad_input_exits():
        check_zoom_range(minzoom, maxzoom)
        if folder is not None:
            page_files(_settings().web_dir)  # a missing module fails before any work
        check_writable(out)  # before any build: an unwritable or unknown target fails at once
        cartography = cartography_options(
            units, index_every, attribute_names, schedule, attribution, sea, depth_labels, label_orientation
        )
        if source is not None and dataset is not None:
            fail("give either SOURCE or --dataset, not both")
        if source is None and dataset is None:
            fail("give a contour file or DEM, or --store PATH --dataset ID")
        if source is not None and names_a_source(source):
            cache, info = build_into_cache(
                open_source(source, bbox, dem_zoom, source_scale),
                store,
                elevation_field=elevation_field,
                interval=interval,
                source_scale=source_scale,
                target_scale=target_scale,
                workers=workers,
                cartography=cartography,
            )
            store_path = cache.path
            dataset_id = info.id
        else:
            dataset_id = dataset if dataset is not None else str(source)
            store_path = store or _service_store()
            _stored_dataset(store_path, dataset_id, source if source is not None else f"--dataset {dataset_id}")
        with LazyProgress(_progress, f"tiles z{minzoom}-{maxzoom}") as progress:  # drawn once tiles are counted
            result = export_dataset(
                store_path,
                dataset_id,
                out,
                minzoom=minzoom,
                maxzoom=maxzoom,
                workers=workers,
                progress=progress.update,
            )
        written = _write_map(store_path, dataset_id, folder, out, minzoom, maxzoom) if folder is not None else ""
    from engine.store.store import CCSStore

    stored = CCSStore(store_path, readonly=True)
    skipped = stored.dataset(dataset_id).bad_features
    report_skipped_features(err_console, skipped, report)
    issues = report_contour_issues(err_console, stored, dataset_id, report)
    write_report(report, stored, dataset_id, source or dataset_id, skipped)
    console.print(
        f"{out}: {result.tiles} tiles ({result.format}, gzip MVT, z{minzoom}-{maxzoom}; {result.empty} empty left "
        f"out), {result.bytes / 1e6:.2f} MB; {issues_phrase(issues)}; tiles {result.seconds:.1f} s, "
        f"total {time.perf_counter() - started:.1f} s{written}",
        highlight=False,
        soft_wrap=True,
    )

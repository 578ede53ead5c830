"""``ccsm serve`` and ``ccsm build`` (owned by the tile service work)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from app.cli import app
from app.cli.commands_engine import ElevationFieldOption, IntervalOption, ReportOption, check_report
from app.cli.terrain_options import SOURCE_HELP, BboxOption, DemZoomOption, open_source

if TYPE_CHECKING:
    from engine.store.store import CCSStore as CCSStoreType

SourcesArg = Annotated[
    list[str] | None,
    typer.Argument(help=SOURCE_HELP.replace("Contour file", "Contour files") + " None = the bundled sample."),
]
StoreOpt = Annotated[
    Path | None, typer.Option("--store", help="SQLite store file [env CCSM_STORE_PATH; var/ccsm.sqlite].")
]
SourceScaleOpt = Annotated[
    float | None, typer.Option("--source-scale", help="Scale denominator of the source (t = 0) [50000].")
]
TargetScaleOpt = Annotated[
    float | None, typer.Option("--target-scale", help="Scale denominator of t = 1 [500000].")
]


def _set_env(name: str, value: object) -> None:
    if value is not None:
        os.environ[f"CCSM_{name}"] = str(value)


@app.command()
def serve(
    sources: SourcesArg = None,
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port.", min=1, max=65535)] = 8000,
    workers: Annotated[int, typer.Option(help="uvicorn worker processes (they share the store).", min=1)] = 1,
    store: StoreOpt = None,
    elevation_field: ElevationFieldOption = None,
    interval: IntervalOption = None,
    bbox: BboxOption = None,
    dem_zoom: DemZoomOption = None,
    source_scale: SourceScaleOpt = None,
    target_scale: TargetScaleOpt = None,
    log_level: Annotated[str, typer.Option(help="uvicorn log level.")] = "info",
) -> None:
    """Serve tiles, TileJSON, /simplify and the web map (FastAPI on uvicorn).

    Missing or changed sources build in the background at startup; the store then serves them at once on
    every restart.
    """
    import uvicorn

    if sources:
        os.environ["CCSM_SOURCES"] = _checked_sources(sources, bbox, dem_zoom, source_scale)
    _set_env("BBOX", bbox)
    _set_env("DEM_ZOOM", dem_zoom)
    _set_env("STORE_PATH", store)
    _set_env("ELEVATION_FIELD", elevation_field)
    _set_env("INTERVAL", interval)
    _set_env("SOURCE_SCALE", source_scale)
    _set_env("TARGET_SCALE", target_scale)
    _set_env("LOG_LEVEL", log_level)
    from pydantic import ValidationError

    from app.settings import Settings

    try:
        settings = Settings()
    except ValidationError as exc:
        typer.echo(f"error: invalid settings: {exc}", err=True)
        raise typer.Exit(2) from None
    _check_store_or_exit(settings.store_path)
    # The app is created from the environment in each worker (app.main:app), so 1 or N workers behave alike.
    # The protocol (named by import path, so every worker imports it) adds the head and body timeouts and the
    # per-client connection cap (app/http/connection_limits.py).
    from app.http.connection_limits import HTTP_PROTOCOL

    uvicorn.run(
        "app.main:app",
        host=host,
        port=port,
        workers=workers,
        log_level=log_level,
        proxy_headers=True,
        http=HTTP_PROTOCOL,
    )


def _checked_sources(sources: list[str], bbox: str | None, dem_zoom: int | None, source_scale: float | None) -> str:
    """The sources as CCSM_SOURCES takes them (local files made absolute), each checked as ``ccsm build``
    checks it but with nothing fetched (their builds run once the server is up); exit status 2 on the first
    that is not a source."""
    import json

    from app.cli.terrain_options import parse_bbox
    from app.datasets.sources import configured_source
    from engine.errors import CCSMError

    out = []
    for text in sources:
        try:
            area = parse_bbox(bbox)
            source = configured_source(text, bbox=area, dem_zoom=dem_zoom, source_scale=source_scale or 50_000.0)
        except CCSMError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(2) from None
        if isinstance(source, Path) and not source.exists():
            typer.echo(f"error: source not found: {text}", err=True)
            raise typer.Exit(2)
        out.append(str(Path(text).resolve()) if Path(text).exists() else text)
    return json.dumps(out) if any("," in s for s in out) else ",".join(out)


def _check_store_or_exit(store_path: Path) -> None:
    """Refuse to start on a damaged store (exit status 2 and what to do), instead of a traceback loop."""
    from app.service import open_checked_store
    from engine.errors import StoreError

    try:
        open_checked_store(store_path).close()
    except StoreError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None


@app.command()
def build(
    source: Annotated[str | None, typer.Argument(help=SOURCE_HELP + " None = the bundled sample.")] = None,
    store: StoreOpt = None,
    dataset: Annotated[
        str | None, typer.Option("--id", help="Dataset id [from the file name; 'sample'].")
    ] = None,
    name: Annotated[str | None, typer.Option(help="Human name of the dataset.")] = None,
    elevation_field: ElevationFieldOption = None,
    interval: IntervalOption = None,
    bbox: BboxOption = None,
    dem_zoom: DemZoomOption = None,
    source_scale: SourceScaleOpt = None,
    target_scale: TargetScaleOpt = None,
    workers: Annotated[int | None, typer.Option(help="Build processes [one per core].", min=1)] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Rebuild even if the store holds the same source.")
    ] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask scheduler (tcp://HOST:8786) to run the DEM windows and the contours' builds on "
            "[none: --workers local processes].",
        ),
    ] = None,
    publish: Annotated[
        Path | None,
        typer.Option(
            "--publish",
            help="After the build, point this link (the live store of running replicas) at --store, atomically.",
        ),
    ] = None,
    block: Annotated[
        int | None,
        typer.Option(
            "--block", min=2, help="GeoTIFF / .asc: trace in windows of this many cells a side [by size]."
        ),
    ] = None,
    report: ReportOption = None,
) -> None:
    """Precompute a source into the store without serving (one transaction: a killed build changes nothing)."""
    from rich.console import Console

    from app.cli.lazy_progress import LazyProgress, progress_bar
    from app.datasets.sources import SAMPLE_ID, SAMPLE_NAME  # not app.service: the web app's imports cost 0.5 s
    from app.settings import Settings
    from engine.build.datasets import SourceSpec, build_dataset, build_lock, slugify
    from engine.errors import CCSMError
    from engine.store.store import CCSStore

    console = Console(stderr=True)
    check_report(report)
    if scheduler is not None:
        console.print(f"building on the Dask cluster at {scheduler}")
    settings = Settings()
    store_path = store or settings.store_path
    if source is None:
        from engine.io.source import sample_contours_path

        spec = SourceSpec(sample_contours_path(), dataset or SAMPLE_ID, name or SAMPLE_NAME)
    else:
        try:
            opened = open_source(source, bbox, dem_zoom, source_scale or settings.source_scale)
        except CCSMError as exc:
            console.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2) from None
        if isinstance(opened, Path) and not opened.exists():
            console.print(f"[red]error:[/red] source not found: {source}")
            raise typer.Exit(2)
        spec = SourceSpec(
            opened.resolve() if isinstance(opened, Path) else opened,
            dataset or slugify(opened.stem),
            name or opened.stem,
            elevation_field=elevation_field if elevation_field is not None else settings.elevation_field,
            interval=interval if interval is not None else settings.interval,
            source_scale=source_scale or settings.source_scale,
            target_scale=target_scale or settings.target_scale,
            block=block,
        )
    console.print(f"building {spec.dataset} from {spec.path.name} into {store_path}")
    try:
        ccs_store = CCSStore(store_path)
        bar = progress_bar(console, description="[bold]{task.description}")
        with (
            build_lock(store_path),
            LazyProgress(lambda: bar, f"building {spec.dataset}") as progress,  # drawn once the source is read
        ):
            with build_executor(scheduler, workers or settings.build_workers) as executor:
                info, rebuilt = build_dataset(
                    ccs_store, spec, workers=workers or settings.build_workers, progress=progress.update, force=force,
                    executor=executor,
                )
    except CCSMError as exc:
        from app.cli.messages import cli_message

        console.print(f"[red]error:[/red] {cli_message(exc)}", highlight=False, soft_wrap=True)
        raise typer.Exit(2) from None
    verb = "built" if rebuilt else "already current:"
    from app.cli.contour_issues import issues_phrase, report_contour_issues, report_skipped_features, write_report

    report_skipped_features(console, info.bad_features, report)
    issues = report_contour_issues(console, ccs_store, info.id, report)
    write_report(report, ccs_store, info.id, str(spec.path), info.bad_features)
    console.print(
        f"{verb} {info.id} -> {store_path} ({info.n_contours} contours, {info.n_vertices} vertices, "
        f"data_version {info.data_version}, {len(info.bad_features)} bad features, {issues_phrase(issues)})"
    )
    if publish is not None:
        publish_store(ccs_store, publish)
        console.print(f"published {store_path} as {publish}")


def publish_store(built: CCSStoreType, live: Path) -> None:
    """Point the live link at the built store (engine/store/switch.py).

    Exits with status 2 when ``live`` cannot become the link (see :func:`engine.store.switch.publish`).
    """
    from engine.errors import StoreError
    from engine.store.switch import publish

    built.close()
    try:
        publish(live, built.path)
    except StoreError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None


@contextmanager
def build_executor(scheduler: str | None, workers: int | None) -> Iterator[Executor | None]:
    """Where ``ccsm build`` runs its per-window and per-chunk work: the Dask cluster at ``scheduler``, else a
    pool of ``workers`` local processes (None: one per core), else (one worker) this process."""
    from engine.parallel import cores, dask_executor, local_pool

    if scheduler is not None:
        with dask_executor(scheduler) as executor:
            yield executor
        return
    workers = cores() if workers is None else workers
    if workers <= 1:
        yield None
        return
    with local_pool(workers) as pool:
        yield pool

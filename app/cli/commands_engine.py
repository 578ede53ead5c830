"""``ccsm simplify`` and ``ccsm evaluate``: the engine on the command line.

Bad input (unreadable file, unknown CRS, bad option) ends with a one-line message on stderr and exit status 2,
never a traceback (app/cli/__init__.py).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from app.cli import app
from app.cli.contour_issues import issues_phrase, report_contour_issues, report_skipped_features, write_report
from app.cli.lazy_progress import LazyProgress, progress_bar
from app.cli.messages import cli_message
from app.cli.terrain_options import SOURCE_HELP, BboxOption, DemZoomOption, open_source
from engine.errors import CCSMError
from engine.types import BadFeature

if TYPE_CHECKING:
    from engine.cartography.options import CartographyOptions
    from engine.evaluation.topology import ScaleTopology
    from engine.io.source import Source
    from engine.store.records import DatasetInfo
    from engine.store.store import CCSStore
    from engine.types import ContourSet

err_console = Console(stderr=True)
console = Console()

#: Output CRS names of ``--crs``.
OUTPUT_CRS = {"4326": "EPSG:4326", "3857": "EPSG:3857"}


def fail(message: str) -> NoReturn:
    """Print ``message`` on stderr and exit with status 2 (bad input)."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(code=2)


@contextmanager
def bad_input_exits() -> Iterator[None]:
    """Turn the engine's domain errors (bad input) into exit status 2 with the engine's message."""
    try:
        yield
    except CCSMError as exc:
        fail(cli_message(exc))


def check_scale(name: str, value: float) -> float:
    """A scale denominator option: positive and finite, else exit 2."""
    if not (math.isfinite(value) and value > 0):
        fail(f"{name} must be a positive scale denominator (e.g. 250000), got {value}")
    return float(value)


def output_crs(crs: str, source_crs: str) -> str:
    """The CRS ``--crs`` names: 4326, 3857, source, or any authority string pyproj knows (checked)."""
    from engine.io.crs import parse_crs

    value = crs.strip()
    if value.lower() == "source":
        return source_crs
    value = OUTPUT_CRS.get(value, value)
    parse_crs(value, where="--crs")  # SourceError -> exit 2
    return value


def _progress() -> Progress:
    return progress_bar(err_console)


def _bad_feature_table(bad: list[BadFeature], limit: int | None = None) -> Table:
    table = Table(title=f"{len(bad)} feature(s) left out", title_justify="left")
    table.add_column("id")
    table.add_column("reason")
    shown = bad if limit is None else bad[:limit]
    for b in shown:
        table.add_row(str(b.id), b.reason + (f" ({b.where})" if b.where else ""))
    return table


#: Build options shared by the commands that build a source: into the cache store (simplify, export), and into the
#: service's store (serve, build: elevation field and interval; their scales default to the service's settings).
SourceScaleOption = Annotated[float, typer.Option("--source-scale", help="Scale denominator of the input (t = 0).")]
TargetScaleOption = Annotated[
    float, typer.Option("--target-scale", help="Scale denominator of the CCS's target (t = 1).")
]
ElevationFieldOption = Annotated[
    str | None,
    typer.Option("--elevation-field", help="Elevation attribute of a contour file (found by name if omitted)."),
]
IntervalOption = Annotated[
    float | None,
    typer.Option(
        "--interval",
        min=0.0,
        help="Contour interval, in the source's vertical unit [contour files: from their levels; needed for a DEM].",
    ),
]

#: Cartography options of a source (docs/design.md section 9), shared by simplify and export.
UnitsOption = Annotated[
    str | None,
    typer.Option("--units", help="Vertical unit m, ft or fm (fathoms; default: as the source states it, else m)."),
]
IndexEveryOption = Annotated[int, typer.Option("--index-every", help="Index contours are every n-th interval.")]
AttributeNamesOption = Annotated[
    str, typer.Option("--attribute-names", help="Tile attribute names: ccsm (elevation) or maplibre-contour (ele).")
]
ScheduleOption = Annotated[
    str | None,
    typer.Option("--schedule", help="Interval schedule override STEP:HIDE_SCALE,...,STEP (default: the rule)."),
]
AttributionOption = Annotated[
    str | None, typer.Option("--attribution", help="Who made the data (TileJSON attribution).")
]
ReportOption = Annotated[
    Path | None,
    typer.Option(
        "--report",
        help="Write every skipped feature and every contour issue to FILE (.json or .csv); the terminal "
        "summarises them.",
        metavar="FILE",
    ),
]


def check_report(report: Path | None) -> None:
    """Exit 2 before any build when ``--report`` names a file of another format than JSON or CSV."""
    from app.cli.run_report import report_problem

    problem = report_problem(report)
    if problem is not None:
        fail(problem)


SeaOption = Annotated[
    str, typer.Option("--sea", help="The 0 m line: drop it, draw it as a coastline, or keep it as a contour.")
]
DepthLabelsOption = Annotated[
    str, typer.Option("--depth-labels", help="Negative levels labelled negative (-200 m) or below-datum (200 m).")
]
LabelOrientationOption = Annotated[
    str,
    typer.Option("--label-orientation", help="Label text top toward higher ground (uphill) or always upright."),
]


def cartography_options(
    units: str | None,
    index_every: int,
    attribute_names: str,
    schedule: str | None,
    attribution: str | None,
    sea: str = "drop",
    depth_labels: str = "negative",
    label_orientation: str = "uphill",
) -> CartographyOptions | None:
    """The cartography options given on the command line, checked (InvalidParameter names a bad one); None
    when all are at their defaults, so a source built without them is found in the cache again."""
    from engine.cartography.options import CartographyOptions

    options = CartographyOptions(
        units, index_every, attribute_names, schedule, attribution, sea, depth_labels, label_orientation
    )
    return None if options == CartographyOptions() else options.checked()


def _open_cache(path: Path, *, is_default: bool) -> CCSStore:
    """The store of built sources. The default one is only a cache: one of an older store format (left by an
    earlier version of ccsm) is replaced by a new one, as the content hashes would rebuild it anyway. A store
    given with ``--store`` is the user's, and is never replaced (its format error is shown)."""
    from engine.errors import StoreFormatError
    from engine.store.store import CCSStore

    try:
        return CCSStore(path)
    except StoreFormatError:
        if not is_default:
            raise
        for stale in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
            stale.unlink(missing_ok=True)
        return CCSStore(path)


def default_cache_store() -> Path:
    """Where ``ccsm simplify`` keeps what it builds, so a second scale or method costs seconds."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ccsm" / "sources.ccsm.sqlite"


@app.command()
def simplify(
    source: Annotated[str, typer.Argument(help=SOURCE_HELP)],
    scale: Annotated[
        float, typer.Option("--scale", help="Map scale denominator of the output (250000 for 1:250,000).")
    ] = 250_000.0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output GeoJSON file.")] = Path("simplified.geojson"),
    method: Annotated[
        str,
        typer.Option(
            "--method",
            help="ccsm, dp (Douglas-Peucker), wm (Wang-Mueller), vw (Visvalingam-Whyatt) or original.",
        ),
    ] = "ccsm",
    source_scale: SourceScaleOption = 50_000.0,
    target_scale: TargetScaleOption = 500_000.0,
    elevation_field: ElevationFieldOption = None,
    interval: IntervalOption = None,
    bbox: BboxOption = None,
    dem_zoom: DemZoomOption = None,
    crs: Annotated[str, typer.Option("--crs", help="Output CRS: 4326 (GeoJSON default), 3857 or source.")] = "4326",
    workers: Annotated[int | None, typer.Option("--workers", help="Worker processes (default: one per core).")] = None,
    store: Annotated[
        Path | None,
        typer.Option(
            "--store",
            help="Store that keeps built sources by content hash [$XDG_CACHE_HOME/ccsm/sources.ccsm.sqlite].",
        ),
    ] = None,
    all_levels: Annotated[
        bool,
        typer.Option("--all-levels", help="Keep the levels the interval schedule no longer draws at --scale."),
    ] = False,
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
    """Write every contour of SOURCE as it looks at one map scale.

    The source is built once into a store (by the hash of its bytes and the scales); later calls at other
    scales or with other methods read it from there. The answer is the same as ``GET /simplify``'s.
    """
    from engine.checks import check_method
    from engine.io.crs import parse_crs
    from engine.serve.renderer import Renderer
    from engine.serve.simplify import feature_collection
    from engine.serve.simplify import simplify as simplify_dataset

    method = method.strip().lower()
    scale = check_scale("--scale", scale)
    source_scale = check_scale("--source-scale", source_scale)
    target_scale = check_scale("--target-scale", target_scale)
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    check_report(report)
    started = time.perf_counter()
    with bad_input_exits():
        check_method(method)
        cartography = cartography_options(
            units, index_every, attribute_names, schedule, attribution, sea, depth_labels, label_orientation
        )
        opened = open_source(source, bbox, dem_zoom, source_scale)
        if isinstance(opened, Path) and not opened.exists():
            fail(f"{source}: file not found")
        cache, info = build_into_cache(
            opened,
            store,
            elevation_field=elevation_field,
            interval=interval,
            source_scale=source_scale,
            target_scale=target_scale,
            workers=workers,
            cartography=cartography,
        )
        to_crs = output_crs(crs, info.source_crs)
        result = simplify_dataset(Renderer(cache), info.id, scale, method=method, all_levels=all_levels)
        doc = feature_collection(
            result.contours,
            scale,
            method,
            crs=to_crs,
            decimals=7 if parse_crs(to_crs).is_geographic else 3,
            dropped=result.dropped,
        )
        write_json_atomically(out, doc)
    bad = [BadFeature(b["id"], b["reason"], b.get("where", "")) for b in info.bad_features]
    n_in = info.n_contours + len(bad)
    report_skipped_features(err_console, bad, report)
    issues = report_contour_issues(err_console, cache, info.id, report)
    write_report(report, cache, info.id, str(source), bad)
    console.print(
        f"{out}: {len(result.contours)} contours at 1:{scale:,.0f} ({method}, CRS {to_crs}); "
        f"{result.vanished} too small to show at this scale (left out); "
        f"{result.dropped} dropped (their level is not drawn at this scale); {len(bad)} bad feature(s); "
        f"{n_in} input feature(s); {issues_phrase(issues)}; {time.perf_counter() - started:.1f} s",
        highlight=False,
        soft_wrap=True,
    )


def build_into_cache(
    source: Source,
    store: Path | None,
    *,
    elevation_field: str | None,
    interval: float | None,
    source_scale: float,
    target_scale: float,
    workers: int | None,
    cartography: CartographyOptions | None = None,
) -> tuple[CCSStore, DatasetInfo]:
    """Build a source into the cache store (once per content hash of its bytes and scales), with a progress bar.

    The dataset id is ``src-`` and the hash's first 16 hex digits, so another scale or method of the same
    source, or an export of it, reuses the build.
    """
    from engine.build.datasets import SourceSpec, build_dataset, source_hash

    spec = SourceSpec(
        path=source.resolve() if isinstance(source, Path) else source,
        dataset="",
        name=source.stem,
        elevation_field=elevation_field,
        interval=interval,
        source_scale=source_scale,
        target_scale=target_scale,
        cartography=cartography,
    )
    spec = replace(spec, dataset="src-" + source_hash(spec.path, spec.params())[:16])
    store_path = store or default_cache_store()
    try:
        cache = _open_cache(store_path, is_default=store is None)
    except OSError as exc:
        fail(f"cannot open the store {store_path}: {exc.strerror or exc}")
    with LazyProgress(_progress, "building surfaces") as progress:  # drawn once the source is read
        info, _ = build_dataset(cache, spec, workers=workers, progress=progress.update)
    return cache, info


def write_json_atomically(path: Path, doc: dict[str, Any]) -> None:
    """Write JSON to a temporary file beside ``path`` and rename it: readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(doc, separators=(",", ":"), allow_nan=False))
    tmp.replace(path)


@app.command()
def evaluate(
    source: Annotated[Path, typer.Argument(help="Contour file or DEM to evaluate on.")],
    out: Annotated[
        Path, typer.Option("--out", help="Directory for the CSV tables, PNG figures and summary.md.")
    ] = Path("evaluation"),
    levels: Annotated[int, typer.Option("--levels", help="Results per method and contour (paper: 100).")] = 100,
    sample: Annotated[
        int | None, typer.Option("--sample", help="Evaluate this many random contours (default: all).")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sample and of the 20 table contours.")] = 0,
    source_scale: Annotated[float, typer.Option("--source-scale", help="Scale denominator of the input.")] = 50_000.0,
    target_scale: Annotated[float, typer.Option("--target-scale", help="Target scale for --target scale.")] = 500_000.0,
    target: Annotated[
        str, typer.Option("--target", help="extreme (paper Fig. 10: down to 2 points / a triangle) or scale.")
    ] = "extreme",
    crossing_step: Annotated[int, typer.Option("--crossing-step", help="Count crossings at every n-th level.")] = 1,
    table_contours: Annotated[
        int, typer.Option("--table-contours", help="Random contours of Table 2, Fig. 11, Table 3.")
    ] = 20,
    elevation_field: Annotated[
        str | None, typer.Option("--elevation-field", help="Elevation attribute of a contour file.")
    ] = None,
    interval: Annotated[float | None, typer.Option("--interval", help="Contour interval of a DEM source.")] = None,
    workers: Annotated[int | None, typer.Option("--workers", help="Worker processes (default: one per core).")] = None,
    topology_scales: Annotated[
        int,
        typer.Option(
            "--topology-scales",
            help="Count the pairs apart in the input that touch or cross at this many scales from the source "
            "scale to twice the target scale, per method (0: skip).",
        ),
    ] = 10,
) -> None:
    """Compare CCSM with DP, WM and VW as the paper's section 3.2 does; write tables and figures."""
    from engine.evaluation.pipeline import evaluate_set
    from engine.evaluation.report import write_report, write_topology
    from engine.io.source import read_source

    target = target.strip().lower()
    if target not in ("extreme", "scale"):
        fail(f"--target must be extreme or scale, got {target!r}")
    source_scale = check_scale("--source-scale", source_scale)
    target_scale = check_scale("--target-scale", target_scale)
    for name, value, low in (
        ("--levels", levels, 2),
        ("--crossing-step", crossing_step, 1),
        ("--table-contours", table_contours, 0),
        ("--topology-scales", topology_scales, 0),
    ):
        if value < low:
            fail(f"{name} must be >= {low}, got {value}")
    if sample is not None and sample < 1:
        fail(f"--sample must be >= 1, got {sample}")
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    started = time.perf_counter()
    with bad_input_exits():
        if not source.exists():
            fail(f"{source}: file not found")
        contour_set = read_source(source, elevation_field=elevation_field, interval=interval)
        with _progress() as progress:
            tasks: dict[str, Any] = {}

            def report(stage: str, done: int, total: int) -> None:
                if stage not in tasks:
                    tasks[stage] = progress.add_task(stage, total=total)
                progress.update(tasks[stage], completed=done, total=total)

            ev = evaluate_set(
                contour_set,
                levels=levels,
                sample=sample,
                seed=seed,
                target=target,
                source_scale=source_scale,
                target_scale=target_scale,
                workers=workers,
                crossing_step=crossing_step,
                table_contours=table_contours,
                progress=report,
            )
            topology = _scale_topology(contour_set, topology_scales, source_scale, target_scale, workers)
        runtime = time.perf_counter() - started
        written = write_report(ev, out, source=str(source), runtime_s=runtime)
        if topology is not None:
            written.append(write_topology(topology, out))
    if ev.bad_features:
        err_console.print(_bad_feature_table(ev.bad_features, limit=50))
    mean = ev.mean_curve()
    console.print(
        f"{out}: {len(written)} files; {len(ev.contour_ids)} contours x {levels} levels x {len(ev.methods)} methods "
        f"in {runtime:.1f} s",
        highlight=False,
        soft_wrap=True,
    )
    console.print(
        "mean Sim at the last level: "
        + ", ".join(f"{m} {mean[k, -1]:.4f}" for k, m in enumerate(ev.methods))
        + "; largest jump of the mean curve: "
        + ", ".join(f"{m} {j:.4f}" for m, j in zip(ev.methods, ev.mean_curve_jumps(), strict=True)),
        highlight=False,
        soft_wrap=True,
    )
    if topology is not None:
        console.print(_topology_table(topology))


def _scale_topology(
    contour_set: ContourSet, n_scales: int, source_scale: float, target_scale: float, workers: int | None
) -> ScaleTopology | None:
    """``evaluate --topology-scales``: the per-scale topology counts, or None when asked for none."""
    from engine.evaluation.topology import topology_by_scale, topology_scales

    if not n_scales:
        return None
    scales = topology_scales(source_scale, target_scale, n_scales)
    return topology_by_scale(
        contour_set, scales, source_scale=source_scale, target_scale=target_scale, workers=workers
    )


def _topology_table(topology: ScaleTopology) -> Table:
    """The per-scale topology counts as a console table."""
    table = Table(
        title=f"pairs apart in the input that touch or cross ({topology.input_pairs} pairs meeting in the input "
        "left out; ccsm as served)"
    )
    table.add_column("scale", justify="right")
    for method in topology.methods:
        table.add_column(method, justify="right")
    for scale, *counts in topology.rows():
        table.add_row(f"1:{scale:,.0f}", *(str(c) for c in counts))
    return table

"""``ccsm simplify`` and ``ccsm evaluate``: the engine on the command line.

Bad input (unreadable file, unknown CRS, bad option) ends with a one-line message on stderr and exit status 2,
never a traceback (app/cli/__init__.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from app.cli import app
from engine.errors import CCSMError
from engine.types import BadFeature

err_console = Console(stderr=True)
console = Console()

#: Simplification methods of ``ccsm simplify``.
SIMPLIFY_METHODS = ("ccsm", "dp", "wm", "vw")
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
        fail(str(exc))


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
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
        transient=False,
    )


def _bad_feature_table(bad: list[BadFeature], limit: int | None = None) -> Table:
    table = Table(title=f"{len(bad)} feature(s) left out", title_justify="left")
    table.add_column("id")
    table.add_column("reason")
    shown = bad if limit is None else bad[:limit]
    for b in shown:
        table.add_row(str(b.id), b.reason + (f" ({b.where})" if b.where else ""))
    return table


@app.command()
def simplify(
    source: Annotated[
        Path,
        typer.Argument(help="Contour file (GeoJSON, GeoPackage, Shapefile) or DEM (GeoTIFF, .asc, .npz)."),
    ],
    scale: Annotated[
        float, typer.Option("--scale", help="Map scale denominator of the output (250000 for 1:250,000).")
    ] = 250_000.0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output GeoJSON file.")] = Path(
        "simplified.geojson"
    ),
    method: Annotated[
        str,
        typer.Option(
            "--method", help="ccsm, dp (Douglas-Peucker), wm (Wang-Mueller) or vw (Visvalingam-Whyatt)."
        ),
    ] = "ccsm",
    source_scale: Annotated[
        float, typer.Option("--source-scale", help="Scale denominator of the input (t = 0).")
    ] = 50_000.0,
    target_scale: Annotated[
        float, typer.Option("--target-scale", help="Scale denominator of the CCS's target (t = 1).")
    ] = 500_000.0,
    elevation_field: Annotated[
        str | None,
        typer.Option(
            "--elevation-field", help="Elevation attribute of a contour file (found by name if omitted)."
        ),
    ] = None,
    interval: Annotated[
        float | None,
        typer.Option("--interval", help="Contour interval of a DEM source, in its vertical unit."),
    ] = None,
    crs: Annotated[
        str, typer.Option("--crs", help="Output CRS: 4326 (GeoJSON default), 3857 or source.")
    ] = "4326",
    workers: Annotated[
        int | None, typer.Option("--workers", help="Worker processes (default: one per core).")
    ] = None,
) -> None:
    """Write every contour of SOURCE as it looks at one map scale."""
    from engine.baselines import simplify_at_scale
    from engine.ccsm.build import build_contour_set
    from engine.ccsm.regression import t_for_scale
    from engine.ccsm.similarity import SimilarityReference
    from engine.evaluation.levels import rotate_ring_to
    from engine.io.source import read_source, write_geojson
    from engine.params import BuildParams

    method = method.strip().lower()
    if method not in SIMPLIFY_METHODS:
        fail(f"unknown method {method!r}; expected one of {', '.join(SIMPLIFY_METHODS)}")
    scale = check_scale("--scale", scale)
    source_scale = check_scale("--source-scale", source_scale)
    target_scale = check_scale("--target-scale", target_scale)
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    started = time.perf_counter()
    with bad_input_exits():
        params = BuildParams(source_scale=source_scale, target_scale=target_scale)
        if not source.exists():
            fail(f"{source}: file not found")
        contour_set = read_source(source, elevation_field=elevation_field, interval=interval)
        to_crs = output_crs(crs, contour_set.source_crs)
        by_id = {c.id: c for c in contour_set.contours}
        features: list[tuple[Any, bool, dict[str, Any]]] = []
        vanished: list[Any] = []
        bad: list[BadFeature]
        if method == "ccsm":
            with _progress() as progress:
                task = progress.add_task("building surfaces", total=len(contour_set.contours))
                built = build_contour_set(
                    contour_set,
                    params,
                    workers=workers,
                    progress=lambda d, t: progress.update(task, completed=d, total=t),
                )
            bad = built.bad_features
            for ccs in built.surfaces:
                if ccs.vanish_scale <= scale:
                    vanished.append(ccs.contour_id)
                    continue
                t = t_for_scale(built.model.ladder, ccs.t_at_scale, scale)
                path = ccs.at(t)
                geom = path[:-1] if ccs.closed else path
                initial = by_id[ccs.contour_id].coords
                if ccs.closed:
                    initial = rotate_ring_to(initial, ccs.base[0])
                sim = SimilarityReference.of(initial, ccs.closed, params.similarity_spacing_m).similarity(
                    geom
                )
                props = {
                    "id": ccs.contour_id,
                    "elevation": ccs.elevation,
                    "t": t,
                    "similarity": sim,
                    "scale": scale,
                }
                features.append((geom, ccs.closed, props))
        else:
            bad = list(contour_set.bad_features)
            with _progress() as progress:
                task = progress.add_task(f"simplifying ({method})", total=len(contour_set.contours))
                for c in contour_set.contours:
                    try:
                        geom = simplify_at_scale(method, c.coords, c.closed, scale)
                        sim = SimilarityReference.of(
                            c.coords, c.closed, params.similarity_spacing_m
                        ).similarity(geom)
                    except CCSMError as exc:
                        bad.append(BadFeature(c.id, str(exc)))
                        continue
                    finally:
                        progress.advance(task)
                    props = {
                        "id": c.id,
                        "elevation": c.elevation,
                        "t": None,
                        "similarity": sim,
                        "scale": scale,
                    }
                    features.append((geom, c.closed, props))
        out.parent.mkdir(parents=True, exist_ok=True)
        write_geojson(out, features, from_crs=contour_set.working_crs, to_crs=to_crs)
    n_in = len(contour_set.contours) + len(contour_set.bad_features)
    if bad:
        err_console.print(_bad_feature_table(bad))
    console.print(
        f"{out}: {len(features)} contours at 1:{scale:,.0f} ({method}, CRS {to_crs}); "
        f"{len(vanished)} too small to show at this scale (left out); {len(bad)} bad feature(s); "
        f"{n_in} input feature(s); {time.perf_counter() - started:.1f} s",
        highlight=False,
        soft_wrap=True,
    )


@app.command()
def evaluate(
    source: Annotated[Path, typer.Argument(help="Contour file or DEM to evaluate on.")],
    out: Annotated[
        Path, typer.Option("--out", help="Directory for the CSV tables, PNG figures and summary.md.")
    ] = Path("evaluation"),
    levels: Annotated[
        int, typer.Option("--levels", help="Results per method and contour (paper: 100).")
    ] = 100,
    sample: Annotated[
        int | None, typer.Option("--sample", help="Evaluate this many random contours (default: all).")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sample and of the 20 table contours.")] = 0,
    source_scale: Annotated[
        float, typer.Option("--source-scale", help="Scale denominator of the input.")
    ] = 50_000.0,
    target_scale: Annotated[
        float, typer.Option("--target-scale", help="Target scale for --target scale.")
    ] = 500_000.0,
    target: Annotated[
        str, typer.Option("--target", help="extreme (paper Fig. 10: down to 2 points / a triangle) or scale.")
    ] = "extreme",
    crossing_step: Annotated[
        int, typer.Option("--crossing-step", help="Count crossings at every n-th level.")
    ] = 1,
    table_contours: Annotated[
        int, typer.Option("--table-contours", help="Random contours of Table 2, Fig. 11, Table 3.")
    ] = 20,
    elevation_field: Annotated[
        str | None, typer.Option("--elevation-field", help="Elevation attribute of a contour file.")
    ] = None,
    interval: Annotated[
        float | None, typer.Option("--interval", help="Contour interval of a DEM source.")
    ] = None,
    workers: Annotated[
        int | None, typer.Option("--workers", help="Worker processes (default: one per core).")
    ] = None,
) -> None:
    """Compare CCSM with DP, WM and VW as the paper's section 3.2 does; write tables and figures."""
    from engine.evaluation.pipeline import evaluate_set
    from engine.evaluation.report import write_report
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
        runtime = time.perf_counter() - started
        written = write_report(ev, out, source=str(source), runtime_s=runtime)
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

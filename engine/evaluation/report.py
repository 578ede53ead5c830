"""Write an :class:`~engine.evaluation.pipeline.Evaluation` as CSV tables, PNG figures (matplotlib Agg) and
a ``summary.md``."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from engine.evaluation.measures import SAME_SCALE_WINDOW
from engine.evaluation.pipeline import PAPER_METHODS, RISE_TOLERANCE, Evaluation, finite_mean, pooled_errors
from engine.evaluation.topology import ScaleTopology

LABELS = {"ccsm": "CCSM", "dp": "DP", "wm": "WM", "vw": "VW"}
COLOURS = {"ccsm": "#e6a100", "dp": "#1f5fbf", "wm": "#2a9d3a", "vw": "#b03a8c"}
#: Levels whose mean similarity the summary lists (1-based, as the paper numbers them), for 100 levels.
HEADLINE_LEVELS = (1, 25, 50, 75, 100)

FILES = (
    "fig10_similarity.csv",
    "fig10_similarity.png",
    "jumps.csv",
    "fig_jumps.png",
    "crossings.csv",
    "fig_crossings.png",
    "table2_maav.csv",
    "fig11_linear_density.csv",
    "fig11_linear_density.png",
    "table3_positional_error.csv",
    "summary.md",
)


def _write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[Any]], comment: str = "") -> None:
    with path.open("w", newline="") as f:
        if comment:
            f.write(f"# {comment}\n")
        w = csv.writer(f)
        w.writerow(header)
        for row in rows:
            w.writerow([_fmt(v) for v in row])


def _every_level(step: int) -> str:
    """Which levels were counted: every level, or one level in ``step`` (a subset)."""
    return "every level" if step == 1 else f"one level in {step} (a subset)"


def _fmt(v: Any) -> Any:
    if isinstance(v, float | np.floating):
        return "nan" if not math.isfinite(float(v)) else f"{float(v):.9g}"
    return v


def _pyplot() -> Any:  # matplotlib.pyplot, a module: imported late so the engine loads without a display
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_figure(plt: Any, fig: Any, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)  # pyplot keeps every open figure alive until it is closed


def _finish_level_plot(plt: Any, ax: Any, path: Path, *, xlabel: str, ylabel: str, title: str) -> None:
    # The line plots over the levels (one line per method) share their look: grid, legend.
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    _save_figure(plt, ax.figure, path)


def headline_levels(levels: int) -> list[int]:
    """1-based levels the summary lists: 1, 25, 50, 75, 100 scaled to ``levels``."""
    return sorted({max(1, min(levels, round(k * levels / 100))) for k in HEADLINE_LEVELS})


def write_report(
    ev: Evaluation, out_dir: str | Path, *, source: str = "", runtime_s: float | None = None
) -> list[Path]:
    """Write every table, figure and the summary into ``out_dir`` (created); returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plt = _pyplot()
    methods = list(ev.methods)
    lv = np.arange(1, ev.levels + 1)
    mean = ev.mean_curve()
    n = len(ev.contour_ids)

    # Fig. 10
    _write_csv(
        out / "fig10_similarity.csv",
        ["level", *[f"{m}_mean" for m in methods], *[f"{m}_std" for m in methods]],
        ([int(i), *mean[:, i - 1], *ev.sims[:, :, i - 1].std(axis=0)] for i in lv),
        comment=f"mean Sim(L0, level) over {n} contours; target={ev.target}",
    )
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for k, m in enumerate(methods):
        ax.plot(lv, mean[k], label=LABELS[m], color=COLOURS[m], lw=1.8 if m == "ccsm" else 1.3)
    _finish_level_plot(
        plt,
        ax,
        out / "fig10_similarity.png",
        xlabel=f"level i (1 = initial contour, {ev.levels} = most simplified)",
        ylabel="mean similarity",
        title=f"Fig. 10: shape similarity by level ({n} contours)",
    )

    # Jumps
    cj = ev.contour_jumps()
    mj = ev.mean_curve_jumps()
    cr = ev.contour_rises()
    rising = ev.contours_rising()
    mr = ev.mean_curve_rises()
    at = [int(np.argmax(np.abs(np.diff(mean[k])))) + 1 for k in range(len(methods))]
    _write_csv(
        out / "jumps.csv",
        [
            "method",
            "contour_jump_mean",
            "contour_jump_median",
            "contour_jump_max",
            "mean_curve_jump",
            "mean_curve_jump_at_level",
            "contours_rising",
            "contour_rise_max",
            "mean_curve_rise_max",
        ],
        (
            [
                m,
                cj[:, k].mean(),
                float(np.median(cj[:, k])),
                cj[:, k].max(),
                mj[k],
                at[k],
                int(rising[k]),
                cr[:, k].max(),
                mr[k],
            ]
            for k, m in enumerate(methods)
        ),
        comment="largest |Sim(i+1) - Sim(i)| per contour (mean/median/max over contours) and of the mean curve; "
        "jump_at_level = i of the pair (i, i+1), 1-based; contours_rising = contours whose Sim rises by more "
        f"than {RISE_TOLERANCE:g} between two levels somewhere",
    )
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), dpi=120)
    x = np.arange(len(methods))
    axes[0].bar(x - 0.2, cj.mean(axis=0), 0.4, label="mean over contours", color="#777")
    axes[0].bar(x + 0.2, mj, 0.4, label="of the mean curve", color="#e6a100")
    axes[0].set_xticks(x, [LABELS[m] for m in methods])
    axes[0].set_ylabel("largest jump |Sim(i+1) - Sim(i)|")
    axes[0].legend(fontsize=8)
    axes[0].set_title("Largest jump between consecutive levels")
    for k, m in enumerate(methods):
        axes[1].plot(lv[1:], np.abs(np.diff(mean[k])), color=COLOURS[m], label=LABELS[m])
    axes[1].set_xlabel("level i")
    axes[1].set_ylabel("|mean Sim(i) - mean Sim(i-1)|")
    axes[1].set_yscale("log")
    axes[1].legend(fontsize=8)
    axes[1].grid(alpha=0.3)
    _save_figure(plt, fig, out / "fig_jumps.png")

    # Crossings
    _write_csv(
        out / "crossings.csv",
        ["method", "level", "pairs_intersecting", "pairs_crossing"],
        ([m, lvl + 1, hit, cross] for m, lvl, hit, cross in ev.crossings),
        comment="pairs of different contours that meet / properly cross at a level (1-based); "
        + _every_level(ev.crossing_step)
        + " counted",
    )
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for m in methods:
        rows = [r for r in ev.crossings if r[0] == m]
        ax.plot([r[1] + 1 for r in rows], [r[2] for r in rows], color=COLOURS[m], label=LABELS[m], marker=".")
    _finish_level_plot(
        plt,
        ax,
        out / "fig_crossings.png",
        xlabel="level i",
        ylabel="pairs of contours that meet or cross",
        title=f"Crossings between different contours ({n} contours)",
    )

    # Table 2, Fig. 11, Table 3
    tables = ev.table_contours
    idx = {m: k for k, m in enumerate(methods)}
    pairs = [("dp", "ccsm"), ("dp", "wm"), ("wm", "ccsm"), ("vw", "ccsm"), ("vw", "dp"), ("vw", "wm")]
    _write_csv(
        out / "table2_maav.csv",
        [
            "contour",
            "id",
            "n_vertices",
            "closed",
            "groups",
            *[f"sd_{a}_{b}" for a, b in pairs],
            "maav",
            "maav_with_vw",
            "below_0.002",
            "vw_in_window",
        ],
        (
            [
                k + 1,
                t.contour_id,
                t.n_vertices,
                t.closed,
                len(t.groups),
                *[t.sd[idx[a], idx[b]] for a, b in pairs],
                t.maav,
                t.maav_with_vw,
                t.maav < SAME_SCALE_WINDOW,
                t.vw_in_window,
            ]
            for k, t in enumerate(tables)
        ),
        comment=f"paper eq. 11 over CCSM/DP/WM same-scale groups (window {SAME_SCALE_WINDOW}); VW = its level "
        f"nearest each group's mean similarity; seed {ev.seed}",
    )
    _write_csv(
        out / "fig11_linear_density.csv",
        ["contour", "id", *methods],
        ([k + 1, t.contour_id, *[t.linear_density[m] for m in methods]] for k, t in enumerate(tables)),
        comment="eq. 12: length / area(buffer(width = std of positional error)), 1/m, "
        "mean over the contour's same-scale groups",
    )
    fig, ax = plt.subplots(figsize=(9, 4), dpi=120)
    xs = np.arange(1, len(tables) + 1)
    w = 0.8 / len(methods)
    for k, m in enumerate(methods):
        ax.bar(
            xs + (k - (len(methods) - 1) / 2) * w,
            [t.linear_density[m] for t in tables],
            w,
            label=LABELS[m],
            color=COLOURS[m],
        )
    ax.set_xticks(xs)
    ax.set_xlabel("contour #")
    ax.set_ylabel("linear density (1/m)")
    ax.set_yscale("log")
    ax.set_title("Fig. 11: linear density at the same scale")
    ax.legend(fontsize=8)
    _save_figure(plt, fig, out / "fig11_linear_density.png")
    errors = pooled_errors(tables)
    _write_csv(
        out / "table3_positional_error.csv",
        ["method", "mean_m", "std_m", "max_m", "n_errors", "results"],
        (
            [
                m,
                errors[m].mean_m,
                errors[m].std_m,
                errors[m].max_m,
                errors[m].n,
                sum(len(t.groups) for t in tables),
            ]
            for m in methods
        ),
        comment="eq. 13: distance of every initial vertex to the simplified polyline, "
        "pooled over the same-scale results",
    )

    _write_summary(out / "summary.md", ev, source, runtime_s, mj, cj, errors)
    return [out / f for f in FILES]


def _write_summary(
    path: Path, ev: Evaluation, source: str, runtime_s: float | None, mj: Any, cj: Any, errors: Any
) -> None:
    methods = list(ev.methods)
    mean = ev.mean_curve()
    hl = headline_levels(ev.levels)
    lines = [
        "# ccsm evaluate: summary",
        "",
        f"- source: `{source}`" if source else "- source: (in memory)",
        f"- contours evaluated: {len(ev.contour_ids)} of {ev.n_input} ({int(ev.closed.sum())} rings); "
        f"left out: {len(ev.bad_features)}",
        f"- levels per method: {ev.levels}; target: {ev.target}; seed: {ev.seed}",
    ]
    if runtime_s is not None:
        lines.append(
            f"- runtime: {runtime_s:.1f} s ("
            + ", ".join(f"{k} {v:.1f} s" for k, v in ev.timings.items())
            + ")"
        )
    lines += [
        "",
        "## Fig. 10: mean similarity by level",
        "",
        "| level | " + " | ".join(LABELS[m] for m in methods) + " |",
        "|---" * (len(methods) + 1) + "|",
    ]
    for i in hl:
        lines.append(f"| {i} | " + " | ".join(f"{mean[k, i - 1]:.4f}" for k in range(len(methods))) + " |")
    cr = ev.contour_rises()
    rising = ev.contours_rising()
    mr = ev.mean_curve_rises()
    lines += [
        "",
        "## Largest jump between consecutive levels",
        "",
        "| method | mean curve | per contour, mean | per contour, max | largest rise of the mean curve "
        f"| contours whose Sim rises (> {RISE_TOLERANCE:g}) | largest rise of one contour |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, m in enumerate(methods):
        lines.append(
            f"| {LABELS[m]} | {mj[k]:.4f} | {cj[:, k].mean():.4f} | {cj[:, k].max():.4f} | {mr[k]:.2e} "
            f"| {rising[k]} of {len(cr)} | {cr[:, k].max():.2e} |"
        )
    lines += [
        "",
        f"## Crossings between different contours ({_every_level(ev.crossing_step)})",
        "",
        "| method | levels with any | max pairs meeting | max pairs crossing |",
        "|---|---|---|---|",
    ]
    for m in methods:
        rows = [r for r in ev.crossings if r[0] == m]
        with_any = sum(1 for r in rows if r[2] > 0)
        lines.append(
            f"| {LABELS[m]} | {with_any} of {len(rows)} | {max(r[2] for r in rows)} | {max(r[3] for r in rows)} |"
        )
    tables = ev.table_contours
    if tables:
        maavs = [t.maav for t in tables]
        lines += [
            "",
            f"## Same-scale comparison ({len(tables)} random contours, {sum(len(t.groups) for t in tables)} groups)",
            "",
            f"- MAAV (eq. 11, CCSM/DP/WM): mean {np.mean(maavs):.5f}, max {np.max(maavs):.5f}; "
            f"{sum(v < SAME_SCALE_WINDOW for v in maavs)} of {len(tables)} below {SAME_SCALE_WINDOW}",
            f"- MAAV with VW: mean {np.mean([t.maav_with_vw for t in tables]):.5f}; VW members within the window: "
            f"{sum(t.vw_in_window for t in tables)} of {sum(len(t.groups) for t in tables)}",
            "- linear density (eq. 12, mean over contours, 1/m): "
            + ", ".join(
                f"{LABELS[m]} {finite_mean([t.linear_density[m] for t in tables]):.5f}" for m in methods
            ),
            "",
            "| method | positional error mean (m) | std (m) | max (m) |",
            "|---|---|---|---|",
        ]
        for m in methods:
            e = errors[m]
            lines.append(f"| {LABELS[m]} | {e.mean_m:.2f} | {e.std_m:.2f} | {e.max_m:.2f} |")
        lines.append("")
        lines.append(f"(The paper's Table 2 used the three methods {', '.join(LABELS[m] for m in PAPER_METHODS)}.)")
    path.write_text("\n".join(lines) + "\n")


#: The file of the per-scale topology table (``ccsm evaluate --topology-scales``).
TOPOLOGY_FILE = "topology_by_scale.csv"


def write_topology(topology: ScaleTopology, out_dir: str | Path) -> Path:
    """Write the pairs apart in the input that touch or cross, per scale and method, as CSV; returns its path."""
    path = Path(out_dir) / TOPOLOGY_FILE
    _write_csv(
        path,
        ["scale", *topology.methods],
        ([round(row[0]), *row[1:]] for row in topology.rows()),
        comment=f"pairs of contours apart in the input that touch or cross; {topology.contours} contours, "
        f"{topology.input_pairs} pairs already meeting in the input left out; ccsm as served",
    )
    return path

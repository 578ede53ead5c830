"""The CLI's report of the contours a build serves without part of their build (no label, input geometry),
and of the features it skipped: a table when few, else one summary line per kind (app/cli/feature_summary.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console

from app.cli.feature_summary import print_rows
from app.cli.run_report import write_run_report

if TYPE_CHECKING:
    from engine.store.store import CCSStore

#: Where the terminal's summary says the full list is when no ``--report`` was given.
REPORT_HINT = "--report FILE"


def report_contour_issues(console: Console, store: CCSStore, dataset: str, report: Path | None = None) -> int:
    """Print the dataset's contour issues (when it has any) on ``console``; returns how many."""
    issues, total = store.contour_issues(dataset)
    if not total:
        return 0
    title = f"{total} contour(s) served without part of their build"
    if total > len(issues):
        title += f" (the first {len(issues)} summarised)"
    print_rows(
        console,
        [(str(i["fid"]), str(i["id"]), i["step"], i["reason"]) for i in issues],
        [(str(i["id"]), f"{i['step']}: {i['reason']}") for i in issues],
        title=title,
        columns=("fid", "id", "step", "reason"),
        what=("contour served without", "contours served without"),
        where_all=str(report or REPORT_HINT),
    )
    return total


def report_skipped_features(console: Console, skipped: Sequence[Any], report: Path | None = None) -> None:
    """Print the features a build left out (``BadFeature``\\ s or their JSON objects), when there are any."""
    rows = [_skipped_row(b) for b in skipped]
    if rows:
        print_rows(
            console,
            rows,
            rows,
            title=f"{len(rows)} feature(s) left out",
            columns=("id", "reason"),
            what=("feature skipped", "features skipped"),
            where_all=str(report or REPORT_HINT),
        )


def _as_dict(bad: Any) -> dict[str, Any]:
    """A skipped feature as the store keeps it (a ``BadFeature`` is turned into its JSON object)."""
    return bad if isinstance(bad, dict) else {"id": bad.id, "reason": bad.reason, "where": bad.where}


def _skipped_row(bad: Any) -> tuple[str, str]:
    b = _as_dict(bad)
    return str(b["id"]), b["reason"] + (f" ({b['where']})" if b.get("where") else "")


def write_report(report: Path | None, store: CCSStore, dataset: str, source: str, skipped: Sequence[Any]) -> None:
    """``--report FILE``: every skipped feature and every contour issue of the dataset (nothing when None)."""
    if report is None:
        return
    _, total = store.contour_issues(dataset, limit=0)
    issues, _ = store.contour_issues(dataset, limit=total)
    write_run_report(report, source=source, dataset=dataset, skipped=[_as_dict(b) for b in skipped], issues=issues)


def issues_phrase(total: int) -> str:
    """The summary line's part on contour issues."""
    return f"{total} contour(s) served without part of their build"

"""The CLI's report of the contours a build serves without part of their build (no label, input geometry)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from engine.store.store import CCSStore

#: Issues the console table shows at most (the count is always given in full).
SHOWN = 50


def report_contour_issues(console: Console, store: CCSStore, dataset: str) -> int:
    """Print a table of the dataset's contour issues (when it has any) on ``console``; returns how many."""
    issues, total = store.contour_issues(dataset)
    if not total:
        return 0
    table = Table(
        title=f"{total} contour(s) served without part of their build", title_justify="left", show_lines=False
    )
    for column in ("fid", "id", "step", "reason"):
        table.add_column(column)
    for issue in issues[:SHOWN]:
        table.add_row(str(issue["fid"]), str(issue["id"]), issue["step"], issue["reason"])
    console.print(table)
    if total > SHOWN:
        console.print(f"... and {total - SHOWN} more (GET /datasets/{dataset} lists them)", highlight=False)
    return total


def issues_phrase(total: int) -> str:
    """The summary line's part on contour issues."""
    return f"{total} contour(s) served without part of their build"

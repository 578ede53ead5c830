"""Per-feature warnings summarised: one line per kind of reason, with its count and the first few ids.

A DEM of whole-number heights yields hundreds of tiny rings around grid nodes, each skipped with the same
reason; a row for each buries the summary. Few rows are still shown as a table; the full list goes to
``--report FILE`` (app/cli/run_report.py).
"""

from __future__ import annotations

from collections.abc import Sequence

from rich.console import Console
from rich.table import Table

#: Up to this many rows are shown as a table, one row each; more are summarised by kind.
TABLE_ROWS = 10

#: Ids named on a summary line.
SHOWN_IDS = 5


def summary_lines(rows: Sequence[tuple[str, str]], what: tuple[str, str], where_all: str) -> list[str]:
    """One line per kind of reason among ``rows`` (id, reason), most frequent first.

    The kind is the reason up to its first colon ("degenerate contour: grid nodes lie at 250, ..."); the first
    reason of a kind is quoted whole as its example. ``what`` is the noun phrase for one and for many rows.

    >>> summary_lines([("1", "bad: x"), ("2", "bad: y")], ("contour skipped", "contours skipped"), "r.json")
    ['2 contours skipped: bad (e.g. x) — ids 1, 2; all in r.json']
    """
    ids: dict[str, list[str]] = {}
    example: dict[str, str] = {}
    for ident, reason in rows:
        kind, _, detail = " ".join(reason.split()).partition(": ")
        ids.setdefault(kind, []).append(ident)
        example.setdefault(kind, detail)
    lines = []
    for kind, kind_ids in sorted(ids.items(), key=lambda item: -len(item[1])):
        shown = ", ".join(kind_ids[:SHOWN_IDS]) + (", …" if len(kind_ids) > SHOWN_IDS else "")
        noun = what[0] if len(kind_ids) == 1 else what[1]
        detail = f" (e.g. {example[kind]})" if example[kind] else ""
        lines.append(f"{len(kind_ids)} {noun}: {kind}{detail} — ids {shown}; all in {where_all}")
    return lines


def print_rows(
    console: Console,
    rows: Sequence[tuple[str, ...]],
    summary: Sequence[tuple[str, str]],
    *,
    title: str,
    columns: Sequence[str],
    what: tuple[str, str],
    where_all: str,
) -> None:
    """A table of ``rows`` when there are few, else the :func:`summary_lines` of ``summary`` (id, reason)."""
    if len(rows) <= TABLE_ROWS:
        table = Table(title=title, title_justify="left")
        for column in columns:
            table.add_column(column)
        for row in rows:
            table.add_row(*row)
        console.print(table)
        return
    console.print(title, highlight=False, soft_wrap=True)
    for line in summary_lines(summary, what, where_all):
        console.print("  " + line, highlight=False, soft_wrap=True, markup=False)

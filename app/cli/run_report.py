"""``--report FILE``: every feature a build skipped and every contour issue, as JSON or CSV.

The terminal shows them summarised (app/cli/feature_summary.py); the report lists each one.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: Report formats, by the file's extension.
REPORT_SUFFIXES = (".json", ".csv")

#: The CSV report's columns: ``kind`` is ``skipped_feature`` or ``contour_issue``.
CSV_COLUMNS = ("kind", "id", "reason", "where", "fid", "step")


def report_problem(path: Path | None) -> str | None:
    """Why ``--report`` cannot be written as given, or None (checked before any build)."""
    if path is None or path.suffix.lower() in REPORT_SUFFIXES:
        return None
    return f"--report {path}: give a .json or .csv file"


def write_run_report(
    path: Path,
    *,
    source: str,
    dataset: str,
    skipped: Sequence[dict[str, Any]],
    issues: Sequence[dict[str, Any]],
) -> None:
    """Write the report (JSON or CSV by ``path``'s extension) through a temporary file beside it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    skipped_rows = [{"id": str(b["id"]), "reason": b["reason"], "where": b.get("where", "")} for b in skipped]
    issue_rows = [{"fid": i["fid"], "id": str(i["id"]), "step": i["step"], "reason": i["reason"]} for i in issues]
    if path.suffix.lower() == ".csv":
        with tmp.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, CSV_COLUMNS, restval="")
            writer.writeheader()
            writer.writerows({"kind": "skipped_feature", **row} for row in skipped_rows)
            writer.writerows({"kind": "contour_issue", **row} for row in issue_rows)
    else:
        doc = {"source": source, "dataset": dataset, "skipped_features": skipped_rows, "contour_issues": issue_rows}
        tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(path)

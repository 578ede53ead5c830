"""The command line's progress bars, and one that appears only once its work's size is known.

A bar started before the input is read draws ``0/?`` and stays on the terminal above the error of a bad
input; :class:`LazyProgress` starts at the first report that gives a total, which the engine makes once the input
is open.
"""

from __future__ import annotations

from collections.abc import Callable
from types import TracebackType

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TaskID,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


def progress_bar(console: Console, *, time_left: bool = False, description: str = "{task.description}") -> Progress:
    """A bar as every command draws one: what is done, the bar, steps done of the total and the time spent; with
    ``time_left`` also the share done and the time still to go (for work of many minutes, such as an export)."""
    columns: list[ProgressColumn] = [TextColumn(description), BarColumn(), MofNCompleteColumn()]
    if time_left:
        columns.append(TaskProgressColumn())
    columns.append(TimeElapsedColumn())
    if time_left:
        columns.append(TimeRemainingColumn())
    # Four redraws a second read as smooth; rich's ten had its drawing thread take 3 % of a core from the build.
    return Progress(*columns, console=console, transient=False, refresh_per_second=4)


class LazyProgress:
    """A context manager whose :meth:`update` draws one task's bar from the first report with a total."""

    def __init__(self, make: Callable[[], Progress], description: str) -> None:
        self._make = make
        self._description = description
        self._progress: Progress | None = None
        self._task: TaskID | None = None

    def update(self, done: int, total: int | None) -> None:
        """Report ``done`` of ``total`` steps; nothing is drawn while the total is unknown."""
        if self._progress is None:
            if total is None:
                return
            self._progress = self._make()
            self._progress.start()
            self._task = self._progress.add_task(self._description, total=total)
        assert self._task is not None
        self._progress.update(self._task, completed=done, total=total)

    def __enter__(self) -> LazyProgress:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._progress is not None:
            self._progress.stop()

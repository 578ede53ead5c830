"""A progress bar that appears only once its work's size is known.

A bar started before the input is read draws ``0/?`` and stays on the terminal above the error of a bad
input; this one starts at the first report that gives a total, which the engine makes once the input is open.
"""

from __future__ import annotations

from collections.abc import Callable
from types import TracebackType

from rich.progress import Progress, TaskID


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

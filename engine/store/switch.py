"""Replicas switch to a new store atomically: the live store path is a symbolic link to a built store file.

A new build is written to its own file beside the live one (``ccsm build --store NEW --publish LIVE``); when it
is complete, :func:`publish` points the link at it with one ``rename``, which POSIX makes atomic: a reader
resolving the link sees the old file or the new one, never neither. A serving process follows the link with a
:class:`StorePointer`: it opens each store by its resolved file (never through the link, so a connection opened
late cannot land in the other store) and, when the link moves, opens the new file for the requests that start
from then on while requests already running finish on the old one. The old file is left in place; removing it
is the operator's choice once no replica serves it.
"""

from __future__ import annotations

import os
import sqlite3
import threading
import time
from pathlib import Path

from engine.errors import StoreError

#: A follower looks at the link at most this often (seconds): a switch shows within this delay.
CHECK_EVERY_S = 0.25


def publish(live: str | os.PathLike[str], built: str | os.PathLike[str]) -> Path:
    """Point the link ``live`` at the store file ``built`` in one atomic step; returns the resolved target.

    Raises
    ------
    StoreError
        ``built`` does not exist, or ``live`` exists and is a plain file (a store cannot become a link
        without a moment where its path is missing or wrong; move it beside it and publish it first).
    """
    live, target = Path(live), Path(built).resolve()
    if not target.is_file():
        raise StoreError(f"cannot publish {built}: no such store file")
    if live.exists() and not live.is_symlink():
        raise StoreError(f"cannot publish to {live}: it is a plain file, not a link to a store")
    _fold_write_ahead_log(target)
    live.parent.mkdir(parents=True, exist_ok=True)
    temporary = live.with_name(f".{live.name}.{os.getpid()}.{threading.get_ident()}.link")
    temporary.unlink(missing_ok=True)
    os.symlink(target, temporary)
    os.replace(temporary, live)  # rename(2): atomic
    return target


def _fold_write_ahead_log(path: Path) -> None:
    """Write the build's WAL into the store file, so a replica opens one complete file."""
    try:
        con = sqlite3.connect(f"file:{path}?mode=rw", uri=True, timeout=60.0)
        try:
            con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        finally:
            con.close()
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"cannot publish {path.name}: {exc}") from exc


class StorePointer:
    """Follows a live store path: :meth:`moved` tells when the link points at another file."""

    def __init__(self, live: str | os.PathLike[str]) -> None:
        self.live = Path(live)
        self.target = self.resolve()
        self._checked = time.monotonic()
        self._lock = threading.Lock()

    def resolve(self) -> Path:
        """The store file the live path names now."""
        return Path(os.path.realpath(self.live))

    @property
    def follows(self) -> bool:
        """True when the live path is a link (a plain store file never moves)."""
        return self.live.is_symlink()

    def moved(self) -> Path | None:
        """The new target if the link moved since the last call that said so, else None (checked at most
        every :data:`CHECK_EVERY_S` seconds)."""
        now = time.monotonic()
        if now - self._checked < CHECK_EVERY_S:
            return None
        with self._lock:
            self._checked = now
            target = self.resolve()
            if target == self.target or not target.is_file():
                return None
            self.target = target
            return target

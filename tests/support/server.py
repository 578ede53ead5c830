"""Waiting on a service under test (a TestClient or an httpx client on a live server)."""

from __future__ import annotations

import time
from typing import Any, Protocol


class _Getter(Protocol):
    def get(self, url: str) -> Any: ...


def wait_ready(client: _Getter, ident: str, timeout: float = 120.0) -> dict[str, Any]:
    """The dataset's detail once its build has ended (``ready`` or ``failed``); TimeoutError after ``timeout``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        d = client.get(f"/datasets/{ident}").json()
        if d["state"] in ("ready", "failed"):
            return d
        time.sleep(0.1)
    raise TimeoutError(f"dataset {ident} still building after {timeout:.0f} s")

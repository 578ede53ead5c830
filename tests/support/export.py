"""An archive export whose renderer gives up part way: what the CLI and engine tests of a failed export share."""

from __future__ import annotations

from typing import Any

import pytest

import engine.serve.export as export_mod


def fail_render_batch_after(monkeypatch: pytest.MonkeyPatch, batches: int, error: Exception) -> list[int]:
    """Let the export draw ``batches`` batches of tiles, then raise ``error`` on the next.

    Returns the list that gets one entry per call of the renderer, so a test can tell how far the export went.
    """
    real = export_mod.render_batch
    calls: list[int] = []

    def failing(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        if len(calls) > batches:
            raise error
        return real(*args, **kwargs)

    monkeypatch.setattr(export_mod, "render_batch", failing)
    return calls

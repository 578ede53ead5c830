"""A request cancelled while its job is in a render worker (its client hung up, app/http/disconnect.py): a job that
ends within the grace gives its worker back, so a client that asks and hangs up cannot make the pool kill and
respawn workers (docs/service.md, "Under load"). The pool is real: worker processes drawing from a real store.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

from app.render.jobs import TileJob
from app.render.pool import RenderPool, render_config_for
from app.settings import Settings
from tests.app.conftest import LAT0, LON0
from tests.app.helpers import tile_for


async def cancel_inside_the_worker(pool: RenderPool, job: TileJob) -> bool:
    """Run ``job`` and cancel it as soon as a worker has it; whether the cancel landed while it was there."""
    task = asyncio.ensure_future(pool.run(job))
    while not any(w.busy_since is not None for w in pool._workers):
        assert not task.done(), "the job ended before a worker took it"
        await asyncio.sleep(0)
    task.cancel()
    await asyncio.wait({task})
    return task.cancelled()


def test_a_tile_whose_client_hangs_up_keeps_its_worker(built_store: Path, tmp_path: Path) -> None:
    settings = Settings(store_path=built_store, serve_sample=False, sources=[])
    job = TileJob("hills", *tile_for(LON0, LAT0, 12), 12.0, "ccsm", None, store=built_store, gzip=False)

    async def scenario() -> tuple[int, list[int], list[int], bytes | None]:
        pool = RenderPool(render_config_for(settings), size=1, queue=0, timeout_s=60)
        await pool.start()
        try:
            before = pool.pids()
            cancelled = [await cancel_inside_the_worker(pool, job) for _ in range(5)]
            assert all(cancelled), cancelled
            answer = await pool.run(job)  # waits for the worker to come back, then draws with it
            return pool.replaced, before, pool.pids(), answer.body
        finally:
            await pool.close()

    replaced, before, after, body = asyncio.run(scenario())
    assert replaced == 0 and after == before, (replaced, before, after)
    assert body  # the kept worker still draws the tile

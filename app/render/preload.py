"""Imported once by the render workers' fork server (``set_forkserver_preload``), for its side effect.

It compiles the engine's numba kernels in the fork server, so every render worker forked from it starts
with them compiled: neither the first tile after a restart nor a worker that replaces a killed one pays
the compile (about 20 s on 2 cores without numba's disk cache, about 1 s with it).
"""

from __future__ import annotations

import logging

from engine.warmup import warm_up

try:
    warm_up()
except Exception:  # workers still work, compiling on first use; the fork server must not die
    logging.getLogger("ccsm.render").warning("compiling the kernels ahead of the workers failed", exc_info=True)

"""The test helpers that find a live server's processes hold up while the server's children come and go."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import time

import psutil
from support.processes import fork_server


def test_fork_server_passes_over_a_child_that_has_ended() -> None:
    # A build process that has just ended is a zombie until its parent reaps it; asking for its command line
    # raises, and a helper that did so failed a server test on a loaded machine now and then.
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while psutil.Process(ended.pid).status() != psutil.STATUS_ZOMBIE:
        assert time.monotonic() < deadline, "the child never ended"
        time.sleep(0.01)
    try:
        with multiprocessing.get_context("forkserver").Pool(1) as pool:
            assert pool.apply(abs, (-3,)) == 3  # the fork server runs
            found = fork_server(os.getpid())
            assert found is not None and "forkserver" in " ".join(found.cmdline())
    finally:
        ended.wait()

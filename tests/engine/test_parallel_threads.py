"""A task a build sends to a worker runs with one BLAS thread (``parallel.run_single_threaded``): every BLAS pool
the worker has loaded, including one loaded after its first task, is limited while the task runs and given back
after it; the libraries are looked for again only when a module has been imported since, not on every task."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from threadpoolctl import ThreadpoolController, threadpool_info, threadpool_limits

import engine.parallel as parallel
from engine.parallel import run_single_threaded

REPO = Path(__file__).resolve().parents[2]


def pools() -> list[tuple[str, int]]:
    return sorted((i["filepath"], i["num_threads"]) for i in threadpool_info())


def test_a_task_runs_with_one_thread_in_every_pool_and_the_pools_are_given_back() -> None:
    with threadpool_limits(2):  # a known state to come back to, whatever the environment set
        before = pools()
        assert before and {n for _, n in before} == {2}
        inside = run_single_threaded(pools)
        assert [path for path, _ in inside] == [path for path, _ in before]
        assert {n for _, n in inside} == {1}
        assert pools() == before


def test_the_libraries_are_found_once_until_a_module_is_imported(monkeypatch: pytest.MonkeyPatch) -> None:
    found: list[int] = []

    class Counting(ThreadpoolController):
        def __init__(self) -> None:
            found.append(1)
            super().__init__()

    monkeypatch.setattr(parallel, "ThreadpoolController", Counting)
    monkeypatch.setattr(parallel, "_pools", None)
    for k in range(50):
        assert run_single_threaded(lambda k=k: k * 2) == k * 2
    assert len(found) == 1
    monkeypatch.setitem(sys.modules, "ccsm_test_new_module", object())  # as an import inside a task would
    run_single_threaded(int)
    run_single_threaded(int)
    assert len(found) == 2


def test_a_pool_loaded_after_the_first_task_is_limited_too(tmp_path: Path) -> None:
    # In a fresh process: a first task, then a module whose import loads a thread pool the process did not have
    # (GNU OpenMP: libgomp1, which R's r-base-core needs, so the suite's real-DEM tests bring it).
    (tmp_path / "brings_openmp.py").write_text("import ctypes\nctypes.CDLL('libgomp.so.1')\n")
    script = textwrap.dedent(
        """
        import json
        from threadpoolctl import threadpool_info, threadpool_limits
        from engine.parallel import run_single_threaded

        def threads():
            return sorted((i["internal_api"], i["num_threads"]) for i in threadpool_info())

        first = run_single_threaded(threads)
        import brings_openmp  # noqa: F401

        threadpool_limits(2)  # every pool at 2 outside a task, whatever the environment set
        print(json.dumps({"first": first, "outside": threads(), "inside": run_single_threaded(threads)}))
        """
    )
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{tmp_path}"}
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True, text=True, check=True, timeout=120
    )
    seen = json.loads(done.stdout)
    assert "openmp" not in [api for api, _ in seen["first"]], "OpenMP was loaded already: the test shows nothing"
    assert "openmp" in [api for api, _ in seen["outside"]]
    assert {n for _, n in seen["outside"]} == {2}
    assert [api for api, _ in seen["inside"]] == [api for api, _ in seen["outside"]]
    assert {n for _, n in seen["inside"]} == {1}, seen["inside"]


def test_a_local_pools_workers_inherit_a_started_numba() -> None:
    # In a fresh interpreter (this one has long started numba): a worker forked by local_pool finds numba's
    # implementations loaded before it calls any kernel, as its parent loaded them before forking it.
    code = textwrap.dedent(
        """
        import sys
        from engine.parallel import local_pool

        def numba_started():
            return "numba.np.arraymath" in sys.modules

        assert not numba_started()
        with local_pool(2) as pool:
            print(pool.submit(numba_started).result())
        """
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"

"""The build's spool on disk (``scratch.DiskSpool``): surfaces kept by number as the pickles workers send, appended
to a scratch file and read back one ``pread`` each. Whatever the order of puts, replacements and batch sizes, a
number gives the last bytes put under it; a number never put is refused by name; a failed write is a clear store
error; the file goes with the spool, and a dead build's spool file is swept like its other scratch files."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import engine.scratch as scratch
from engine.errors import StoreError
from engine.payloads import FileUnreachable, fetched
from engine.scratch import SCRATCH_PREFIX, DiskSpool, host_name, remove_stale_scratch

# Batches of (number, bytes) as a build puts them: chunks in order, then the repair's rebuilds out of order.
batches = st.lists(
    st.lists(st.tuples(st.integers(0, 60), st.binary(min_size=0, max_size=300)), min_size=0, max_size=12),
    min_size=1,
    max_size=12,
)


@settings(deadline=None, max_examples=60)
@given(puts=batches, per_write=st.integers(1, 5))
def test_each_number_gives_the_last_bytes_put_under_it(
    puts: list[list[tuple[int, bytes]]], per_write: int, tmp_path_factory: pytest.TempPathFactory
) -> None:
    expected: dict[int, bytes] = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(scratch, "WRITE_BUFFERS", per_write)  # several writes a batch
        spool = DiskSpool(tmp_path_factory.mktemp("spool"))
        try:
            for batch in puts:
                spool.put_payloads(batch)
                expected.update(batch)
                wanted = sorted(expected)[::-1] + sorted(expected)  # any order, numbers asked twice
                assert spool.get_payloads(wanted) == [expected[i] for i in wanted]
            never = [i for i in range(-1, 62) if i not in expected]
            for i in never[:3]:
                with pytest.raises(KeyError, match=rf"not in the spool: \[{i}\]"):
                    spool.get_payloads([*expected, i])
        finally:
            spool.close()
    assert not spool.path.exists()


@settings(deadline=None, max_examples=60)
@given(puts=batches)
def test_a_worker_reads_from_a_slice_the_bytes_put_when_it_was_given(
    puts: list[list[tuple[int, bytes]]], tmp_path_factory: pytest.TempPathFactory
) -> None:
    # What a block's or a shard's task is sent instead of the bytes: where they lie. A number put again later
    # lies elsewhere; the slice given before still reads the bytes it was given for.
    spool = DiskSpool(tmp_path_factory.mktemp("slices"))
    given_then: list[tuple[object, bytes]] = []
    try:
        for batch in puts:
            spool.put_payloads(batch)
            kept = sorted({i for i, _ in batch})
            if kept:
                slices = spool.get_slices(kept)
                assert slices is not None
                given_then.extend(zip(slices, spool.get_payloads(kept), strict=True))
        assert fetched([slice_ for slice_, _ in given_then]) == [blob for _, blob in given_then]
        assert fetched([b"as it is", *[slice_ for slice_, _ in given_then[:1]]])[0] == b"as it is"
        spool.stop_slices()
        assert spool.get_slices(sorted({i for batch in puts for i, _ in batch})) is None
    finally:
        spool.close()


def test_a_worker_that_cannot_read_the_spool_says_so(tmp_path: Path) -> None:
    spool = DiskSpool(tmp_path)
    spool.put_payloads([(0, b"x" * 100)])
    (where,) = spool.get_slices([0]) or []
    with pytest.raises(KeyError, match=r"not in the spool: \[1\]"):
        spool.get_slices([0, 1])
    short = tmp_path / "short.spool"
    short.write_bytes(b"x" * 50)  # another machine's file of that name: shorter than the slice
    with pytest.raises(FileUnreachable, match="50 of 100 bytes"):
        fetched([where._replace(path=str(short))])
    spool.close()  # the build process's file is gone (or on another machine)
    with pytest.raises(FileUnreachable, match="No such file"):
        fetched([where])


def test_surfaces_put_as_objects_come_back_equal(tmp_path: Path) -> None:
    spool = DiskSpool(tmp_path)
    try:
        spool.put_many([(2, {"rows": [1.5, 2.5]}), (0, "first")])
        spool.put(2, ("rebuilt", 3))
        assert spool.get([0, 2]) == ["first", ("rebuilt", 3)]
        assert spool.path.parent == tmp_path and spool.path.suffix == ".spool"
    finally:
        spool.close()


def test_a_write_that_fails_is_a_store_error_naming_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spool = DiskSpool(tmp_path)
    try:
        spool.put_payloads([(0, b"kept")])

        def full(fd: int, buffers: list[bytes], offset: int) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        monkeypatch.setattr(os, "pwritev", full)
        with pytest.raises(StoreError, match=rf"{spool.path.name}: No space left on device"):
            spool.put_payloads([(1, b"lost")])
        monkeypatch.setattr(os, "pwritev", lambda fd, buffers, offset: 1)  # a short write
        with pytest.raises(StoreError, match=rf"{spool.path.name}: 1 of 4 bytes written"):
            spool.put_payloads([(1, b"lost")])
        monkeypatch.undo()
        assert spool.get_payloads([0]) == [b"kept"]  # what was kept before stays readable
        with pytest.raises(KeyError):
            spool.get_payloads([1])
    finally:
        spool.close()


def test_a_dead_builds_spool_file_is_swept_and_a_live_ones_kept(tmp_path: Path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{int(dead.stdout)}-abcd.spool"
    unrelated = tmp_path / f"{SCRATCH_PREFIX}{host_name()}-{int(dead.stdout)}-abcd.txt"
    for path in (stale, unrelated):
        path.write_bytes(b"x")
    spool = DiskSpool(tmp_path)  # a new build sweeps first
    try:
        assert not stale.exists() and unrelated.exists()
        assert remove_stale_scratch(tmp_path) == []  # its own file belongs to a live build
        assert spool.path.exists()
    finally:
        spool.close()

import dataclasses
import math
import re
import sqlite3

import numpy as np
import pytest

from engine.build.datasets import SourceSpec, build_dataset, source_hash
from engine.errors import StoreError, UnknownLayer
from engine.io.source import read_source
from engine.store.schema import PIECE_KINDS
from engine.store.staging import leftover_ids, purge_some, row_ids
from engine.store.store import CCSStore
from tests.app.conftest import synthetic_features, write_geojson


@pytest.fixture(scope="module")
def src(tmp_path_factory):
    return write_geojson(tmp_path_factory.mktemp("s") / "h.geojson", synthetic_features()[:8])


@pytest.fixture()
def store(tmp_path, src):
    s = CCSStore(tmp_path / "x.sqlite")
    build_dataset(s, SourceSpec(src, "h", "h"), workers=1)
    return s


def test_wal_and_format(store):
    assert store._con().execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert store.integrity_ok()


def test_round_trip(store, src):
    info = store.dataset("h")
    assert info.n_contours == 8 and info.data_version == 1
    recs = store.load(store.all_fids("h"))
    assert len(recs) == 8
    r = recs[0]
    assert r.base.shape == r.top.shape and r.base.shape[1] == 2
    assert r.t_at_scale.shape == info.ladder.shape
    assert r.sig.shape == (len(r.base),) and np.isinf(r.sig[0])
    cs = read_source(src)
    assert np.allclose(r.original_w, cs.contours[0].coords)


def test_rtree_query(store):
    info = store.dataset("h")
    assert len(store.query("h", info.bounds_3857)) == 8
    assert store.query("h", (0, 0, 1, 1)) == []
    assert store.query("other", info.bounds_3857) == []


def test_unchanged_source_is_not_rebuilt_changed_one_is(store, src, tmp_path):
    spec = SourceSpec(src, "h", "h")
    _, rebuilt = build_dataset(store, spec, workers=1)
    assert not rebuilt
    changed = write_geojson(tmp_path / "h.geojson", synthetic_features()[:9])
    info, rebuilt = build_dataset(store, SourceSpec(changed, "h", "h"), workers=1)
    assert rebuilt and info.data_version == 2 and info.n_contours == 9
    assert info.source_hash == source_hash(changed, spec.params())


def _unchanged(store, before, fids, recs):
    """The dataset 'h' as it was before a failed build, for this process's reader and a new one."""
    assert leftover_ids(store._con()) == []
    for reader in (store, CCSStore(store.path)):
        info = reader.dataset("h")
        assert (info.data_version, info.source_hash) == (before.data_version, before.source_hash)
        assert reader.all_fids("h") == fids
        assert len(reader.query("h", info.bounds_3857)) == len(fids)
        for old, new in zip(recs, reader.load(fids), strict=True):
            assert np.array_equal(old.base, new.base) and np.array_equal(old.original, new.original)
        assert reader.integrity_ok()


def test_failed_merge_rolls_back(store, src):
    before, fids = store.dataset("h"), store.all_fids("h")
    recs = store.load(fids)
    # The store refuses the sixth contour a build stages: the merge's transaction fails part way.
    store._con().execute(
        "CREATE TEMP TRIGGER refuse_sixth BEFORE INSERT ON main.contours "
        "WHEN (SELECT count(*) FROM main.contours WHERE dataset <> 'h') >= 5 "
        "BEGIN SELECT RAISE(ABORT, 'refused'); END"
    )
    statements: list[str] = []
    store._con().set_trace_callback(statements.append)
    with pytest.raises(sqlite3.IntegrityError, match="refused"):
        build_dataset(store, SourceSpec(src, "h", "h", source_scale=40_000), workers=1)
    store._con().set_trace_callback(None)
    store._con().execute("DROP TRIGGER refuse_sixth")
    # The failure came while the rows were staged: the merge's transaction rolled back, no switch, the staged
    # rows removed, the dataset's rows never touched.
    rollback = statements.index("ROLLBACK")
    batch = statements[: rollback + 1][::-1]
    batch = batch[: batch.index("BEGIN IMMEDIATE")]
    assert any(q.startswith("INSERT INTO contours(fid") for q in batch), batch
    assert not any(q.startswith("UPDATE datasets SET id") for q in statements)
    live = store._stored_rows_id("h")
    assert not any(q.startswith(f"SELECT fid FROM contours WHERE dataset='{live}' LIMIT") for q in statements)
    _unchanged(store, before, fids, recs)


def test_a_row_its_shard_refuses_fails_the_build_and_leaves_the_store(store, src, monkeypatch):
    before, fids = store.dataset("h"), store.all_fids("h")
    recs = store.load(fids)
    import engine.build.datasets as datasets

    real_rows = datasets.contour_rows

    def rows_with_a_bad_sixth(*a):
        rows = real_rows(*a)
        # SQLite stores a NaN as NULL: the NOT NULL elevation makes the sixth contour's INSERT fail.
        rows[5] = dataclasses.replace(rows[5], elevation=math.nan)
        return rows

    monkeypatch.setattr(datasets, "contour_rows", rows_with_a_bad_sixth)
    statements: list[str] = []
    store._con().set_trace_callback(statements.append)
    with pytest.raises(sqlite3.IntegrityError, match="NOT NULL"):
        build_dataset(store, SourceSpec(src, "h", "h", source_scale=40_000), workers=1)
    store._con().set_trace_callback(None)
    # The shard (written apart from the store) failed: nothing was merged, nothing switched.
    assert not any(q.startswith("INSERT INTO contours") for q in statements)
    assert not any(q.startswith("UPDATE datasets SET id") for q in statements)
    _unchanged(store, before, fids, recs)


def test_rollback_inside_the_transaction(store):
    fids = store.all_fids("h")
    with pytest.raises(RuntimeError), store._write() as cur:
        cur.execute("DELETE FROM contours")
        raise RuntimeError("killed")
    assert store.all_fids("h") == fids


def test_delete_and_unknown(store):
    assert store.delete("h")
    with pytest.raises(UnknownLayer):
        store.dataset("h")
    assert not store.delete("h")


def test_not_a_store(tmp_path):
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(StoreError):
        CCSStore(bad)


def test_packed_tiles_equal_contour_by_contour(store):
    from engine.serve.renderer import Renderer
    from engine.tiles.grid import tiles_covering
    from engine.types import Bounds

    packed = Renderer(store)
    by_contour = Renderer(store, contour_cache_bytes=1)  # too small for a pack: packed per tile from pieces
    assert by_contour.pack("h") is None and packed.pack("h") is not None
    info = store.dataset("h")
    n = 0
    for z in range(8, 15):
        for tile in tiles_covering(Bounds(*info.bounds_3857), z)[:6]:
            for kw in ({}, {"t": 0.5}, {"method": "original"}):
                a = packed.tile("h", *tile, **kw)
                b = by_contour.tile("h", *tile, **kw)
                assert a.data == b.data and a.features == b.features
                n += a.features
    assert n > 0


# -- issue 10: ids reserved atomically, builds that cannot resurrect a deleted dataset, damage detected -------


def _reserve_in_processes(path, ident, n, free):
    """n processes (fresh connections each) claim one id at once; their answers."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(n) as pool:
        return pool.starmap(_claim, [(str(path), ident, free)] * n)


def _claim(path, ident, free):
    s = CCSStore(path)
    return s.reserve_free(ident) if free else s.reserve(ident)


def test_issue_10_reserve_is_atomic_across_processes(store, tmp_path):
    answers = _reserve_in_processes(store.path, "race", 6, free=False)
    assert sorted(answers) == [False] * 5 + [True]
    assert "race" in store.build_statuses()  # (reported failed: the claiming process is gone)
    assert not store.reserve("h")  # a stored dataset is taken too
    names = _reserve_in_processes(store.path, "twin", 6, free=True)
    assert sorted(names) == sorted(["twin"] + [f"twin-{k}" for k in range(2, 7)])


def test_issue_10_failed_id_is_taken_until_deleted(store):
    assert store.reserve("x")
    assert store.fail_build("x", "broken")
    assert not store.reserve("x")
    assert store.delete_any("x") and not store.delete_any("x")
    assert store.reserve("x")


def test_issue_10_a_build_deleted_meanwhile_writes_nothing(store, src):
    from engine.errors import BuildCancelled

    assert store.reserve("late")
    assert store.update_build_progress("late", 1, 8)
    assert store.delete_any("late")
    assert not store.update_build_progress("late", 2, 8)  # the build learns it was deleted
    assert not store.fail_build("late", "x")  # and cannot bring it back as failed
    with pytest.raises(BuildCancelled):
        build_dataset(store, SourceSpec(src, "late", "late"), workers=1, only_if_building=True)
    assert store.data_version("late") is None and "late" not in store.build_statuses()


def test_issue_10_quick_check_finds_flipped_bytes(store, tmp_path):
    assert store.quick_check() == "ok"
    store.checkpoint()
    data = bytearray(store.path.read_bytes())
    for i in range(4096, len(data), 991):
        data[i] ^= 0xFF
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(bytes(data))
    try:
        problem = CCSStore(bad).quick_check()
    except StoreError as exc:
        problem = str(exc)
    assert problem != "ok" and problem


def test_issue_12_rows_written_batch_by_batch_make_the_same_dataset(store, src, monkeypatch):
    import engine.build.datasets as datasets

    whole = store.dataset("h")
    rows = store.load(store.all_fids("h"))
    monkeypatch.setattr(datasets, "SAVE_BATCH", 3)  # 8 contours: batches of 3, 3 and 2
    info, rebuilt = build_dataset(store, SourceSpec(src, "h", "h"), workers=1, force=True)
    assert rebuilt and info.data_version == whole.data_version + 1
    written = store.load(store.all_fids("h"))
    assert [r.contour_id for r in written] == [str(c.id) for c in read_source(src).contours]
    for old, new in zip(rows, written, strict=True):
        assert old.contour_id == new.contour_id and np.array_equal(old.base, new.base)
    # The dataset's row, tallied as the rows went by, agrees with the rows themselves.
    assert info.n_contours == len(written)
    assert info.n_closed == sum(r.closed for r in written)
    assert info.n_vertices == sum(len(r.original_w) for r in written)
    xy = np.concatenate([np.concatenate([r.base, r.top, r.original]) for r in written])
    assert info.bounds_3857 == (*xy.min(axis=0), *xy.max(axis=0))


def test_issue_12_a_build_failing_in_its_second_batch_leaves_the_stored_version(store, src, monkeypatch):
    import engine.build.datasets as datasets

    before = store.dataset("h")
    fids = store.all_fids("h")
    real_rows = datasets.contour_rows
    calls = []

    def fail_on_second_batch(*a):
        calls.append(1)
        if len(calls) == 2:
            raise MemoryError("killed in the second batch")
        return real_rows(*a)

    monkeypatch.setattr(datasets, "SAVE_BATCH", 3)
    monkeypatch.setattr(datasets, "contour_rows", fail_on_second_batch)
    with pytest.raises(MemoryError):
        build_dataset(store, SourceSpec(src, "h", "h", source_scale=40_000), workers=1)
    for reader in (store, CCSStore(store.path)):
        info = reader.dataset("h")
        assert (info.data_version, info.source_hash, info.n_contours) == (
            before.data_version,
            before.source_hash,
            before.n_contours,
        )
        assert reader.all_fids("h") == fids


#: A statement that writes contour rows, their R*Tree entries, pieces or issues.
ROW_WRITE = re.compile(
    r"^(UPDATE|INSERT|DELETE|REPLACE)\b.*(\bcontours|contour_rtree|_pieces|_piece_rtree|contour_issues)\b"
)


def _rows_under(store: CCSStore, ident: str) -> int:
    return store._con().execute("SELECT count(*) FROM contours WHERE dataset=?", (ident,)).fetchone()[0]


def test_a_rebuild_switches_without_rewriting_a_row_and_alternates_its_row_ids(store, src):
    first = store._stored_rows_id("h")
    n_first = _rows_under(store, first)
    statements: list[str] = []
    store._con().set_trace_callback(statements.append)
    info, rebuilt = build_dataset(store, SourceSpec(src, "h", "h", source_scale=40_000), workers=1)
    store._con().set_trace_callback(None)
    assert rebuilt
    at = next(k for k, q in enumerate(statements) if q.startswith("UPDATE datasets SET id"))
    begin = max(k for k in range(at) if statements[k] == "BEGIN IMMEDIATE")
    switch = statements[begin : statements.index("COMMIT", at) + 1]
    assert not [q for q in switch if ROW_WRITE.match(q)], switch  # the switch points at the rows, no more
    second = store._stored_rows_id("h")
    assert {first, second} == set(row_ids("h"))
    assert _rows_under(store, first) == 0 and _rows_under(store, second) == info.n_contours == n_first
    assert leftover_ids(store._con()) == []
    assert len(store.query("h", info.bounds_3857)) == info.n_contours == len(store.all_fids("h"))
    assert len(store.dataset_heads("h")[0]) == info.n_contours
    third, _ = build_dataset(store, SourceSpec(src, "h", "h", source_scale=45_000), workers=1)
    assert store._stored_rows_id("h") == first and _rows_under(store, second) == 0
    assert third.data_version > info.data_version and store.integrity_ok()


def test_the_rows_a_stored_dataset_reads_are_never_purged(store):
    live = store._stored_rows_id("h")
    with pytest.raises(StoreError, match="a stored dataset's"), store._write() as cur:
        purge_some(cur, live)
    assert _rows_under(store, live) == store.dataset("h").n_contours


def test_a_format_3_store_is_migrated_and_its_first_rebuild_moves_its_rows(tmp_path, src):
    path = tmp_path / "old.sqlite"
    store = CCSStore(path)
    build_dataset(store, SourceSpec(src, "h", "h"), workers=1)
    before, fids = store.dataset("h"), store.all_fids("h")
    recs, labels, issues = store.load(fids), store.labels("h"), store.contour_issues("h")
    live = store._stored_rows_id("h")
    store.close()
    # Format 3's layout: a dataset's rows under its own id, no rows_id column.
    con = sqlite3.connect(path)
    tables = ["contours", "contour_rtree", "contour_issues", *(f"{kind}_piece_rtree" for kind in PIECE_KINDS)]
    for table in tables:
        con.execute(f"UPDATE {table} SET dataset='h' WHERE dataset=?", (live,))
    con.execute("ALTER TABLE datasets DROP COLUMN rows_id")
    con.execute("UPDATE store_meta SET value='3' WHERE key='format'")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="has format 3, expected 4"):
        CCSStore(path, readonly=True)  # a reader cannot migrate it

    migrated = CCSStore(path)
    assert migrated._stored_rows_id("h") == "h" and CCSStore(path, readonly=True).all_fids("h") == fids
    for old, new in zip(recs, migrated.load(migrated.all_fids("h")), strict=True):
        assert np.array_equal(old.base, new.base) and old.contour_id == new.contour_id
    assert len(migrated.query("h", before.bounds_3857)) == len(fids)
    assert migrated.contour_issues("h") == issues
    assert np.array_equal(migrated.labels("h").anchors.fid, labels.anchors.fid)
    assert leftover_ids(migrated._con()) == []

    info, rebuilt = build_dataset(migrated, SourceSpec(src, "h", "h", source_scale=40_000), workers=1)
    assert rebuilt and migrated._stored_rows_id("h") in row_ids("h")
    assert _rows_under(migrated, "h") == 0 and leftover_ids(migrated._con()) == []
    assert len(migrated.all_fids("h")) == info.n_contours and migrated.integrity_ok()

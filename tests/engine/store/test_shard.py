"""Shards: rows written apart from the store (by the worker that made them) and merged into it by SQLite.

The merge must give what a row-by-row write gives: the next free fids (past every fid the store ever used), each
contour's pieces, R*Tree entries and issues under its own new fid, and the rows unchanged; and the same whether
the build process merges the shards in order or the workers merge them themselves, in any order, some twice.
Checked on contours generated here, merged into a store that already holds, and has deleted, other datasets.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import engine.store.shard as shard_module
from engine.errors import StoreError
from engine.store.codec import piece_count, piece_rows
from engine.store.records import NewContour, NewDataset
from engine.store.shard import MergedShard, Shard, StageTarget, attached, fid_runs, merge_on_worker, write_shard
from engine.store.staging import leftover_ids
from engine.store.store import CCSStore

#: Rows per contour drawn here: past PIECE_ROWS, so that contours of one, two and three pieces occur.
MOST_ROWS = 700


@st.composite
def new_contours(draw: st.DrawFn) -> NewContour:
    n_rows = draw(st.integers(2, MOST_ROWS))
    n_input = draw(st.integers(2, MOST_ROWS))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-1e6, 1e6, 2)
    base = centre + rng.normal(0, 5e3, (n_rows, 2))
    top = base + rng.normal(0, 50, (n_rows, 2))
    original = centre + rng.normal(0, 5e3, (n_input, 2))
    everything = np.vstack([base, top, original])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    issues = draw(
        st.lists(st.tuples(st.sampled_from(["repair", "labels", "surface"]), st.text(max_size=12)), max_size=2)
    )
    return NewContour(
        contour_id=f"c{seed}",
        elevation=float(rng.integers(-400, 4000)),
        closed=draw(st.booleans()),
        group=draw(st.integers(0, 4)),
        vanish_scale=draw(st.sampled_from([np.inf, 2.5e5, 1e6])),
        length_m=float(rng.uniform(1, 1e5)),
        base=base,
        top=top,
        original=original,
        original_w=original - centre,
        t_at_scale=rng.uniform(0, 1, 33),
        sim_t=np.linspace(0, 1, 11),
        sim=rng.uniform(0, 1, 11),
        sig=rng.uniform(0, 100, n_rows).astype(np.float32),
        sig_top=rng.uniform(0, 100, n_rows).astype(np.float32),
        sig_original=rng.uniform(0, 100, n_input).astype(np.float32),
        n_input=n_input,
        box=(float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])),
        issues=tuple(issues),
    )


def _meta(name: str) -> NewDataset:
    return NewDataset(
        name=name,
        source=f"{name}.geojson",
        source_hash=name,
        params={},
        build_seconds=0.0,
        working_crs="EPSG:3857",
        source_crs="EPSG:3857",
        interval=10.0,
        source_scale=50_000.0,
        target_scale=500_000.0,
        ladder=np.geomspace(50_000.0, 500_000.0, 33),
        bad_features=[],
    )


def _save(store: CCSStore, name: str, shards: list[Shard]) -> None:
    """Store ``shards`` as dataset ``name``, merged by the store in order (as a build without workers does)."""
    store.save(name, _meta(name), lambda _target: shards, sum(shard.tally.n for shard in shards))


def _assert_stored(store: CCSStore, dataset: str, fid: int, c: NewContour) -> None:
    """Contour ``fid`` of ``dataset`` is ``c``: its row, pieces, R*Tree entry and issues."""
    (record,) = store.load([fid])
    assert (record.contour_id, record.elevation, record.closed) == (
        c.contour_id,
        c.elevation,
        c.closed,
    )
    for name in ("base", "top", "original", "original_w", "t_at_scale", "sim", "sig", "sig_top", "sig_original"):
        assert np.array_equal(getattr(record, name), getattr(c, name)), (fid, name)
    minx, maxx, miny, maxy = c.box
    assert fid in store.query(dataset, (minx, miny, maxx, maxy))
    for kind, rows in (("ccs", c.base), ("original", c.original)):
        pieces = store.pieces_meeting(dataset, (minx, miny, maxx, maxy), kind, fid_range=(fid, fid))
        assert pieces.k.tolist() == list(range(piece_count(len(rows)))), (fid, kind)
        starts = np.concatenate([[0], np.cumsum(pieces.n)])
        for k in range(len(pieces.k)):
            assert np.array_equal(pieces.columns[0][starts[k] : starts[k + 1]], rows[piece_rows(len(rows), k)])


def _store_with_history(path, earlier: list[NewContour]) -> CCSStore:  # noqa: ANN001 - a path
    """A store holding dataset "kept" (the first of ``earlier``) and having held "gone" (all of them)."""
    store = CCSStore(path)
    _save(store, "kept", [write_shard(earlier[:1])])
    _save(store, "gone", [write_shard(earlier)])
    store.delete("gone")  # its fids are never given again
    return store


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    earlier=st.lists(new_contours(), min_size=1, max_size=4),
    batches=st.lists(st.lists(new_contours(), min_size=1, max_size=6), min_size=1, max_size=3),
    stage_contours=st.integers(1, 5),
)
def test_merged_shards_hold_every_row_under_the_next_free_fids(
    tmp_path_factory: pytest.TempPathFactory,
    monkeypatch: pytest.MonkeyPatch,
    earlier: list[NewContour],
    batches: list[list[NewContour]],
    stage_contours: int,
) -> None:
    monkeypatch.setattr(shard_module, "STAGE_CONTOURS", stage_contours)  # several merge steps per shard
    store = _store_with_history(tmp_path_factory.mktemp("shards") / "store.sqlite", earlier)
    used = int(store._con().execute("SELECT seq FROM sqlite_sequence WHERE name='contours'").fetchone()[0])

    shards = [write_shard(batch) for batch in batches]
    info = store.save("b", _meta("b"), lambda _target: shards, sum(len(batch) for batch in batches))

    merged = [c for batch in batches for c in batch]
    fids = store.all_fids("b")
    assert fids == list(range(used + 1, used + 1 + len(merged)))
    for fid, c in zip(fids, merged, strict=True):
        _assert_stored(store, "b", fid, c)
    _assert_stored(store, "kept", store.all_fids("kept")[0], earlier[0])
    issues, total = store.contour_issues("b")
    expected = [
        (fid, c.contour_id, step, reason) for fid, c in zip(fids, merged, strict=True) for step, reason in c.issues
    ]
    assert [(i["fid"], i["id"], i["step"], i["reason"]) for i in issues] == expected and total == len(expected)
    assert (info.n_contours, info.n_closed) == (len(merged), sum(c.closed for c in merged))
    assert info.n_vertices == sum(c.n_input for c in merged)
    assert info.bounds_3857 == (
        min(c.box[0] for c in merged),
        min(c.box[2] for c in merged),
        max(c.box[1] for c in merged),
        max(c.box[3] for c in merged),
    )
    assert store.integrity_ok()


def _dump(store: CCSStore, dataset: str) -> dict[str, list[tuple]]:
    """Every row the store holds for ``dataset``, by table, in fid order (pieces by fid and k: their own ids
    are the store's business)."""
    con, rows = store._con(), store._rows_of(dataset)
    out = {
        "contours": con.execute("SELECT * FROM contours WHERE dataset=? ORDER BY fid", (rows,)).fetchall(),
        "rtree": con.execute("SELECT * FROM contour_rtree WHERE dataset=? ORDER BY fid", (rows,)).fetchall(),
        "issues": con.execute("SELECT * FROM contour_issues WHERE dataset=? ORDER BY fid, rowid", (rows,)).fetchall(),
    }
    for kind in ("ccs", "original"):
        out[kind] = con.execute(
            f"SELECT p.fid, p.k, r.minx, r.maxx, r.miny, r.maxy, p.* FROM {kind}_pieces p "
            f"JOIN {kind}_piece_rtree r ON r.piece = p.piece WHERE r.dataset=? ORDER BY p.fid, p.k",
            (rows,),
        ).fetchall()
        out[kind] = [row[:6] + row[9:] for row in out[kind]]  # without the piece id and the repeated fid, k
    return out


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    earlier=st.lists(new_contours(), min_size=1, max_size=3),
    batches=st.lists(st.lists(new_contours(), min_size=1, max_size=4), min_size=1, max_size=4),
    stage_contours=st.integers(1, 3),
    data=st.data(),
)
def test_shards_merged_by_their_workers_in_any_order_are_stored_as_merged_in_order(
    tmp_path_factory: pytest.TempPathFactory,
    monkeypatch: pytest.MonkeyPatch,
    earlier: list[NewContour],
    batches: list[list[NewContour]],
    stage_contours: int,
    data: st.DataObject,
) -> None:
    monkeypatch.setattr(shard_module, "STAGE_CONTOURS", stage_contours)
    root = tmp_path_factory.mktemp("workers")
    in_order = _store_with_history(root / "in_order.sqlite", earlier)
    by_workers = _store_with_history(root / "by_workers.sqlite", earlier)
    shards = [write_shard(batch) for batch in batches]
    offsets = np.concatenate([[0], np.cumsum([len(batch) for batch in batches])]).tolist()
    landed = data.draw(st.permutations(range(len(shards))), label="order the workers' merges land in")
    again = data.draw(st.sets(st.sampled_from(range(len(shards)))), label="tasks run twice (a worker lost)")

    def merged_by_workers(target: StageTarget) -> list[MergedShard | Shard]:
        came_back = {}
        for i in landed:
            came_back[i] = merge_on_worker(target, shards[i], offsets[i])
            if i in again:
                came_back[i] = merge_on_worker(target, shards[i], offsets[i])
        return [came_back[i] for i in range(len(shards))]

    _save(in_order, "b", shards)
    info = by_workers.save("b", _meta("b"), merged_by_workers, offsets[-1])
    assert _dump(by_workers, "b") == _dump(in_order, "b")
    assert len(_dump(by_workers, "b")["contours"]) == info.n_contours == offsets[-1]
    assert by_workers.integrity_ok()


@settings(max_examples=5, deadline=None)
@given(contour=new_contours())
def test_a_worker_that_cannot_open_the_builds_store_sends_its_shard_back(
    tmp_path_factory: pytest.TempPathFactory, contour: NewContour
) -> None:
    root = tmp_path_factory.mktemp("elsewhere")
    shard = write_shard([contour])
    # Another machine's store at the same path holds no reservation of this build (or another token).
    other = CCSStore(root / "store.sqlite")
    _save(other, "d", [write_shard([contour])])
    target = StageTarget(str(root / "store.sqlite"), "d", "\x01sd", 1, "not its token", False)
    before = _dump(other, "d")
    assert merge_on_worker(target, shard, 0) is shard
    assert _dump(other, "d") == before and leftover_ids(other._con()) == []
    # No file at that path at all: none is made there. Another kind of file: it is not touched.
    nowhere = StageTarget(str(root / "nowhere.sqlite"), "d", "\x01sd", 1, "token", False)
    assert merge_on_worker(nowhere, shard, 0) is shard
    assert not (root / "nowhere.sqlite").exists()
    for name, content in (("text.sqlite", b"not a database"), ("other.sqlite", None)):
        path = root / name
        if content is None:
            sqlite3.connect(path).execute("CREATE TABLE t(x)").connection.commit()
        else:
            path.write_bytes(content)
        before_bytes = path.read_bytes()
        assert merge_on_worker(StageTarget(str(path), "d", "\x01sd", 1, "token", False), shard, 0) is shard
        assert path.read_bytes() == before_bytes, name


@settings(max_examples=5, deadline=None)
@given(contours=st.lists(new_contours(), min_size=2, max_size=2))
def test_a_worker_still_merging_after_its_build_failed_leaves_nothing(
    tmp_path_factory: pytest.TempPathFactory, contours: list[NewContour]
) -> None:
    store = CCSStore(tmp_path_factory.mktemp("failed") / "store.sqlite")
    told: list[StageTarget] = []

    def fails_after_one(target: StageTarget) -> Iterator[MergedShard | Shard]:
        told.append(target)
        yield merge_on_worker(target, write_shard(contours[:1]), 0)
        raise RuntimeError("a task failed")

    with pytest.raises(RuntimeError, match="a task failed"):
        store.save("d", _meta("d"), fails_after_one, 2)
    # The other task lands after the build gave up: its reservation is gone, so it merges nothing.
    late = merge_on_worker(told[0], write_shard(contours[1:]), 1)
    assert isinstance(late, Shard)
    assert store._con().execute("SELECT count(*) FROM contours").fetchone()[0] == 0
    assert leftover_ids(store._con()) == [] and store.dataset_ids() == []


@settings(max_examples=5, deadline=None)
@given(contours=st.lists(new_contours(), min_size=1, max_size=3))
def test_a_save_whose_shards_miss_contours_stores_nothing(
    tmp_path_factory: pytest.TempPathFactory, contours: list[NewContour]
) -> None:
    store = CCSStore(tmp_path_factory.mktemp("short") / "store.sqlite")
    n = len(contours)
    with pytest.raises(StoreError, match=f"{n} contours written, {n + 1} expected"):
        store.save("d", _meta("d"), lambda _target: [write_shard(contours)], n + 1)
    assert store.dataset_ids() == [] and leftover_ids(store._con()) == []
    assert store._con().execute("SELECT count(*) FROM contours").fetchone()[0] == 0


@given(
    rows=st.lists(st.integers(1, 300_000), min_size=1, max_size=60),
    most_contours=st.integers(1, 70),
    most_rows=st.integers(1, 400_000),
)
def test_merge_runs_cover_a_shard_in_order_each_bounded(rows: list[int], most_contours: int, most_rows: int) -> None:
    contours = [(fid, n) for fid, n in enumerate(rows, start=1)]
    runs = list(fid_runs(contours, most_contours, most_rows))
    covered = [fid for first, last in runs for fid in range(first, last + 1)]
    assert covered == [fid for fid, _ in contours]
    for first, last in runs:
        assert last - first + 1 <= most_contours
        # A run stops at the contour that reaches the bound: without its last contour it is under the bound.
        assert sum(rows[first - 1 : last - 1]) < most_rows


def test_a_shard_is_detached_after_a_failed_merge(tmp_path) -> None:
    store = CCSStore(tmp_path / "store.sqlite")
    con = store._con()
    with pytest.raises(RuntimeError), attached(con, write_shard([])):
        raise RuntimeError("merge failed")
    assert [row[1] for row in con.execute("PRAGMA database_list")] == ["main"]
    with pytest.raises(sqlite3.OperationalError):
        con.execute("SELECT count(*) FROM shard.contours")


@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(contour=new_contours())
def test_a_workers_merge_waits_for_the_write_lock_as_long_as_other_merges_hold_it(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch, contour: NewContour
) -> None:
    # Every worker of a build merges under the store's one write lock, in turn: with many workers a merge waits
    # many merges long, far past the few seconds a request may wait before it is told the store is busy.
    import threading

    import engine.store.connection as connection

    monkeypatch.setattr(connection, "BUSY_TIMEOUT_S", 0.2)  # a request's wait, made short
    monkeypatch.setattr(shard_module, "MERGE_BUSY_TIMEOUT_S", 10.0)
    path = tmp_path_factory.mktemp("busy") / "store.sqlite"
    store = CCSStore(path)

    def merged_while_another_holds_the_lock(target: StageTarget) -> list[MergedShard | Shard]:
        holder = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        holder.execute("BEGIN IMMEDIATE")  # another worker's merge
        threading.Timer(1.0, lambda: holder.execute("ROLLBACK")).start()
        return [merge_on_worker(target, write_shard([contour]), 0)]

    info = store.save("d", _meta("d"), merged_while_another_holds_the_lock, 1)
    assert info.n_contours == 1
    _assert_stored(store, "d", store.all_fids("d")[0], contour)

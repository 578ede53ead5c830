"""Shards: rows written apart from the store (by the worker that made them) and merged into it by SQLite.

The merge must give what a row-by-row write gives: the next free fids (past every fid the store ever used), each
contour's pieces, R*Tree entries and issues under its own new fid, and the rows unchanged. Checked on contours
generated here, merged into a store that already holds, and has deleted, other datasets.
"""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import engine.store.store as store_module
from engine.store.codec import piece_count, piece_rows
from engine.store.records import NewContour, NewDataset
from engine.store.shard import attached, fid_runs, write_shard
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
    monkeypatch.setattr(store_module, "STAGE_CONTOURS", stage_contours)  # several merge steps per shard
    store = CCSStore(tmp_path_factory.mktemp("shards") / "store.sqlite")
    store.save("kept", _meta("kept"), [write_shard(earlier[:1])])
    store.save("gone", _meta("gone"), [write_shard(earlier)])
    used = max(store.all_fids("gone"))
    store.delete("gone")  # its fids are never given again

    info = store.save("b", _meta("b"), [write_shard(batch) for batch in batches])

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

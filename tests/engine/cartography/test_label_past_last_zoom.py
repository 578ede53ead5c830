"""Issue 24's crash: a contour whose own first label zoom lies past the last zoom (a ring too small to draw
before then) has no zoom to test its candidates at; it gets none instead of stopping the whole placement."""

from __future__ import annotations

import numpy as np

from engine.cartography.labels import LabelSource, LabelStyle, contour_candidates, place_labels


def source(first_zoom: float, fid: int = 1) -> LabelSource:
    a = np.linspace(0, 2 * np.pi, 400)
    base = np.column_stack([5000 * np.cos(a), 5000 * np.sin(a)])
    return LabelSource(
        fid=fid,
        elevation=500.0,
        text="500 m",
        rank=1,
        base=base,
        top=base * 0.999,
        t_at_scale=np.linspace(0.0, 1.0, 4),
        first_zoom=first_zoom,
    )


LADDER = np.array([50_000.0, 100_000.0, 250_000.0, 500_000.0])


def test_a_contour_first_labelled_past_the_last_zoom_has_no_candidates() -> None:
    xy, angle, score, first = contour_candidates(source(18.5), LADDER, 45.0, 17.0, LabelStyle())
    assert xy.shape == (0, 2) and len(angle) == len(score) == len(first) == 0


def test_it_does_not_stop_the_others_labels() -> None:
    placed = place_labels([source(18.5, fid=1), source(12.0, fid=2)], LADDER, 45.0, 17.0)
    assert len(placed) > 0 and set(placed.fid.tolist()) == {2}
    assert placed.issues == ()  # nothing failed: that ring is simply never labelled

"""Uploading a GeoJSON contour set by dropping it on the page; service errors are shown, not swallowed."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

pytestmark = pytest.mark.browser

SMALL = Path(__file__).resolve().parents[1] / "data" / "small_contours.geojson"


def drop_file(app, name: str, text: str, mime: str = "application/geo+json") -> None:
    data_transfer = app.page.evaluate_handle(
        """([name, text, mime]) => {
            const dt = new DataTransfer();
            dt.items.add(new File([text], name, {type: mime}));
            return dt;
        }""",
        [name, text, mime],
    )
    app.page.dispatch_event("#maps", "dragenter", {"dataTransfer": data_transfer})
    assert app.page.locator("#dropzone").is_visible()
    app.page.dispatch_event("#maps", "drop", {"dataTransfer": data_transfer})


def type_upload_scales(app, source: str, target: str) -> None:
    app.page.click(".upload-options summary")
    app.page.fill("#upload-source-scale", source)
    app.page.fill("#upload-target-scale", target)


def shown_error(app) -> str:
    return app.wait_until(
        "() => [...document.querySelectorAll('#messages .message.error p')].map(p => p.textContent).join('\\n')",
        what="an error message",
    )


def test_drop_uploads_builds_and_fits(app):
    app.open()
    first = app.page.evaluate("() => window.ccsm.state.datasetId")
    drop_file(app, "small_contours.geojson", SMALL.read_text())
    app.wait_until("() => !document.getElementById('upload-progress').hidden", what="progress shown")
    app.wait_until(
        "(first) => window.ccsm.state.datasetId && window.ccsm.state.datasetId !== first",
        timeout_s=60,
        arg=first,
        what="uploaded dataset selected",
    )
    app.wait_settled()
    assert app.page.evaluate("() => window.ccsm.errors") == []
    # Fitted: the view contains the data's bounds, and is not much larger.
    fit = app.page.evaluate(
        """() => {
            const b = window.ccsm.state.tilejson.bounds, v = window.ccsm.maps.a.getBounds();
            const contains = v.getWest() <= b[0] && v.getSouth() <= b[1] && v.getEast() >= b[2] && v.getNorth() >= b[3];
            return {contains,
                    ratio: (v.getEast() - v.getWest()) / (b[2] - b[0])};
        }"""
    )
    assert fit["contains"] and fit["ratio"] < 4, fit
    options = app.page.locator("#dataset option").all_inner_texts()
    assert len(options) >= 2
    assert app.rendered_lines()


def test_upload_error_is_shown(app):
    app.open()
    app.watch.allowed_statuses.update({400, 413, 415, 422})
    drop_file(app, "notes.geojson", "this is not GeoJSON", mime="text/plain")
    text = shown_error(app)
    assert "notes.geojson" in text and "HTTP 4" in text, text
    assert "[object Object]" not in text


def test_upload_uses_the_scales_typed_in_the_page(app):
    app.open()
    first = app.page.evaluate("() => window.ccsm.state.datasetId")
    type_upload_scales(app, "10000", "120000")
    drop_file(app, "small_contours.geojson", SMALL.read_text())
    dataset = app.wait_until(
        "(first) => window.ccsm.state.datasetId !== first && window.ccsm.state.datasetId",
        timeout_s=60,
        arg=first,
        what="uploaded dataset selected",
    )
    scales = httpx.get(f"{app.base_url}/datasets/{dataset}").json()["scales"]
    assert (scales["source_scale"], scales["target_scale"]) == (10000.0, 120000.0), scales


def test_upload_with_scales_in_the_wrong_order_shows_the_service_message(app):
    app.open()
    app.watch.allowed_statuses.update({400, 422})
    type_upload_scales(app, "900000", "100000")
    drop_file(app, "small_contours.geojson", SMALL.read_text())
    text = shown_error(app)
    assert "small_contours.geojson" in text and "scale" in text, text

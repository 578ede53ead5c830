"""Browser-test fixtures: the real tile service in a subprocess, and Debian's Chromium driven by Playwright.

Chromium is never downloaded (`playwright install` is not used): Playwright's Python API launches
/usr/bin/chromium with SwiftShader WebGL, so MapLibre gets WebGL2 without a GPU. A missing Chromium fails these
tests everywhere; they never skip (`make test` installs it when run as root).

Set CCSM_TEST_BASE_URL to run the tests against a service that is already running instead of starting one.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
from chromium_launch import CHROMIUM, CHROMIUM_ARGS

REPO = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 640, "height": 480}
SERVICE_START_S = 240.0
#: The service processes these fixtures started, by base URL (for stopping one while a test proves it is
#: not needed).
SERVICE_PROCESSES: dict[str, subprocess.Popen[bytes]] = {}
#: Their stores, by base URL (for `ccsm export` from the same built datasets).
SERVICE_STORES: dict[str, Path] = {}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _tail(path: Path, n: int = 40) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


def _wait_for_service(url: str, proc: subprocess.Popen[bytes] | None, log: Path | None) -> None:
    """Wait for /healthz, then for at least one ready dataset; fail at once if the server process dies."""
    deadline = time.monotonic() + SERVICE_START_S
    healthy = False
    last = ""
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the tile service exited with {proc.returncode}:\n{_tail(log) if log else ''}")
        try:
            if not healthy:
                healthy = httpx.get(f"{url}/healthz", timeout=2).status_code == 200
            if healthy:
                datasets = httpx.get(f"{url}/datasets", timeout=5).json()
                last = json.dumps(datasets)[:300]
                if any(d.get("state") == "ready" for d in datasets):
                    return
                if datasets and all(d.get("state") == "failed" for d in datasets):
                    pytest.fail(f"every dataset failed to build: {last}")
        except httpx.HTTPError as exc:
            last = repr(exc)
        time.sleep(0.25)
    pytest.fail(f"the tile service was not ready within {SERVICE_START_S:.0f} s (last: {last})")


@pytest.fixture(scope="session")
def service_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of a running tile service with a ready dataset."""
    external = os.environ.get("CCSM_TEST_BASE_URL")
    if external:
        _wait_for_service(external.rstrip("/"), None, None)
        yield external.rstrip("/")
        return
    tmp = tmp_path_factory.mktemp("browser-service")
    port = _free_port()
    log = tmp / "service.log"
    env = dict(os.environ)
    env.update(BROWSER_SERVICE_ENV(tmp))
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "app.main:app", "--host", "127.0.0.1", "--port", str(port)],
            cwd=REPO,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    SERVICE_PROCESSES[url] = proc
    SERVICE_STORES[url] = Path(env["CCSM_STORE_PATH"])
    try:
        _wait_for_service(url, proc, log)
        yield url
    finally:
        SERVICE_PROCESSES.pop(url, None)
        SERVICE_STORES.pop(url, None)
        os.kill(proc.pid, signal.SIGCONT)
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


@contextmanager
def service_stopped(url: str) -> Iterator[bool]:
    """Stop (SIGSTOP) the service process started for ``url`` while the block runs, so nothing can be served by
    it; yields False when the service is not ours to stop (CCSM_TEST_BASE_URL)."""
    proc = SERVICE_PROCESSES.get(url)
    if proc is None:
        yield False
        return
    os.kill(proc.pid, signal.SIGSTOP)
    try:
        yield True
    finally:
        os.kill(proc.pid, signal.SIGCONT)


def watched_page(context: Any, *, console_errors: bool = False) -> tuple[Any, list[str], list[str]]:
    """A new page of ``context``, every URL it asks for, and its errors (uncaught exceptions, failed requests and,
    with ``console_errors``, console.error lines): what a page served without the service is checked by."""
    page = context.new_page()
    requests: list[str] = []
    errors: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("requestfailed", lambda r: errors.append(f"{r.url} {r.failure}"))
    if console_errors:
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    return page, requests, errors


def BROWSER_SERVICE_ENV(tmp: Path) -> dict[str, str]:  # noqa: N802  (a table, read like a constant)
    """Settings for the service under test: its own store in tmp, a small dataset so it is ready in seconds."""
    return {
        "CCSM_STORE_PATH": str(tmp / "store.ccsm.sqlite"),
    }


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    """Debian's Chromium, launched once per run."""
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: install it with `sudo apt-get install chromium fonts-dejavu-core`")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


class PageFailure(AssertionError):
    """A page error, failed request or error status seen while a test waited."""


@dataclass
class Watch:
    """Everything that went wrong in the page; checked while waiting and at teardown."""

    origin: str
    page_errors: list[str] = field(default_factory=list)
    failed_requests: list[str] = field(default_factory=list)
    bad_responses: list[str] = field(default_factory=list)
    outside_requests: list[str] = field(default_factory=list)
    aborted_tiles: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    allowed_statuses: set[int] = field(default_factory=set)

    def problems(self) -> list[str]:
        return [
            *(f"pageerror: {e}" for e in self.page_errors),
            *(f"request failed: {r}" for r in self.failed_requests),
            *(f"HTTP error: {r}" for r in self.bad_responses),
            *(f"request outside the service: {r}" for r in self.outside_requests),
        ]

    def check(self) -> None:
        problems = self.problems()
        if problems:
            raise PageFailure("\n".join(problems[:10]))

    def tile_requests(self) -> list[str]:
        return [u for u in self.requests if ".mvt" in u]

    def geometry_tile_requests(self) -> list[str]:
        """Tile requests without the page's label tiles: those are per-level tiles named by the style's source
        (``/tiles/...`` with no query but ``v``), asked at integer zooms only, since label anchors never move."""
        return [u for u in self.tile_requests() if "/morph/" in u or set(httpx.URL(u).params) - {"v"}]


@dataclass
class App:
    """A page showing the app, with helpers that fail fast on a page error instead of timing out."""

    page: Any
    watch: Watch
    base_url: str

    def wait_until(self, js: str, timeout_s: float = 20.0, arg: Any = None, what: str | None = None) -> Any:
        deadline = time.monotonic() + timeout_s
        while True:
            self.watch.check()
            value = self.page.evaluate(js, arg)
            if value:
                return value
            if time.monotonic() > deadline:
                state = self.page.evaluate("() => window.ccsm?.layerStates?.() ?? null")
                raise AssertionError(f"timed out after {timeout_s} s waiting for {what or js}; layers: {state}")
            time.sleep(0.05)

    def wait_settled(self, timeout_s: float = 20.0) -> None:
        """Wait until every contour layer shows what the camera asks for, with all its tiles (twice in a row)."""
        self.wait_until("() => window.ccsm && window.ccsm.settled()", timeout_s, what="settled")
        self.page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        self.wait_until("() => window.ccsm.settled()", timeout_s, what="settled (again)")

    def open(self, query: str = "") -> None:
        self.page.goto(f"{self.base_url}/{query}")
        self.wait_until("() => window.ccsm && (window.ccsm.state.tilejson || window.ccsm.failed)", what="dataset")
        failed = self.page.evaluate("() => window.ccsm.failed ?? null")
        if failed:
            raise AssertionError(f"the page failed to start: {failed}")
        self.wait_settled()

    def jump(self, **camera: Any) -> None:
        self.page.evaluate("(c) => window.ccsm.maps.a.jumpTo(c)", camera)

    def rendered_lines(self, layer: str = "main", bbox: list[float] | None = None) -> list[list[list[float]]]:
        """Polylines (lon, lat) of the contours on screen for one layer set, optionally only those that
        cross ``bbox`` (west, south, east, north in degrees)."""
        return self.page.evaluate(
            """([name, bbox]) => {
                const l = window.ccsm.layers[name], m = l.map;
                let where;
                if (bbox) {
                    const a = m.project([bbox[0], bbox[3]]), b = m.project([bbox[2], bbox[1]]);
                    where = [[a.x, a.y], [b.x, b.y]];
                }
                const fs = where ? m.queryRenderedFeatures(where, {layers: l.visibleLayerIds})
                                 : m.queryRenderedFeatures({layers: l.visibleLayerIds});
                const out = [];
                for (const f of fs) {
                    const g = f.geometry;
                    if (g.type === 'LineString') out.push(g.coordinates);
                    else if (g.type === 'MultiLineString') out.push(...g.coordinates);
                }
                return out;
            }""",
            [layer, bbox],
        )


@pytest.fixture
def app(browser: Any, service_url: str) -> Iterator[App]:
    """A fresh page on the app; at teardown, asserts that nothing went wrong in it."""
    context = browser.new_context(viewport=VIEWPORT)
    context.set_default_timeout(10_000)
    page = context.new_page()
    watch = Watch(origin=service_url)

    def on_request_failed(request: Any) -> None:
        failure = request.failure or ""
        # Overtaken tile loads are aborted on purpose (the page removes their source; MapLibre drops hillshade
        # tiles it no longer needs).
        if "ERR_ABORTED" in failure and (".mvt" in request.url or "/hillshade/" in request.url):
            watch.aborted_tiles.append(request.url)
        else:
            watch.failed_requests.append(f"{request.url} ({failure})")

    def on_request(request: Any) -> None:
        watch.requests.append(request.url)
        if not request.url.startswith((service_url, "data:", "blob:")):
            watch.outside_requests.append(request.url)

    def on_response(response: Any) -> None:
        if response.status >= 400 and response.status not in watch.allowed_statuses:
            watch.bad_responses.append(f"{response.status} {response.url}")

    page.on("pageerror", lambda exc: watch.page_errors.append(str(exc)))
    page.on("requestfailed", on_request_failed)
    page.on("request", on_request)
    page.on("response", on_response)
    try:
        yield App(page=page, watch=watch, base_url=service_url)
        watch.check()
    finally:
        context.close()

"""Issue 28 item 4: the tokenless loopback check parses ``Host`` strictly.

``Host: [::1]evil.com`` from loopback passed the old check (the part up to ``]`` was kept); every form a Host
header can take is parsed whole here, and anything with trailing junk names no host at all.
"""

from __future__ import annotations

import pytest

from app.routes.security import LOOPBACK_NAMES, host_name
from tests.app.test_upload_ownership import BODY, GEOJSON, _client


@pytest.mark.parametrize(
    ("header", "expected"),
    [
        ("localhost", "localhost"),
        ("LocalHost:8000", "localhost"),
        ("127.0.0.1", "127.0.0.1"),
        ("127.0.0.1:65535", "127.0.0.1"),
        ("[::1]", "[::1]"),
        ("[::1]:8000", "[::1]"),
        ("[0:0:0:0:0:0:0:1]:80", "[::1]"),
        (" localhost ", "localhost"),
        ("example.org:443", "example.org"),
    ],
)
def test_well_formed_hosts_are_read_with_their_port_dropped(header: str, expected: str) -> None:
    assert host_name(header) == expected


@pytest.mark.parametrize(
    "header",
    [
        "[::1]evil.com",
        "[::1]:8000evil",
        "[::1]:8000:1",
        "localhost:8000:9000",
        "localhost:99999",
        "localhost:",
        "localhost evil.com",
        "localhost/evil",
        "[::1",
        "::1",
        "[evil]",
        "[::1%lo]",
        "user@localhost",
        "",
    ],
)
def test_malformed_hosts_name_no_host(header: str) -> None:
    assert host_name(header) is None
    assert host_name(header) not in LOOPBACK_NAMES


@pytest.mark.parametrize("host", ["[::1]evil.com", "localhost:8000evil", "[::1]:8000:1", "::1"])
def test_issue_28_spoofed_host_from_loopback_is_refused(tmp_path, built_store, synthetic_path, host: str) -> None:
    with _client(tmp_path, built_store, synthetic_path) as c:
        r = c.post("/datasets?id=spoofed", content=BODY, headers={**GEOJSON, "host": host})
        assert r.status_code == 403, r.text
        assert "localhost" in r.json()["detail"]
        assert c.delete("/datasets/hills", headers={"host": host}).status_code == 403
        assert [d["id"] for d in c.get("/datasets").json()] == ["hills"]


@pytest.mark.parametrize("host", ["localhost:8000", "[::1]:8000", "127.0.0.1"])
def test_loopback_hosts_may_still_write(tmp_path, built_store, synthetic_path, host: str) -> None:
    with _client(tmp_path, built_store, synthetic_path) as c:
        r = c.post("/datasets?id=local", content=BODY, headers={**GEOJSON, "host": host})
        assert r.status_code == 202, r.text

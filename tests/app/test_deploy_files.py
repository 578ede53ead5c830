"""Dockerfile, docker-compose.yml and .env.example, checked without a Docker engine."""

from __future__ import annotations

import re

import yaml

from app.settings import Settings
from tests.app.conftest import REPO


def dockerfile() -> list[tuple[str, str]]:
    text = (REPO / "Dockerfile").read_text()
    text = re.sub(r"\\\n", " ", text)
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            word, _, rest = line.partition(" ")
            out.append((word.upper(), rest.strip()))
    return out


def test_dockerfile_multi_stage_non_root_healthcheck_volume():
    ins = dockerfile()
    froms = [rest for word, rest in ins if word == "FROM"]
    assert len(froms) >= 2 and any(" AS " in f.upper() for f in froms)
    assert any(word == "COPY" and rest.startswith("--from=") for word, rest in ins)
    users = [rest for word, rest in ins if word == "USER"]
    assert users and users[-1] not in ("root", "0")
    health = [rest for word, rest in ins if word == "HEALTHCHECK"]
    assert len(health) == 1 and "/healthz" in health[0]
    volumes = [rest for word, rest in ins if word == "VOLUME"]
    assert volumes and "/data" in volumes[0]
    env = " ".join(rest for word, rest in ins if word == "ENV")
    assert "CCSM_STORE_PATH=/data/" in env
    assert [rest for word, rest in ins if word == "EXPOSE"] == ["8000"]
    cmd = [rest for word, rest in ins if word == "CMD"][-1]
    assert "serve" in cmd and "0.0.0.0" in cmd and "8000" in cmd


def test_dockerfile_copies_exist():
    for word, rest in dockerfile():
        if word == "COPY" and not rest.startswith("--from"):
            parts = [p for p in rest.split() if not p.startswith("--")]
            for src in parts[:-1]:
                assert (REPO / src).exists(), src


def test_compose():
    doc = yaml.safe_load((REPO / "docker-compose.yml").read_text())
    svc = doc["services"]["ccsm"]
    assert svc["build"] == "."
    assert "8000:8000" in svc["ports"]
    assert any(v.endswith(":/data") for v in svc["volumes"])
    assert "/healthz" in " ".join(svc["healthcheck"]["test"])
    assert svc["environment"]["CCSM_STORE_PATH"].startswith("/data/")
    assert set(doc["volumes"]) == {v.split(":")[0] for v in svc["volumes"]}


def test_env_example_lists_every_setting_and_parses(tmp_path):
    text = (REPO / ".env.example").read_text()
    names = {m.group(1).lower() for m in re.finditer(r"^CCSM_([A-Z_]+)=", text, re.M)}
    assert names == set(Settings.model_fields)
    s = Settings(_env_file=REPO / ".env.example")  # type: ignore[call-arg]
    defaults = Settings(_env_file=None)  # type: ignore[call-arg]
    assert s.model_dump() == defaults.model_dump()

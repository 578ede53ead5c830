import subprocess
import sys


def test_engine_imports_no_web_framework():
    code = (
        "import sys, engine, engine.store, engine.render, engine.mvt, engine.tiles\n"
        "bad = [m for m in ('fastapi', 'starlette', 'uvicorn', 'pydantic_settings') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_importing_app_main_builds_nothing(tmp_path):
    code = (
        "import os, app.main\n"
        "assert 'app' not in vars(app.main)\n"
        "assert not os.path.exists('var/never.sqlite')\n"
    )
    subprocess.run(
        [sys.executable, "-c", code],
        check=True,
        cwd=tmp_path.parent,
        env={
            **__import__("os").environ,
            "CCSM_STORE_PATH": "var/never.sqlite",
            "PYTHONPATH": str(__import__("pathlib").Path(__file__).resolve().parents[2]),
        },
    )

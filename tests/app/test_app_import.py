import subprocess
import sys


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

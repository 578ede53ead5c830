"""Which numba kernels compile after the warm-up: a fresh interpreter warms up, runs a body of code, and
reports every kernel of ``engine`` that gained a compiled signature while the body ran.

Shared by the warm-up tests of the build, of tiles from stored pieces and of morph tiles. A body sets ``n`` (how
much it did, so a probe that did nothing cannot pass) and may read ``sys.argv[1:]``; it may
call ``before = compiled()`` again to count only from there.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_HEAD = """
import json, sys
from numba.core.registry import CPUDispatcher
from engine.warmup import warm_up


def compiled():
    found = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("engine."):
            continue
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher):
                found[f"{name}.{attr}"] = len(value.signatures)
    return found


warm_up()
before = compiled()
"""

_TAIL = """
after = compiled()
print(json.dumps({"compiled": sorted(k for k, c in after.items() if c > before.get(k, 0)), "n": n}))
"""


def compiled_after_warm_up(body: str, *args: str) -> tuple[list[str], int]:
    """The kernels ``body`` compiled in a warmed-up interpreter, and the ``n`` it set."""
    code = _HEAD + textwrap.dedent(body) + _TAIL
    out = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=REPO, capture_output=True, text=True, timeout=600, check=True
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    return report["compiled"], report["n"]

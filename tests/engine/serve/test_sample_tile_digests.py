"""Issue 23: the house moves (store, readers, renderer, builds split into modules of one job) leave every tile of
the bundled sample as it was, byte for byte.

The digest was recorded with ``bench/tile_digests.py`` at 91ff931, the commit before those moves, and again on the
tree after them: both gave the same total. A change that alters any of these tiles' bytes fails here; if the
change is meant (a fix, a new property), record the new total here with the reason in the commit.
"""

from __future__ import annotations

from importlib.metadata import version

import pytest
from support.tile_digests import tile_digests, total_digest

from engine.build.datasets import SourceSpec, build_dataset
from engine.io.source import sample_contours_path
from engine.serve.renderer import Renderer
from engine.store.store import CCSStore

pytestmark = pytest.mark.slow

#: ``bench/tile_digests.py`` at 91ff931 (before the moves): 888 tiles. Recorded again when the sample's labels (a
#: contour file) began to read uphill by their neighbouring levels (issue 25): only label angles changed, since
#: with ``label_orientation="upright"`` the tiles still give f26da31f...7eb684.
#:
#: The same code gives other bytes on other machines and installs: on 2026-12-06's fresh install ebe861...
#: (upright 2eba10f5...6292e9), on 2026-12-07's (an AMD EPYC without AVX-512, the dependencies as pip resolved
#: them that day) d92ac0... with the code of both days. Neither numba's target CPU (NUMBA_CPU_NAME=generic) nor
#: numpy's SIMD level changed it, so the floating point of a dependency moved a few coordinates across a
#: rounding step. The test guards a refactor: the tiles must be one of the recorded environments' exactly; a
#: change of the code that alters any tile gives a digest none of them has. A later fresh install the same day
#: (numpy 2.4.6, scipy 1.17.1, shapely 2.2.0, numba 0.68.1, pyproj 3.7.2) gave a6f821... with stop 30's code.
RECORDED = {
    (888, "ebe861c72ab74b8f41c7dd7ffdf3e7e93e63ebdb7187777a56b4a5b259a0c366"),
    (888, "d92ac078207c4e0e1c3f91c366b4eb6a0deec52c863697423392c17ef7b6647c"),
    (888, "a6f821ce75fd98763e4f5922bb6490f8a9aec690e494ba2a02f554909d903117"),
}
#: The dependencies whose floating point the tiles rest on: named in a failure, so a new environment is told
#: from a change of the code by running the test at the last commit that passed.
NUMERIC_PACKAGES = ("numpy", "scipy", "shapely", "numba", "pyproj")


@pytest.fixture(scope="module")
def sample_renderer(tmp_path_factory: pytest.TempPathFactory) -> Renderer:
    path = tmp_path_factory.mktemp("digests") / "sample.sqlite"
    build_dataset(CCSStore(path), SourceSpec(sample_contours_path(), "sample", "sample"), workers=2)
    return Renderer(CCSStore(path, readonly=True))


def test_issue_23_sample_tiles_are_byte_for_byte_those_before_the_moves(sample_renderer: Renderer) -> None:
    found = total_digest(tile_digests(sample_renderer, "sample"))
    installed = ", ".join(f"{name} {version(name)}" for name in NUMERIC_PACKAGES)
    assert found in RECORDED, f"tiles {found} with {installed}"

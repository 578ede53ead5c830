"""The names of the generalization methods and the families they fall in: the one place every layer reads them.

The methods themselves live where their layer allows: the per-scale simplifiers in :mod:`engine.baselines`, the
continuous method in :mod:`engine.ccsm`, and the one interface the tiles, ``/simplify`` and the CLI ask (what
to draw, whether a pinned t applies, which pool a tile goes to) in :mod:`engine.serve.methods`, built from these
names. This module sits on the ground floor so that the baselines and the evaluation, below the serving layer,
see the same names without reaching up to it.
"""

from __future__ import annotations

from typing import Literal, TypeAlias, get_args

#: A simplification method every tool of ccsm can compare.
MethodName: TypeAlias = Literal["ccsm", "dp", "wm", "vw", "original"]

#: The continuous changing surface model (Qian et al. 2021): every contour at its own t.
CCSM: MethodName = "ccsm"
#: The input contours, unsimplified.
ORIGINAL: MethodName = "original"
#: The per-scale simplifiers CCSM is compared with (Douglas–Peucker, Wang–Müller, Visvalingam–Whyatt), in
#: the order the paper compares them.
BASELINE_METHODS: tuple[MethodName, ...] = ("dp", "wm", "vw")
#: The methods an evaluation compares (every method that generalizes), in the order of its tables.
COMPARED_METHODS: tuple[MethodName, ...] = (CCSM, *BASELINE_METHODS)
#: Every method, in the order messages list them.
METHODS: tuple[MethodName, ...] = get_args(MethodName)

assert set(METHODS) == {*COMPARED_METHODS, ORIGINAL}, "every method name falls in a family"

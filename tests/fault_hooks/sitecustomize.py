"""Faults injected into one step of every Python process a test starts (the service's build processes, the
real CLI), named by the environment variable ``CCSM_TEST_FAULT``: a test puts this folder first on PYTHONPATH,
so the processes run the real code with just that step broken.

``CCSM_TEST_FAULT`` is ``STEP:WHICH``:

- ``surface:ID`` / ``repair:ID``: the surface of contour ID (``*``: of every contour) cannot be built at the
  first build / at a rebuild of the crossing repair;
- ``surface+input:*``: nor its input geometry (nothing can be served);
- ``labels:ELEVATION``: the label candidates of the contours of that elevation cannot be found;
- ``internal:simplify``: ``engine.serve.simplify.simplify`` raises (an internal error of ``ccsm simplify``).
"""

from __future__ import annotations

import os

FAULT = os.environ.get("CCSM_TEST_FAULT", "")


class InjectedFault(RuntimeError):
    """The failure a test asked for."""


def _install(step: str, which: str) -> None:
    if step in ("surface", "repair", "surface+input"):
        import engine.ccsm.contour_issues as issues

        build = issues.build_ccs

        def failing_build(contour, params, factor=1.0):  # type: ignore[no-untyped-def]
            first = factor >= 1.0
            if which in ("*", str(contour.id)) and (first if step != "repair" else not first):
                raise InjectedFault(f"injected {step} fault")
            return build(contour, params, factor)

        issues.build_ccs = failing_build
        if step == "surface+input":

            def failing_input(contour):  # type: ignore[no-untyped-def]
                raise InjectedFault("injected fault in the input geometry")

            issues.still_surface = failing_input
    elif step == "labels":
        import engine.cartography.labels as labels

        candidates = labels.contour_candidates

        def failing_candidates(src, *args):  # type: ignore[no-untyped-def]
            if src.elevation == float(which):
                raise InjectedFault("injected labels fault")
            return candidates(src, *args)

        labels.contour_candidates = failing_candidates
    elif step == "internal":
        import engine.serve.simplify as simplify

        def failing_simplify(*args, **kwargs):  # type: ignore[no-untyped-def]
            raise InjectedFault("injected internal error")

        simplify.simplify = failing_simplify


if FAULT:
    _install(*FAULT.split(":", 1))

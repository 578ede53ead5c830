"""The paper's comparison of CCSM with Douglas–Peucker, Wang–Müller (and Visvalingam–Whyatt), section 3.2.

- :mod:`engine.evaluation.levels`: every method's 100-level ladder in one compact form;
- :mod:`engine.evaluation.measures`: similarity jumps, MAAV (eq. 11), linear density (eq. 12), positional
  error (eq. 13), crossings between contours;
- :mod:`engine.evaluation.pipeline`: runs it all on a contour set, on every core;
- :mod:`engine.evaluation.report`: CSV tables, PNG figures and a summary (``ccsm evaluate``).
"""

from engine.evaluation.levels import EVAL_METHODS, SurfaceLadder, VertexLadder, contour_ladders
from engine.evaluation.measures import (
    SAME_SCALE_WINDOW,
    crossing_pairs,
    largest_jump,
    linear_density,
    maav,
    positional_errors,
    same_scale_groups,
)
from engine.evaluation.pipeline import Evaluation, evaluate_set
from engine.evaluation.report import write_report

__all__ = [
    "EVAL_METHODS",
    "SAME_SCALE_WINDOW",
    "Evaluation",
    "SurfaceLadder",
    "VertexLadder",
    "contour_ladders",
    "crossing_pairs",
    "evaluate_set",
    "largest_jump",
    "linear_density",
    "maav",
    "positional_errors",
    "same_scale_groups",
    "write_report",
]

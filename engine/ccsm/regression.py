"""Scale -> t: the paper's similarity-scale regression (section 4.3), with the rules docs/design.md section 4 adds.

1. Contours are grouped by size and shape (k-means on log length and sinuosity).
2. For a reference contour of each group, the cartographic rule itself gives Sim(S): Douglas–Peucker at
   0.1 mm x S for a ladder of scales S between source and target. ``f(x) = a e^(bx) + c e^(dx)`` with
   ``x = S / source_scale`` is fitted to those points (``scipy.optimize.curve_fit``).
3. A contour's t at a scale S is where its own Sim(t) table reaches the group's similarity at S.

Rule where the paper is silent: each contour's CCS spans exactly source -> target, so the regression is used
*normalised*: the share of the group's similarity loss reached at S, ``q(S) = (f(S0) - f(S)) / (f(S0) - f(S1))``,
is matched with the share of the contour's own loss, ``(Sim(0) - Sim(t)) / (Sim(0) - Sim(1))``. t = 0 at the
source scale and t = 1 at the target scale for every contour; between them t follows the regression's shape.
When a fit fails or is not monotone, the plain mapping (t linear in log S) is used for that group.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from engine.ccsm.similarity import SimilarityReference
from engine.geom.douglas_peucker import significance
from engine.geom.polyline import path_length
from engine.params import BuildParams
from engine.tolerances import tolerance_for_scale
from engine.types import Contour

#: Number of scales of a reference contour's DP ladder (paper Table 4 had four real maps).
REFERENCE_SCALES = 12
#: Reference contours per group whose DP ladders are averaged into the group's similarity-scale trend.
REFERENCES_PER_GROUP = 8


def exponential_model(x: NDArray[np.float64], a: float, b: float, c: float, d: float) -> NDArray[np.float64]:
    """The paper's eq. 14: f(x) = a e^(bx) + c e^(dx)."""
    return a * np.exp(b * x) + c * np.exp(d * x)


@dataclass(frozen=True)
class GroupModel:
    """The similarity-scale regression of one contour group.

    Attributes
    ----------
    coefficients
        (a, b, c, d) of eq. 14, or None when the group falls back to the log-scale mapping.
    reference_id
        Id of the group's reference contour.
    scales, similarities
        The reference contour's DP ladder the fit was made on.
    """

    coefficients: tuple[float, float, float, float] | None
    reference_id: object
    scales: NDArray[np.float64]
    similarities: NDArray[np.float64]


@dataclass(frozen=True)
class ScaleModel:
    """Maps scale denominators to each contour's t.

    Attributes
    ----------
    source_scale, target_scale
        The range of the CCS.
    ladder
        (S,) log-spaced scales from source to target at which each contour's t is tabulated.
    groups
        One regression per contour group.
    """

    source_scale: float
    target_scale: float
    ladder: NDArray[np.float64]
    groups: tuple[GroupModel, ...]

    def loss_share(self, group: int, scales: NDArray[np.float64]) -> NDArray[np.float64]:
        """q(S) in [0, 1]: the share of the group's similarity loss reached at each scale."""
        s = np.clip(np.asarray(scales, dtype=float), self.source_scale, self.target_scale)
        log_share = np.log(s / self.source_scale) / np.log(self.target_scale / self.source_scale)
        model = self.groups[group] if 0 <= group < len(self.groups) else None
        if model is None or model.coefficients is None:
            return log_share
        x = s / self.source_scale
        f = exponential_model(x, *model.coefficients)
        f0 = exponential_model(np.array([1.0]), *model.coefficients)[0]
        f1 = exponential_model(np.array([self.target_scale / self.source_scale]), *model.coefficients)[0]
        return np.clip((f0 - f) / (f0 - f1), 0.0, 1.0)

    def ladder_share(self, group: int) -> NDArray[np.float64]:
        """:meth:`loss_share` at the ladder's scales, computed once per group (every contour of the group
        asks for it; read-only: the array is shared)."""
        cache: dict[int, NDArray[np.float64]] = self.__dict__.setdefault("_ladder_shares", {})
        if group not in cache:
            share = self.loss_share(group, self.ladder)
            share.flags.writeable = False
            cache[group] = share
        return cache[group]

    def t_table(
        self, group: int, sim_t: NDArray[np.float64], sim: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """A contour's t at every scale of the ladder, from its Sim(t) table; non-decreasing, 0 ... 1."""
        share = self.ladder_share(group)
        envelope = np.minimum.accumulate(sim)  # Sim as measured can wobble by sampling; t must not go back
        loss = envelope[0] - envelope
        if loss[-1] <= 1e-12:  # Ln is L0 within measurement: nothing to match, follow the share linearly
            return share.copy()
        own_share = loss / loss[-1]
        # Strictly increasing x for interpolation: flat stretches of the table take their first t.
        keep = np.concatenate([[True], np.diff(own_share) > 1e-12])
        t = np.interp(share, own_share[keep], sim_t[keep])
        t[0], t[-1] = 0.0, 1.0
        return np.maximum.accumulate(t)


def t_for_scale(ladder: NDArray[np.float64], t_at_scale: NDArray[np.float64], scale: float) -> float:
    """Interpolate a contour's t table at a scale denominator (0 below the ladder, 1 above)."""
    return float(np.interp(np.log(scale), np.log(ladder), t_at_scale, left=0.0, right=1.0))


def contour_features(contour: Contour) -> tuple[float, float]:
    """Size and shape of a contour: log10 length, and sinuosity (length / extent diagonal)."""
    length = path_length(contour.coords, contour.closed)
    diag = float(np.hypot(*np.ptp(contour.coords, axis=0)))
    return float(np.log10(max(length, 1e-9))), length / max(diag, 1e-9)


def group_features(contours: Sequence[Contour]) -> NDArray[np.float64]:
    """(n, 2) :func:`contour_features` of each contour."""
    feats = np.empty((len(contours), 2))
    for i, c in enumerate(contours):
        feats[i] = contour_features(c)
    return feats


def assign_groups(
    contours: Sequence[Contour], n_groups: int, seed: int = 0, feats: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Group contours by size and shape (``feats``: their :func:`group_features`, when already computed).

    Returns
    -------
    labels
        (n,) group of each contour.
    references
        (g,) index of each group's reference contour (the member nearest the group's centre).
    """
    feats = group_features(contours) if feats is None else feats
    k = int(min(max(n_groups, 1), len(contours)))
    scaled = (feats - feats.mean(axis=0)) / np.maximum(feats.std(axis=0), 1e-12)
    if k == 1:
        labels = np.zeros(len(contours), dtype=np.intp)
        centres = scaled.mean(axis=0, keepdims=True)
    else:
        from scipy.cluster.vq import kmeans2  # here: a process that only reads t tables never pays its import

        centres, labels = kmeans2(scaled, k, seed=seed, minit="++")
    references = []
    for g in range(len(centres)):
        members = np.flatnonzero(labels == g)
        if len(members) == 0:
            references.append(-1)
            continue
        dist = np.sum((scaled[members] - centres[g]) ** 2, axis=1)
        references.append(int(members[np.argmin(dist)]))
    return labels.astype(np.intp), np.array(references, dtype=np.intp)


def reference_sets(
    contours: Sequence[Contour],
    labels: NDArray[np.intp],
    references: NDArray[np.intp],
    per_group: int,
    feats: NDArray[np.float64],
) -> list[list[Contour]]:
    """Up to ``per_group`` members of each group nearest its reference contour in size and shape (``feats``:
    their :func:`group_features`, as the grouping used)."""
    scaled = (feats - feats.mean(axis=0)) / np.maximum(feats.std(axis=0), 1e-12)
    sets: list[list[Contour]] = []
    for g, ref in enumerate(references):
        if ref < 0:
            sets.append([])
            continue
        members = np.flatnonzero(labels == g)
        dist = np.sum((scaled[members] - scaled[ref]) ** 2, axis=1)
        nearest = members[np.argsort(dist, kind="stable")[:per_group]]
        sets.append([contours[int(i)] for i in nearest])
    return sets


def reference_similarities(
    reference: Contour, scales: NDArray[np.float64], params: BuildParams
) -> NDArray[np.float64]:
    """Sim(L0, DP(L0, 0.1 mm x S)) of one reference contour at each scale S."""
    probe = SimilarityReference.of(reference.coords, reference.closed, params.similarity_spacing_m)
    # DP at a tolerance keeps the vertices more significant than it: one significance serves every scale.
    sig = significance(reference.coords, reference.closed)
    sims = []
    for s in scales:
        keep = np.flatnonzero(sig > tolerance_for_scale(s))
        sims.append(probe.similarity(reference.coords[keep]))
    return np.array(sims)


def fit_group_model(references: list[Contour], params: BuildParams) -> GroupModel:
    """Fit eq. 14 to the mean DP-at-scale similarities of a group's reference contours.

    One contour's DP ladder is a staircase (DP drops vertices in steps); the mean over a few references near
    the group's centre is the smooth trend the paper read off real maps at several scales.
    """
    scales = np.geomspace(params.source_scale, params.target_scale, REFERENCE_SCALES)
    sims = np.mean([reference_similarities(r, scales, params) for r in references], axis=0)
    y = np.minimum.accumulate(np.array(sims))
    x = scales / params.source_scale
    coefficients = None
    if y[0] - y[-1] > 1e-9:
        span = x[-1] - x[0]
        p0 = (float(y[-1]), -1e-3, float(y[0] - y[-1]), -3.0 / span)
        # a, c >= 0 and b, d <= 0 make f non-increasing, so every fit can be inverted.
        bounds = ([0.0, -50.0, 0.0, -50.0], [10.0, 0.0, 10.0, 0.0])
        from scipy.optimize import OptimizeWarning, curve_fit  # as kmeans2: only a build fits the model

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", OptimizeWarning)
                popt, _ = curve_fit(exponential_model, x, y, p0=p0, bounds=bounds, maxfev=20000)
            fitted = exponential_model(np.linspace(x[0], x[-1], 200), *popt)
            if np.all(np.isfinite(fitted)) and fitted[0] - fitted[-1] > 1e-9:
                coefficients = tuple(float(v) for v in popt)
        except (RuntimeError, ValueError):
            coefficients = None
    return GroupModel(coefficients=coefficients, reference_id=references[0].id, scales=scales, similarities=y)  # type: ignore[arg-type]


def fit_scale_model(
    contours: Sequence[Contour], params: BuildParams, features: NDArray[np.float64] | None = None
) -> tuple[ScaleModel, NDArray[np.intp]]:
    """Group the contours (by ``features``, their :func:`group_features` when already known) and fit one
    regression per group.

    Returns
    -------
    (model, labels)
        The scale model, and each contour's group.
    """
    ladder = np.geomspace(params.source_scale, params.target_scale, params.scale_levels)
    if params.scale_mapping == "log" or not contours:
        return ScaleModel(params.source_scale, params.target_scale, ladder, ()), np.zeros(
            len(contours), np.intp
        )
    # Once for both steps: it reads every contour, from the scratch file on a big build.
    feats = group_features(contours) if features is None else features
    labels, references = assign_groups(contours, params.groups, feats=feats)
    groups = []
    for members in reference_sets(contours, labels, references, REFERENCES_PER_GROUP, feats):
        if not members:
            groups.append(GroupModel(None, None, np.zeros(0), np.zeros(0)))
        else:
            groups.append(fit_group_model(members, params))
    return ScaleModel(params.source_scale, params.target_scale, ladder, tuple(groups)), labels


def t_at_scales(ladder: NDArray[np.float64], tables: NDArray[np.float64], scale: float) -> NDArray[np.float64]:
    """Each row of ``tables`` ((n, S) t at the ladder's scales) interpolated at one scale, as ``t_for_scale``.

    The interpolation weights depend on the ladder and the scale only, so they are found once for all rows.
    """
    logs = np.log(ladder)
    x = math.log(scale)
    if x <= logs[0]:
        return np.zeros(len(tables))  # at and above the source scale: full detail
    if x >= logs[-1]:
        return tables[:, -1].copy()
    i = int(np.searchsorted(logs, x, side="right")) - 1
    f = (x - logs[i]) / (logs[i + 1] - logs[i])
    return tables[:, i] * (1 - f) + tables[:, i + 1] * f

"""Fusion of the dead-reckoning belief with the interval tracker's boxes (paper 002 section 4).

The paper's rule (``"clamp"``, the reference): once an epoch, if the estimated position lies
in the interval position box, keep it; otherwise replace it by the point of the box nearest
to it. The covariance is left alone.

The tracker gives outer boxes ``(K, 3, 2)`` (``x_m``, ``y_m``, ``theta_rad`` rows; lower,
upper columns) grouped into connected components by labels ``(K,)``. With several
components, the one nearest the estimate is used: the distance from the estimated position
to the union of the component's boxes (in ``x, y``), ties to the smallest label. Its
position box is the hull of its boxes (the paper's "rectangle"); a single component gives
the hull of all boxes. :class:`FusionReport` says which component each row used.

Options beside the paper's rule (:class:`FusionRule`):

- ``"clamp_heading"``: the clamp, and the heading clamped the same way to the component's
  heading interval, on the circle: a heading outside ``[lo, hi]`` (taken modulo ``2 pi``) goes
  to the nearer end along the circle; an interval ``2 pi`` wide or more constrains nothing.
  The heading hull of a component that straddles the ``+-pi`` cut of the tracker's chart is
  wide (sound, loose).
- ``"truncated"`` (``"truncated_heading"``): the belief truncated to the box, one coordinate
  after the other (Simon and Simon, "Constrained Kalman filtering via density function
  truncation", 2010): the marginal of ``x`` is replaced by its truncation to ``[lo, hi]``
  (mean and variance of the truncated normal), and the other states follow through their
  covariance with it (the conditional of the rest given ``x`` is kept); then ``y`` (then
  the heading, with its interval shifted by the multiple of ``2 pi`` nearest the mean). It
  moves the mean inside the box AND shrinks the covariance. Sequential truncation is exact
  for one binding coordinate, an approximation for several; the position is finally clipped
  to the box (the heading step moves it through the correlation), so the fused position
  lies in the box as with the clamp.

Never clamps to an empty set: with no box, :func:`fuse` raises :class:`EstimationError`
(``on_empty="raise"``, default) or leaves the belief unchanged (``on_empty="skip"``, reported
in :attr:`FusionReport.skipped`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Literal

import numpy as np
from scipy.special import erfcx, ndtr

from intervals.boxes import group_hulls
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import wrap_angle

_TWO_PI = 2.0 * math.pi


class FusionRule(StrEnum):
    """How the fused branch is brought into the interval box (module docstring)."""

    CLAMP = "clamp"
    """The paper's rule: the position moved to the nearest point of the box."""
    CLAMP_HEADING = "clamp_heading"
    """The clamp, and the heading clamped to the heading interval on the circle."""
    TRUNCATED = "truncated"
    """The belief truncated to the position box (mean and covariance)."""
    TRUNCATED_HEADING = "truncated_heading"
    """The truncation, then the heading truncated to its interval too."""

    @property
    def corrects_heading(self) -> bool:
        """True when the rule also brings the heading into the box's heading interval."""
        return self in (FusionRule.CLAMP_HEADING, FusionRule.TRUNCATED_HEADING)

    @property
    def truncates(self) -> bool:
        """True for the truncation rules (mean and covariance), False for the clamps (mean only)."""
        return self in (FusionRule.TRUNCATED, FusionRule.TRUNCATED_HEADING)


@dataclass(frozen=True, eq=False)
class FusionReport:
    """What one fusion did, per fused row (``r`` rows).

    Attributes:
        rows: ``(r,)`` the batch rows fused.
        component: ``(r,)`` the label of the component used (-1 when skipped).
        distance_m: ``(r,)`` distance from the estimated position to that component's
            boxes (0 inside one).
        moved: ``(r,)`` True where the position was outside the position box (clamped).
        heading_moved: ``(r,)`` True where the heading was outside its interval (heading rules).
        skipped: True when there was no box and ``on_empty="skip"`` left the belief alone.
        hull: ``(r, 3, 2)`` the hull of the component used, the box the rows were fused with
            (NaN when skipped).
    """

    rows: np.ndarray
    component: np.ndarray
    distance_m: np.ndarray
    moved: np.ndarray
    heading_moved: np.ndarray
    skipped: bool = False
    hull: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 2)))


def check_boxes(boxes, labels=None) -> tuple[np.ndarray, np.ndarray]:
    """``boxes (K, 3, 2)`` and ``labels (K,)`` (default: one component, label 0) as arrays.

    Raises:
        EstimationError: wrong shapes, non-finite bounds, a lower bound above an upper one,
            labels that are not integers.
    """
    boxes = np.asarray(boxes, dtype=float)
    if boxes.ndim != 3 or boxes.shape[1:] != (3, 2):
        raise EstimationError(f"fusion: boxes must have shape (K, 3, 2), got {boxes.shape}")
    if not np.isfinite(boxes).all():
        raise EstimationError("fusion: box bounds are not finite")
    if (boxes[..., 0] > boxes[..., 1]).any():
        raise EstimationError("fusion: a box has a lower bound above its upper bound")
    labels = np.zeros(len(boxes), dtype=np.int64) if labels is None else np.asarray(labels)
    if labels.shape != (len(boxes),) or (
        labels.size and not np.issubdtype(labels.dtype, np.integer)
    ):
        raise EstimationError(
            f"fusion: labels must be integers of shape ({len(boxes)},), got {labels.dtype} {labels.shape}"
        )
    return boxes, labels.astype(np.int64)


def box_distance(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Euclidean distance ``(P, K)`` from points ``(P, 2)`` to the ``x, y`` part of boxes ``(K, >=2, 2)``."""
    gap = np.maximum(boxes[None, :, :2, 0] - points[:, None, :], 0.0) + np.maximum(
        points[:, None, :] - boxes[None, :, :2, 1], 0.0
    )
    return np.hypot(gap[..., 0], gap[..., 1])


def nearest_component(points, boxes, labels) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The component nearest each point and its hull.

    Args:
        points: ``(P, 2)`` positions; boxes ``(K, 3, 2)``, ``K >= 1``; labels ``(K,)``.

    Returns:
        ``label (P,)``, ``distance_m (P,)`` to the union of that component's boxes, and the
        component's hull ``(P, 3, 2)``. ``O(P K + K log K)`` time and ``O(P K + C)`` memory
        for ``C`` components.
    """
    points = np.asarray(points, dtype=float)
    names, member = np.unique(labels, return_inverse=True)  # components sorted by label
    order = np.argsort(member, kind="stable")  # the boxes grouped by component
    starts = np.searchsorted(member[order], np.arange(len(names)))  # (C,) each group's first
    distance = box_distance(points, boxes[order])  # (P, K)
    per_component = np.minimum.reduceat(distance, starts, axis=1)  # (P, C)
    chosen = np.argmin(per_component, axis=1)  # first = smallest label on ties
    hulls = group_hulls(boxes, member, len(names))  # (C, 3, 2)
    return names[chosen], per_component[np.arange(len(points)), chosen], hulls[chosen]


def clamp_heading(theta_rad, interval) -> np.ndarray:
    """Headings ``(P,)`` moved to the nearest point of ``interval (P, 2)`` on the circle
    (wrapped to ``[-pi, pi)``); unchanged inside, or when the interval is ``2 pi`` wide."""
    theta = np.asarray(theta_rad, dtype=float)
    lower, width = interval[:, 0], interval[:, 1] - interval[:, 0]
    offset = np.mod(theta - lower, _TWO_PI)  # in [0, 2 pi)
    inside = (offset <= width) | (width >= _TWO_PI)
    to_upper = offset - width  # angle from the upper end, going forward
    to_lower = _TWO_PI - offset  # angle to the lower end, going forward
    target = np.where(to_upper <= to_lower, lower + width, lower)
    return np.where(inside, theta, wrap_angle(target))


def truncated_standard_normal(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance ``(P,)`` of ``N(0, 1)`` truncated to ``[lower, upper]`` ``(P,)``.

    Stable far in the tails: an interval wholly below 0 is mirrored above it, and an
    interval above 0 uses the scaled complementary error function
    (``Q(x) = exp(-x^2/2) erfcx(x / sqrt 2) / 2``), so with ``E = exp(-(u^2 - l^2)/2)``::

        mean = sqrt(2/pi) (1 - E) / (erfcx(l/sqrt 2) - E erfcx(u/sqrt 2))
        var  = 1 + sqrt(2/pi) (l - u E) / (erfcx(l/sqrt 2) - E erfcx(u/sqrt 2)) - mean^2

    The results are clipped to ``[lower, upper]`` and ``[1e-12, 1]`` (rounding guards).
    """
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    flip = upper <= 0.0
    lo, hi = np.where(flip, -upper, lower), np.where(flip, -lower, upper)
    root_half, scale = math.sqrt(0.5), math.sqrt(2.0 / math.pi)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        tail_factor = np.exp(-0.5 * (hi - lo) * (hi + lo))
        denominator = erfcx(lo * root_half) - tail_factor * erfcx(hi * root_half)
        tail_mean = scale * (1.0 - tail_factor) / denominator
        tail_second = scale * (lo - hi * tail_factor) / denominator
        mass = ndtr(hi) - ndtr(lo)
        density_lo, density_hi = np.exp(-0.5 * lo**2), np.exp(-0.5 * hi**2)
        mid_mean = (density_lo - density_hi) / (math.sqrt(_TWO_PI) * mass)
        mid_second = (lo * density_lo - hi * density_hi) / (math.sqrt(_TWO_PI) * mass)
    tail = lo >= 0.0
    mean = np.where(tail, tail_mean, mid_mean)
    ratio = 1.0 + np.where(tail, tail_second, mid_second) - mean**2
    mean = np.clip(mean, lo, hi)
    ratio = np.clip(ratio, 1e-12, 1.0)
    return np.where(flip, -mean, mean), ratio


def truncate_coordinate(mean, cov, index: int, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussians ``mean (P, n)``, ``cov (P, n, n)`` with the marginal of coordinate
    ``index`` truncated to ``[lower, upper]`` ``(P,)`` (Simon and Simon 2010, one constraint)::

        (mu_t, s_t^2) = moments of N(mu, s^2) truncated to [lower, upper]
        x' = x + P[:, i] (mu_t - mu) / s^2,   P' = P - P[:, i] P[i, :] (1 - s_t^2 / s^2) / s^2
    """
    mu = mean[:, index]
    var = cov[:, index, index]
    std = np.sqrt(var)
    shift, ratio = truncated_standard_normal((lower - mu) / std, (upper - mu) / std)
    new_mu, new_var = mu + std * shift, var * ratio
    column = cov[:, :, index]  # (P, n)
    mean = mean + column * ((new_mu - mu) / var)[:, None]
    cov = (
        cov - column[:, :, None] * column[:, None, :] * ((1.0 - new_var / var) / var)[:, None, None]
    )
    return mean, 0.5 * (cov + cov.mT)


def fuse(
    belief: Gaussian,
    boxes,
    labels=None,
    rows=(1,),
    rule: FusionRule | str = FusionRule.CLAMP,
    on_empty: Literal["raise", "skip"] = "raise",
) -> tuple[Gaussian, FusionReport]:
    """Fuse the rows ``rows`` of the batched ``belief (B, n)`` with the interval boxes.

    The first three states of the belief must be ``(x_m, y_m, theta_rad)`` (as in
    :mod:`localization.dead_reckoning`); the other rows are returned unchanged.

    Args:
        belief: the batched belief; boxes: ``(K, 3, 2)``; labels: ``(K,)`` component labels
            (``None``: one component).
        rows: the batch rows to fuse (default ``(1,)``: the fused branch beside the
            UKF-only row 0).
        rule: a :class:`FusionRule` (or its value); ``"clamp"`` is the paper's.
        on_empty: with no box, ``"raise"`` an :class:`EstimationError` or ``"skip"``.

    Returns:
        The new belief and a :class:`FusionReport`.

    Raises:
        EstimationError: bad boxes, labels, rows or rule; no box under ``on_empty="raise"``.
    """
    try:
        rule = FusionRule(rule)
    except ValueError:
        allowed = ", ".join(repr(str(r)) for r in FusionRule)
        raise EstimationError(f"fusion: rule must be one of {allowed}, got {rule!r}") from None
    if on_empty not in ("raise", "skip"):
        raise EstimationError(f"fusion: on_empty must be 'raise' or 'skip', got {on_empty!r}")
    if not isinstance(belief, Gaussian) or belief.mean.ndim != 2 or belief.dim < 3:
        raise EstimationError(
            "fusion: the belief must be a batched Gaussian (B, n) with the pose first"
        )
    rows = np.asarray(rows, dtype=np.int64).reshape(-1)
    batch = belief.mean.shape[0]
    if (
        rows.size == 0
        or (rows < 0).any()
        or (rows >= batch).any()
        or len(np.unique(rows)) != rows.size
    ):
        raise EstimationError(
            f"fusion: rows must be distinct indices in [0, {batch}), got {rows.tolist()}"
        )
    boxes, labels = check_boxes(boxes, labels)
    count = rows.size
    if len(boxes) == 0:
        if on_empty == "raise":
            raise EstimationError(
                "fusion: no interval box (the set is empty): refusing to clamp to an empty set "
                "(on_empty='skip' leaves the belief unchanged)"
            )
        unmoved = np.zeros(count, dtype=bool)
        return belief, FusionReport(
            rows,
            np.full(count, -1),
            np.full(count, np.nan),
            unmoved,
            unmoved,
            True,
            np.full((count, 3, 2), np.nan),
        )

    mean = np.array(belief.mean)
    cov = np.array(belief.cov)
    fused_mean, fused_cov = mean[rows], cov[rows]
    label, distance, hull = nearest_component(fused_mean[:, :2], boxes, labels)
    inside = (fused_mean[:, :2] >= hull[:, :2, 0]).all(axis=1) & (
        fused_mean[:, :2] <= hull[:, :2, 1]
    ).all(axis=1)
    with_heading = rule.corrects_heading
    theta = fused_mean[:, 2]
    heading_moved = np.zeros(count, dtype=bool)
    if with_heading:
        heading_moved = clamp_heading(theta, hull[:, 2]) != theta
    if not rule.truncates:
        fused_mean[:, :2] = np.clip(
            fused_mean[:, :2], hull[:, :2, 0], hull[:, :2, 1]
        )  # nearest point of the box
        if with_heading:
            fused_mean[:, 2] = clamp_heading(theta, hull[:, 2])
    else:
        for index in (0, 1):
            fused_mean, fused_cov = truncate_coordinate(
                fused_mean, fused_cov, index, hull[:, index, 0], hull[:, index, 1]
            )
        if with_heading:
            # the heading interval shifted by the multiple of 2 pi nearest the (current) mean
            now = fused_mean[:, 2]
            shift = _TWO_PI * np.round((now - hull[:, 2].mean(axis=1)) / _TWO_PI)
            lower, upper = hull[:, 2, 0] + shift, hull[:, 2, 1] + shift
            narrow = upper - lower < _TWO_PI
            if narrow.any():
                part_mean, part_cov = truncate_coordinate(
                    fused_mean[narrow], fused_cov[narrow], 2, lower[narrow], upper[narrow]
                )
                part_mean[:, 2] = np.clip(part_mean[:, 2], lower[narrow], upper[narrow])
                fused_mean[narrow], fused_cov[narrow] = part_mean, part_cov
        # in the box whatever the rounding and the heading step (it moves x, y through the correlation)
        fused_mean[:, :2] = np.clip(fused_mean[:, :2], hull[:, :2, 0], hull[:, :2, 1])
    mean[rows], cov[rows] = fused_mean, fused_cov
    report = FusionReport(rows, label, distance, ~inside, heading_moved, hull=hull)
    return Gaussian(mean, cov, belief.angle_indices), report

r"""The sonar scan model: the belt, the reading intervals, a run's scene and an epoch's scan.

Model. Sensor ``i`` sits at ``m_i`` in the robot frame and points along ``alpha_i``; for the pose
``p = (x, y, theta)`` it is at ``s_i(p) = (x, y) + R(theta) m_i`` and its cone holds the
directions ``[theta + alpha_i - gamma, theta + alpha_i + gamma]``. The modelled reading
``d_i(p)`` is the distance from ``s_i`` to the nearest map point inside the cone (``+inf`` if
none). A reading ``m`` with ``|e| <= e_abs + e_rel d`` gives the distance interval
``[d_i] = [(m - e_abs)/(1 + e_rel), (m + e_abs)/(1 - e_rel)]`` (outward rounded); a finite
reading also means ``d <= d_max`` (the simulator returns no echo beyond), so ``hi`` is capped at
``d_max``. A no-echo reading means ``d > d_max`` and is used (as ``[d_max, inf]``, free space)
only when the caller states that echoes are never lost; otherwise it is ignored.

A :class:`SonarScene` holds what does not change during a run (the map's segments and
boundary, validated once, and the belt); :meth:`SonarScene.scan` turns one epoch's readings
into a :class:`SonarScan`, the input of every box test (:mod:`intervals.sonar.cone`,
:mod:`intervals.sonar.room`, :mod:`intervals.sonar.rays`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from intervals.boxes import as_boxes, hull
from intervals.errors import IntervalError
from intervals.sonar.cone_kernel import ECHO, FREE, IGNORED  # kinds of sensor constraint
from intervals.sonar.geometry import (
    GUARD_M,
    MAX_COORDINATE_M,
    SENSOR_BOX_MARGIN,
    down,
    segment_box_gap,
    up,
)
from intervals.sonar.segment_grid import SegmentGrid

__all__ = ["ECHO", "FREE", "IGNORED", "SonarBelt", "SonarScan", "SonarScene", "reading_intervals"]


@dataclass(frozen=True, eq=False)
class SonarBelt:
    """Geometry and error bounds of a sonar belt (same fields as ``robotsim``'s parameters).

    ``mount_xy (k, 2)`` robot frame, m; ``mount_angle_rad (k,)`` robot frame;
    ``half_aperture_rad`` in ``(0, pi/2)``; ``d_max_m`` range limit;
    ``|error| <= error_abs_bound_m + error_rel_bound * d``; ``echoes_never_lost``: a no-echo
    reading then proves free space up to ``d_max_m`` (only true when the sensor cannot lose an
    echo: see the team contract).
    """

    mount_xy: np.ndarray
    mount_angle_rad: np.ndarray
    half_aperture_rad: float
    d_max_m: float = 3.0
    error_abs_bound_m: float = 0.02
    error_rel_bound: float = 0.01
    echoes_never_lost: bool = False

    def __post_init__(self) -> None:
        xy = np.array(self.mount_xy, dtype=np.float64)
        ang = np.array(self.mount_angle_rad, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] == 0 or ang.shape != (xy.shape[0],):
            raise IntervalError(
                f"sonar belt: mount_xy must be (k, 2) and mount_angle_rad (k,), got "
                f"{xy.shape} and {ang.shape}"
            )
        if not (np.all(np.isfinite(xy)) and np.all(np.isfinite(ang))):
            raise IntervalError("sonar belt: mount positions and angles must be finite")
        checks = (
            (0.0 < self.half_aperture_rad < np.pi / 2, "half_aperture_rad must be in (0, pi/2)"),
            (0.0 < self.d_max_m < np.inf, "d_max_m must be positive and finite"),
            (0.0 <= self.error_abs_bound_m < np.inf, "error_abs_bound_m must be >= 0"),
            (0.0 <= self.error_rel_bound < 1.0, "error_rel_bound must be in [0, 1)"),
        )
        for ok, message in checks:
            if not ok:
                raise IntervalError(f"sonar belt: {message}")
        xy.setflags(write=False)
        ang.setflags(write=False)
        object.__setattr__(self, "mount_xy", xy)
        object.__setattr__(self, "mount_angle_rad", ang)

    @classmethod
    def from_params(cls, params, echoes_never_lost: bool | None = None) -> SonarBelt:
        """From any object with the fields of ``robotsim.sensors.sonar.SonarBeltParams``.

        ``echoes_never_lost`` defaults to ``params.lost_echo_prob == 0``.
        """
        if echoes_never_lost is None:
            echoes_never_lost = getattr(params, "lost_echo_prob", 1.0) == 0.0
        return cls(
            mount_xy=params.mount_xy,
            mount_angle_rad=params.mount_angle_rad,
            half_aperture_rad=float(params.half_aperture_rad),
            d_max_m=float(params.d_max_m),
            error_abs_bound_m=float(params.error_abs_bound_m),
            error_rel_bound=float(params.error_rel_bound),
            echoes_never_lost=bool(echoes_never_lost),
        )

    @property
    def count(self) -> int:
        """Number of sensors k."""
        return self.mount_angle_rad.shape[0]

    @cached_property
    def mount_polar(self) -> tuple[np.ndarray, np.ndarray]:
        """``(radius (k, 2), angle (k, 2))`` intervals of the mounts in polar form, robot frame:
        ``m_i = r_i (cos beta_i, sin beta_i)``; ``hypot`` and ``arctan2`` are within 1 ulp, the
        intervals are widened by 1 and 2 ulps."""
        radius = np.hypot(self.mount_xy[:, 0], self.mount_xy[:, 1])
        beta = np.arctan2(self.mount_xy[:, 1], self.mount_xy[:, 0])
        return (
            np.stack([np.maximum(down(radius), 0.0), up(radius)], axis=-1),
            np.stack([down(down(beta)), up(up(beta))], axis=-1),
        )

    @cached_property
    def mount_trig(self) -> tuple[np.ndarray, np.ndarray]:
        """``(cos beta_i, sin beta_i)`` ``(k,)`` of the mount directions (see
        :meth:`mount_polar`)."""
        beta = np.arctan2(self.mount_xy[:, 1], self.mount_xy[:, 0])
        return np.cos(beta), np.sin(beta)

    @cached_property
    def mount_radius_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(r_lo, r_hi)`` ``(k,)`` of the mount radii (see :meth:`mount_polar`)."""
        r = self.mount_polar[0]
        return r[:, 0], r[:, 1]

    @cached_property
    def cone_trig(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``((cos, sin) of alpha_i - gamma, (cos, sin) of alpha_i + gamma)``, each ``(k,)``:
        the right and left cone edges in the robot frame."""
        right = self.mount_angle_rad - self.half_aperture_rad
        left = self.mount_angle_rad + self.half_aperture_rad
        return (np.cos(right), np.sin(right)), (np.cos(left), np.sin(left))

    @cached_property
    def sensor_box_margin_m(self) -> float:
        """Widening of the computed sensor-position boxes: ``SENSOR_BOX_MARGIN`` times (1 m +
        the largest mount radius), far above their float error (see :mod:`intervals.sonar.geometry`);
        computed once per belt (every test and contractor call reads it)."""
        return SENSOR_BOX_MARGIN * (1.0 + float(np.max(self.mount_polar[0][:, 1])))

    @cached_property
    def kernel_table(self) -> np.ndarray:
        """``(k, 8)`` float64, the constants the compiled kernel reads per sensor (columns
        named in :mod:`intervals.sonar.cone_kernel`): ``cos beta_i, sin beta_i`` (:meth:`mount_trig`),
        ``r_lo, r_hi`` (:meth:`mount_radius_bounds`), and ``(cos, sin)`` of the right and left
        cone edges (:meth:`cone_trig`): the very values the numpy reference uses."""
        (c_right, s_right), (c_left, s_left) = self.cone_trig
        table = np.ascontiguousarray(
            np.column_stack(
                [*self.mount_trig, *self.mount_radius_bounds, c_right, s_right, c_left, s_left]
            )
        )
        table.setflags(write=False)
        return table


def reading_intervals(readings_m, belt: SonarBelt) -> tuple[np.ndarray, np.ndarray]:
    """Distance intervals and constraint kinds from readings ``(k,)`` (``inf`` = no echo).

    Returns ``(ranges (k, 2), kind (k,) int8)``: for an echo
    ``[(m - e_abs)/(1 + e_rel), min((m + e_abs)/(1 - e_rel), d_max)]`` rounded outward (lower
    bound at least 0; an echo whose interval is empty cannot come from a fault-free sensor, it is
    marked by ``lo > hi`` and rejects every box); a no-echo reading gives ``[d_max, inf]`` of
    kind :data:`FREE` when ``belt.echoes_never_lost``, else kind :data:`IGNORED`.
    Raises :class:`IntervalError` for a wrong shape, NaN or negative readings.
    """
    m = np.asarray(readings_m, dtype=np.float64)
    if m.shape != (belt.count,):
        raise IntervalError(f"sonar readings: expected shape ({belt.count},), got {m.shape}")
    if np.any(np.isnan(m)) or np.any(m < 0) or np.any(m == -np.inf):
        raise IntervalError("sonar readings: NaN or negative reading (use inf for no echo)")
    echo = np.isfinite(m)
    mf = np.where(echo, m, 0.0)
    lo = down(down(mf - belt.error_abs_bound_m) / up(1.0 + belt.error_rel_bound))
    hi = up(up(mf + belt.error_abs_bound_m) / down(1.0 - belt.error_rel_bound))
    lo = np.maximum(lo, 0.0)
    hi = np.minimum(hi, belt.d_max_m)
    free = ~echo & belt.echoes_never_lost
    kind = np.where(echo, ECHO, np.where(free, FREE, IGNORED)).astype(np.int8)
    lo = np.where(echo, lo, np.where(free, belt.d_max_m, 0.0))
    hi = np.where(echo, hi, np.inf)
    return np.stack([lo, hi], axis=-1), kind


@dataclass(frozen=True, eq=False)
class SonarScene:
    """The fixed part of a run's sonar constraints: the map and the belt.

    ``segments (m, 2, 2)`` world frame, m (coordinates finite, ``|.| <= MAX_COORDINATE_M``);
    ``belt``; ``boundary (p, 2)`` outer wall polygon whose interior is the free space, or None.
    Validated once; :meth:`scan` then builds each epoch's :class:`SonarScan` without copying or
    checking the map again.
    """

    segments: np.ndarray
    belt: SonarBelt
    boundary: np.ndarray | None = None

    def __post_init__(self) -> None:
        seg = np.array(self.segments, dtype=np.float64)
        if seg.ndim != 3 or seg.shape[1:] != (2, 2):
            raise IntervalError(f"sonar scan: segments must be (m, 2, 2), got {seg.shape}")
        if not np.all(np.abs(seg) <= MAX_COORDINATE_M):
            raise IntervalError(
                f"sonar scan: segment coordinates must be finite, |.| <= {MAX_COORDINATE_M} m"
            )
        boundary = None
        if self.boundary is not None:
            boundary = np.array(self.boundary, dtype=np.float64)
            if boundary.ndim != 2 or boundary.shape[1] != 2 or boundary.shape[0] < 3:
                raise IntervalError(
                    f"sonar scan: boundary must be (p >= 3, 2), got {boundary.shape}"
                )
            if not np.all(np.abs(boundary) <= MAX_COORDINATE_M):
                raise IntervalError("sonar scan: boundary coordinates must be finite and bounded")
            boundary.setflags(write=False)
        seg = np.ascontiguousarray(seg)
        seg.setflags(write=False)
        object.__setattr__(self, "segments", seg)
        object.__setattr__(self, "boundary", boundary)

    @cached_property
    def grid(self) -> SegmentGrid:
        """The segments in a uniform grid (:mod:`intervals.sonar.segment_grid`), built on first
        use: the box tests look up the segments near a box there."""
        return SegmentGrid.build(self.segments)

    @cached_property
    def mount_radius_m(self) -> float:
        """Largest distance of a sensor from the robot's centre, m."""
        return float(np.max(np.hypot(*self.belt.mount_xy.T)))

    def scan(self, readings_m) -> SonarScan:
        """The scan of one epoch's readings ``(k,)`` m (``inf`` = no echo) in this scene."""
        return SonarScan(self.segments, self.belt, readings_m, self.boundary, scene=self)


@dataclass(frozen=True, eq=False)
class SonarScan:
    """One scan's constraints against a map: everything the box tests need.

    ``segments (m, 2, 2)`` world frame, m: the segments the tests consider (the scene's, or
    those within reach of some boxes after :meth:`restricted_to`); ``belt``; ``readings_m
    (k,)``; ``boundary (p, 2)`` outer wall polygon whose interior is the free space, or None;
    ``scene``: the :class:`SonarScene` the scan belongs to (None: built here from the three
    map fields, which are then validated); ``segment_ids (m,)``: the indices of ``segments``
    among the scene's (None: all of them, in order). Derived fields: ``ranges (k, 2)`` and ``kind (k,)``
    from :func:`reading_intervals`; ``reach_m``: the largest distance at which a segment can
    matter to some sensor (0 if no sensor is used).
    """

    segments: np.ndarray
    belt: SonarBelt
    readings_m: np.ndarray
    boundary: np.ndarray | None = None
    scene: SonarScene | None = field(default=None, repr=False)
    segment_ids: np.ndarray | None = field(default=None, repr=False)
    ranges: np.ndarray = field(init=False)
    kind: np.ndarray = field(init=False)
    reach_m: float = field(init=False)

    def __post_init__(self) -> None:
        if self.scene is None:
            scene = SonarScene(self.segments, self.belt, self.boundary)
            object.__setattr__(self, "scene", scene)
            object.__setattr__(self, "segments", scene.segments)
            object.__setattr__(self, "boundary", scene.boundary)
            object.__setattr__(self, "segment_ids", None)
        ranges, kind = reading_intervals(self.readings_m, self.belt)
        object.__setattr__(self, "readings_m", np.asarray(self.readings_m, dtype=np.float64))
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "kind", kind)
        used = kind != IGNORED
        reach = np.where(kind == ECHO, ranges[:, 1], self.belt.d_max_m)
        object.__setattr__(self, "reach_m", float(np.max(reach[used])) if used.any() else 0.0)

    @cached_property
    def allowed(self) -> np.ndarray:
        """``(M,)`` bool over the scene's segments: the segment is one of this scan's."""
        assert self.scene is not None
        mask = np.zeros(self.scene.segments.shape[0], dtype=bool)
        mask[slice(None) if self.segment_ids is None else self.segment_ids] = True
        return mask

    def restricted_to(self, boxes: np.ndarray) -> SonarScan:
        """The same scan with only the segments that can matter to poses in ``boxes``: those
        whose distance bound to the (x, y) hull of the boxes is at most the reach plus the
        mount radius (plus ``GUARD_M``), looked up in the scene's grid (which gathers every
        such segment, :mod:`intervals.sonar.segment_grid`) and kept in the scene's order."""
        assert self.scene is not None
        hull_xy = hull(as_boxes(boxes))[:2]
        centre, half = (hull_xy[:, 0] + hull_xy[:, 1]) / 2, (hull_xy[:, 1] - hull_xy[:, 0]) / 2
        reach = self.reach_m + self.scene.mount_radius_m + GUARD_M
        ids = self.scene.grid.near(centre, reach + float(np.hypot(*half)))
        if self.segment_ids is not None:
            ids = ids[self.allowed[ids]]
        seg = self.scene.segments[ids]
        a, e = seg[:, 0], seg[:, 1] - seg[:, 0]
        gap = segment_box_gap(a[:, 0], a[:, 1], e[:, 0], e[:, 1], *centre, *half)
        ids = ids[gap <= reach]
        # the same readings: their intervals, kinds and reach are this scan's (validated and
        # computed once), only the segments (and the mask derived from them) change
        restricted = copy.copy(self)
        restricted.__dict__.pop("allowed", None)
        object.__setattr__(restricted, "segments", self.scene.segments[ids])
        object.__setattr__(restricted, "segment_ids", ids)
        return restricted

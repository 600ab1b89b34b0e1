"""The 1 Hz interval tracker: global localisation, tracking, GOMNE, inconsistency, relocalisation.

Paper 002 section 3: the pose set is first found globally (whole map, any heading); at each
later scan the previous set is predicted *by the robot's physical limits* (it can have moved
at most ``v_max dt`` and turned at most ``omega_max dt``) and contracted by the sonar tests.
Two predictions are offered (docs/models.md section 4):

* ``"sivia"``: the hull of the previous outer boxes, inflated by the limits, inverted as one
  box; when the set is spread (its hull more than :data:`SPREAD_FACTOR` times its volume, as
  a repetitive map's several candidate places), the boxes of that paving meeting none of
  its components' hulls, inflated, are rejected untested (never a looser set than the hull
  alone); a :class:`Refinement` (the finer set behind a coarse epoch) is predicted box by
  box for its boxes wider than ``eps`` (left whole by the budget), so that the next epoch
  refines a coarse cover instead of re-paving its hull;
* ``"imagesp"``: every previous box mapped through the motion inclusion function (by default
  the same inflation), the images merged into a regular grid (IMAGESP), then contracted by
  SIVIA. It keeps separate components apart, so it is tighter when the set is not convex.

Outliers: q-relaxation and GOMNE (:func:`intervals.localize.gomne`), up to ``q_max``. Each epoch
ends in one of the :class:`EpochStatus`:

* ``"global"``: a global search gave the set (the first epoch, and the one after an epoch
  without a set);
* ``"tracking"``: the predicted set, contracted by the scan, is not empty;
* ``"inconsistent"``: the tracked set is empty even with ``q_max`` outliers (a kidnapping, or
  more outliers than ``q_max``): no set is returned (never clamp to an empty or invented
  set) and the next epoch relocalises globally, on a fresh scan (relocalising on the scan
  that just failed could lock onto a wrong place when the failure came from outliers);
* ``"lost"``: a global search was empty: no set; the next epoch searches globally again.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import numba
import numpy as np

from intervals.boxes import (
    Subpaving,
    as_boxes,
    component_hulls,
    hull,
    inflate,
    max_width,
    merge_adjacent,
    pose_scale,
    unwrap_headings,
    volume,
    wrap_headings,
)
from intervals.errors import IntervalError
from intervals.imagesp import coarsen, imagesp
from intervals.localize import (
    GLOBAL_SPLITS_PER_LEVEL,
    MAX_WITHIN_REGIONS,
    TESTS_PER_BOX,
    box_test,
    gomne,
)
from intervals.sivia import OUTSIDE
from intervals.sonar.scan import IGNORED, SonarScan
from intervals.tighten import MAX_LEVELS
from validated_records import bounded, validate_fields

#: The ``"sivia"`` prediction predicts each connected component (and each box wider than
#: ``eps``) apart when the hull of the previous set is more than this many times the set's
#: volume; below, it predicts the hull (one component, compact: the hull is then about as
#: tight and costs no component search).
SPREAD_FACTOR = 8.0


def _unwrapped(boxes: np.ndarray) -> np.ndarray:
    """``boxes (N, 3, 2)`` with their headings unwrapped near the first box's (a set across
    the +-pi cut as one narrow heading interval, possibly beyond ``pi``)."""
    return unwrap_headings(boxes, (boxes[0, 2, 0] + boxes[0, 2, 1]) / 2.0)


#: Cells per axis of the grid on which :func:`covered_volume` counts what boxes cover.
COVER_CELLS = 32


@numba.njit(cache=True)
def _covered_cells(lo, hi, origin, width, cells):
    """The number of cells, of a grid of ``cells`` per axis over the box ``origin + [0,
    width]`` (``(d,)`` each), that some box of ``lo, hi (N, d)`` covers once snapped outward
    to the grid (:func:`covered_volume`). Each box adds its ``2^d`` corners, signed by
    inclusion-exclusion, to a difference array of ``(cells + 1)^d`` counts (flat, C order);
    prefix sums along each axis, in place, then give each cell the number of boxes over it.
    ``O(2^d N + d cells^d)``."""
    n, d = lo.shape
    side = cells + 1
    stride = np.empty(d, dtype=np.int64)
    size = 1
    for a in range(d - 1, -1, -1):
        stride[a] = size
        size *= side
    counts = np.zeros(size, dtype=np.int64)
    first, last = np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64)
    for i in range(n):
        for a in range(d):
            f = min(max(np.floor((lo[i, a] - origin[a]) / width[a] * cells), 0.0), cells - 1.0)
            e = min(max(np.ceil((hi[i, a] - origin[a]) / width[a] * cells), 1.0), float(cells))
            first[a], last[a] = int(f), max(int(e), int(f) + 1)
        for corner in range(1 << d):
            index, sign = 0, 1
            for a in range(d):
                if corner >> (d - 1 - a) & 1:
                    index += last[a] * stride[a]
                    sign = -sign
                else:
                    index += first[a] * stride[a]
            counts[index] += sign
    for a in range(d):  # prefix sums along axis a: the counts seen as (outer, side, inner)
        inner = stride[a]
        for start in range(0, size, side * inner):
            for index in range(start + inner, start + side * inner):
                counts[index] += counts[index - inner]
    # a box adds 1 to the cells from its first to before its last index on every axis, and
    # last <= cells: the slabs at index ``cells`` hold 0, every positive count is a cell's
    covered = 0
    for index in range(size):
        covered += counts[index] > 0
    return covered


def covered_volume(boxes: np.ndarray, cells: int = COVER_CELLS) -> float:
    """An upper estimate of the volume of the union of ``boxes (N, d, 2)`` that counts
    overlaps once: each box snapped outward to a grid of ``cells`` per axis over their hull,
    the cells covered by any box counted (:func:`_covered_cells`, compiled). ``O(N +
    cells^d)``. The sum of the volumes (:func:`volume`) counts a region held by overlapping
    boxes (several initial boxes kept whole) once per box."""
    whole = hull(boxes)
    width = whole[:, 1] - whole[:, 0]
    if not np.all(width > 0):
        return volume(boxes)
    lo, hi = (np.ascontiguousarray(boxes[..., k], dtype=np.float64) for k in (0, 1))
    covered = _covered_cells(lo, hi, np.ascontiguousarray(whole[:, 0]), width, int(cells))
    return float(covered * np.prod(width / cells))


#: A :class:`Refinement` holds at most this many times ``max_boxes`` boxes (the reported set
#: at most ``max_boxes``): 9.6 MB at the default 10 000, for one epoch at a time. As many as
#: SIVIA may test (``TESTS_PER_BOX``): fewer made the refinement of office at ``max_boxes``
#: 200 merge, and stop, every epoch; with 20 it is fine again by the ninth.
KEPT_PER_BOX = TESTS_PER_BOX

#: With ``whole_boxes``, a tracking epoch's SIVIA tests at most this many times ``max_boxes``
#: boxes (a belt that may lose its echoes: :data:`LOST_ECHO_TRACKING_TESTS`; global searches
#: and the epochs that continue a :class:`Refinement`:
#: :data:`intervals.localize.TESTS_PER_BOX`), and none is refined after it: a tracking
#: set that needs more is large by nature (big_hall with half its echoes lost, where one or two
#: echoes leave slabs of poses as wide as the prediction), and a depth-first cut at 4 gave on
#: 30 epochs of it a smaller mean set (285 against 454 m²) in a quarter of the time of 20.
TRACKING_TESTS_PER_BOX = 4

#: ... but at least this many tests (or ``TESTS_PER_BOX * max_boxes`` if fewer): a small
#: ``max_boxes`` (office at 200) keeps the budget it had for its tracking sets.
TRACKING_MIN_TESTS = 40_000

#: With a belt that may lose its echoes (``SonarBelt.echoes_never_lost`` false: a reading
#: without echo is ignored, not free space), a tracking epoch's SIVIA tests at most this many
#: boxes instead (or ``TESTS_PER_BOX * max_boxes`` if fewer), and a set cut short is a coarser
#: cover of its prediction, reported ``coarse``. Where no wall is in reach (big_hall, away from
#: its walls) only the few echoes kept constrain the set: it is the prediction less thin shells
#: of poses at an echo's range from some wall, large by nature, and paving those shells buys
#: little. On big_hall with half its echoes lost (60 s, 61 epochs, ``python
#: benchmarks/lost_echo_budget.py``), session 30, the mean set area against the budget: 40 000
#: tests 681 m², 4000 477, 2000 531, 1000 564, 600 660, 500 731, at a tracking CPU mean of 132,
#: 15.5, 9.9, 7.1, 5.2 and 4.6 ms (load 0.7 to 2.6). Session 31, with the global search at
#: :data:`LOST_ECHO_GLOBAL_EPS_M` and scans without constraint predicted box by box
#: (:data:`LOST_ECHO_PREDICTED_BOXES`): 600 tests 489 m², 400 528, 300 594, at a tracking CPU
#: mean / p95 of 5.3 / 9.3, 3.2 / 6.4 and 2.9 / 5.4 ms (load 2.9, another job running): 400,
#: for sets still smaller than session 30's at 600 (closed loop, ``benchmarks/buildings.py``:
#: 507 against 511 m²).
LOST_ECHO_TRACKING_TESTS = 400

#: A global search of a belt that may lose its echoes paves at this precision, m (or at
#: ``eps_m`` when coarser), and hands its set on as a :class:`Refinement` of its report, so
#: that the next epoch paves its prediction under the full budget (``TESTS_PER_BOX``). Its few
#: echoes leave a set large by nature: on big_hall with half its echoes lost the first scan's
#: three echoes leave strips of poses along the walls, 90 m² in more than 10 000 boxes at
#: ``eps_m`` 0.05 (68 000 box tests, 107 to 150 ms CPU), 189 m² in 365 boxes at 0.2 (36 ms)
#: and 487 m² at 0.4 (24 ms), and the next epoch's six echoes bring each to the same 0.13 m²
#: (``benchmarks/lost_echo_budget.py``, the first two epochs).
LOST_ECHO_GLOBAL_EPS_M = 0.2

#: A tracking epoch of a belt that may lose its echoes whose scan has at most ``q_max``
#: readings that constrain (echoes; no-echo readings are ignored) can reject no pose by the
#: sonar: its set is its prediction, predicted box by box (each box of the previous set grown
#: by the limits, coarsened to at most this many boxes, :func:`intervals.imagesp.coarsen`)
#: instead of from the hulls of the previous set's components, which for a strip along two
#: walls is a square of a wall's length (big_hall with half its echoes lost, one echo: 3670 m²
#: from a set of 644). On that run (60 s, open loop, ``benchmarks/lost_echo_budget.py``) the
#: mean set area with 600, 256, 128 and 64 boxes: 452, 489, 574 and 930 m², against 662
#: from the hulls; fewer boxes make the next epochs cheaper.
LOST_ECHO_PREDICTED_BOXES = 256

#: The smallest SIVIA precision ``eps_m``, metres: finer boxes multiply beyond any memory
#: (a millimetre is far below the sonar's error bounds).
MIN_EPS_M = 1e-3


class Tracker(StrEnum):
    """The tracker's prediction of the previous set (module docstring)."""

    SIVIA = "sivia"
    """The hull of the previous outer boxes, inflated by the limits, inverted as one box."""
    IMAGESP = "imagesp"
    """Every previous box mapped, merged on a grid (IMAGESP), then contracted."""


class EpochStatus(StrEnum):
    """How an epoch ended (module docstring)."""

    GLOBAL = "global"
    TRACKING = "tracking"
    INCONSISTENT = "inconsistent"
    LOST = "lost"


@dataclass(frozen=True)
class TrackerSettings:
    """Settings of the interval tracker (validated at construction, bounds beside each field).

    The scenario file's ``[estimation]`` table sets ``eps_m`` .. ``shave_rounds``; the robot's
    limits come from its ``[robot]`` table.
    """

    v_max_m_s: float = bounded(minimum=0.0)
    """The robot's largest forward speed, m/s (the prediction's reach per second)."""
    omega_max_rad_s: float = bounded(minimum=0.0)
    """The robot's largest yaw rate, rad/s."""
    eps_m: float = bounded(0.05, minimum=MIN_EPS_M)
    """SIVIA precision: boxes narrower than this (scaled widths) are not bisected, m."""
    eps_cells: int = bounded(8, minimum=0, maximum=1_000_000, integer=True)
    """A tracking epoch paves at the precision of the previous set's size over this many
    cells when that is coarser than ``eps_m`` (:meth:`IntervalTracker.epoch_eps`), so that a
    set large by nature (big_hall, far from its walls) is held by a bounded number of boxes
    instead of being paved at ``eps_m`` along its whole boundary: still a sound cover, but
    looser (on big_hall's 600 s run 37 % more area; BENCHMARKS.md, "Large sets paved at
    their own scale"). 0: always ``eps_m``."""
    heading_scale_m_per_rad: float = bounded(1.0, above=0.0)
    """Metres per radian when the heading width is compared with position widths."""
    q_max: int = bounded(1, minimum=0, integer=True)
    """Largest number of outlying sonar readings GOMNE may assume per epoch (the scenario
    also requires fewer than the belt's sensors)."""
    tracker: Tracker = Tracker.SIVIA
    """The prediction: :class:`Tracker` (a string of its values is accepted)."""
    imagesp_pitch_m: float = bounded(0.2, above=0.0)
    """Grid pitch of the IMAGESP prediction (scaled like ``eps_m``; at least ``eps_m``: coarser
    keeps the number of cells small before SIVIA refines)."""
    guaranteed: bool = True
    """Keep the ``q_max``-relaxed set, which holds the truth whenever a scan has at most
    ``q_max`` outliers (true), or GOMNE's smaller set at its minimal ``q``, which can miss it
    (false; see :func:`intervals.localize.gomne`). The guaranteed set is much larger where few
    sensors see a wall, and a kidnapping is then detected later."""
    ray_test: bool | None = None
    """Add the ray test of :mod:`intervals.sonar.rays` to the box test (``None``: only for thin cones,
    see :data:`intervals.localize.RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD`)."""
    max_boxes: int = bounded(10_000, minimum=8, maximum=10_000_000, integer=True)
    """The budget of an epoch (:func:`intervals.localize.localize`): its set holds at most this
    many boxes, its SIVIA tests at most ``TESTS_PER_BOX`` times as many, and the IMAGESP
    prediction makes at most ``TESTS_PER_BOX * max_boxes`` cells (else the image of the hull);
    an epoch cut short keeps a coarser sound cover and is reported ``coarse``. The default keeps
    a test call within a few tens of MB and 600 epochs of sets at the cap within about 350 MB
    (57 bytes a stored box), under 1 GiB a run."""
    contractor: bool = True
    """Contract every SIVIA frontier by the sonar echoes before the box test
    (:mod:`intervals.sonar.contractor`): the same poses kept, in fewer and smaller boxes."""
    shave_rounds: int = bounded(0, minimum=0, maximum=8, integer=True)
    """With ``contractor``, rounds of shaving of the boxes kept
    (:func:`intervals.sonar.contractor.shave`): 0 (default) none; on ``hall`` 2 rounds shrink
    the mean set area by another 37 % (0.015 to 0.009 m²) and cost about 4 ms an epoch, which
    would make the default pipeline slower than before the contractor."""
    tighten_levels: int = bounded(0, minimum=0, maximum=MAX_LEVELS, integer=True)
    """Bisections below ``eps_m`` of the boxes kept, each piece tested and (with ``contractor``)
    contracted, before any shaving (:mod:`intervals.tighten`): 0 (default) none; 9 (each axis
    halved about three times) brings the outer volume from 18 to 40 times the consistent poses'
    volume to 2.1 to 2.6 times (median over the tracking epochs of seven built-in plans;
    ``office_floor`` 73 to 3.1, and 2.0 at 12 levels; ``benchmarks/tightness.py``), for an
    epoch 2.3 to 6 times as dear and a set of tens to hundreds of boxes instead of a few (without
    the test budget ``tighten_max_tested``; at its default, 12 levels give at most 2.1 on five
    plans, ``symmetric`` 2.2 to 2.4, and 3.3 to 3.4 on ``corridor`` and 2.9 to 3.0 on
    ``office_floor`` (4.0 and 3.2 to 3.4 before session 29), tracking CPU p95 6.5 to 9.6 ms
    on six plans with the budget shared with SIVIA and 10.1 on ``cluttered_room`` (quiet
    machine; BENCHMARKS.md, "Tightening's budget spent by expected gain", "One epoch budget for
    SIVIA and the pass", "Session 29's main at 12 levels"), 10.2 on ``apartment_lived_in`` by
    the least of 18 tries an epoch (median 8.2 ms; one run's p95 moves by 4 to 5 ms, and the
    10.9 of the earlier run was that noise: "apartment_lived_in at 12 levels")."""
    tighten_max_tested: int = bounded(4_000, minimum=0, maximum=10_000_000, integer=True)
    """With ``tighten_levels``, the epoch's budget of SIVIA and the tightening in pieces: the
    tightening may test that many pieces minus
    :data:`intervals.localize.SIVIA_TEST_PIECES` per box SIVIA tested in the epoch, floored at
    0 (within the budget's tests left), so a multi-room epoch whose SIVIA tested many boxes gets
    a coarser tightening; the boxes whose refinement is expected to remove the most volume are
    refined first, the others kept as they are (sound, only coarser), and the pass ends after a
    call that removed little (:data:`intervals.tighten.MIN_REMOVED_SHARE`), so its cost stays
    bounded on large sets (:mod:`intervals.tighten`).
    4000: the most that kept every built-in plan's tracking CPU p95 at or under about 9 ms at
    12 levels once a piece cost 1.0 to 1.4 us (session 28; 2000 before)."""

    whole_boxes: bool = True
    """Keep whole the boxes the scan cannot split (``whole_boxes`` of
    :func:`intervals.localize.gomne`): those proved inside the epoch's ``q_max``-relaxed set,
    and along the axes where no visible wall changes (:mod:`intervals.sonar.idle`), so that a
    set large by nature (the sensors see no wall or lose their echoes; a strip along one
    wall) costs a few boxes. False: every box of the set bisected to ``eps_m``."""

    def __post_init__(self) -> None:
        validate_fields(self, IntervalError)
        if not isinstance(self.whole_boxes, bool):
            raise IntervalError(
                f"TrackerSettings.whole_boxes must be True or False, got {self.whole_boxes!r}"
            )
        if not isinstance(self.ray_test, bool | None):
            raise IntervalError(
                f"TrackerSettings.ray_test must be True, False or None, got {self.ray_test!r}"
            )
        if self.imagesp_pitch_m < self.eps_m:
            raise IntervalError(
                f"TrackerSettings.imagesp_pitch_m must be >= eps_m ({self.eps_m:g}), "
                f"got {self.imagesp_pitch_m:g}"
            )


@dataclass(frozen=True)
class Refinement:
    """The finer set behind an epoch whose reported set is coarse, for the next epochs.

    ``scan``: the scan it was paved on; ``paving``: its cover of the poses consistent with
    that scan, with up to :data:`KEPT_PER_BOX` ``* max_boxes`` boxes (what SIVIA refined
    within its budget, before the merge that brings the reported set down to ``max_boxes``);
    ``age_s``: seconds from that scan to the epoch that returned it. While ``paving`` is
    coarse, each next epoch first continues its paving on its own ``scan`` under a budget of
    its own (the same instant: no motion to add, so every budget spent refines it; SIVIA's
    depth-first order leaves the boxes it did not reach as they were), then predicts from it
    over ``age_s`` plus the epoch's ``dt_s`` (its wide boxes apart, :meth:`IntervalTracker.
    groups`) and paves that; such an epoch costs at most twice the budget. An epoch whose own
    set is fine drops it, and so does one whose set the budget had to merge into
    ``KEPT_PER_BOX * max_boxes`` boxes (a set that large by nature, not for want of budget:
    refining it would only double the cost). A fine global set of a belt that may lose its
    echoes is handed on too, as its report (:data:`LOST_ECHO_GLOBAL_EPS_M`), so that the
    next epoch paves under the full budget; it is the only refinement of such a belt, whose
    tracking epochs hand none on, and whose epochs on a scan that rejects no pose
    (:meth:`IntervalTracker.rejects_nothing`) predict cheaply even when given one. Held by the
    caller between epochs (:meth:`IntervalTracker.step`), never logged."""

    scan: SonarScan
    paving: Subpaving
    age_s: float = 0.0


@dataclass(frozen=True)
class EpochResult:
    """Outcome of one tracker epoch.

    ``paving``: the pose set, None when the epoch is ``"inconsistent"`` or ``"lost"`` (headings
    wrapped to ``[-pi, pi]``); ``q``: GOMNE's minimal number of outliers explaining the scan
    (None without a set; the set itself is relaxed by ``q_max`` when the settings are
    ``guaranteed``); ``status``: an :class:`EpochStatus`; ``elapsed_s``: wall time of the
    epoch (timing, not a result); ``coarse``: a budget cut the epoch's paving short or
    merged its boxes (``max_boxes``, or a lost-echo belt's
    :data:`LOST_ECHO_TRACKING_TESTS`): the set is a coarser sound cover; ``refinement``: for a
    coarse epoch, the finer set the next epoch continues from (:class:`Refinement`; pass it
    to the next :meth:`IntervalTracker.step`, and drop it from results kept afterwards).
    """

    paving: Subpaving | None
    q: int | None
    status: EpochStatus
    elapsed_s: float = 0.0
    coarse: bool = False
    refinement: Refinement | None = None

    @property
    def consistent(self) -> bool:
        """False when no set with at most ``q_max`` outliers explains the scan."""
        return self.paving is not None

    @property
    def outer(self) -> np.ndarray:
        """Outer boxes ``(K, 3, 2)`` (K = 0 without a set)."""
        return self.paving.outer if self.paving is not None else np.zeros((0, 3, 2))

    @property
    def inner_mask(self) -> np.ndarray:
        """``(K,)`` bool: the outer box is proved inside the set (``paving.inner`` first)."""
        inner = 0 if self.paving is None else self.paving.inner.shape[0]
        return np.arange(self.outer.shape[0]) < inner

    def components(self) -> tuple[int, np.ndarray]:
        """Connected components of the outer boxes, heading periodic: ``(count, labels (K,))``."""
        if self.paving is None:
            return 0, np.zeros(0, dtype=np.int64)
        return self.paving.components()

    def hull(self) -> np.ndarray:
        """Hull ``(3, 2)`` of the outer boxes, headings unwrapped near the first box (a set
        across the +-pi cut keeps a narrow heading interval, possibly beyond ``pi``); NaN
        without a set."""
        boxes = self.outer
        if boxes.shape[0] == 0:
            return np.full((3, 2), np.nan)
        return hull(_unwrapped(boxes))


def global_box(map_bounds) -> np.ndarray:
    """Pose box ``(3, 2)``: the map bounds ``(2, 2)`` and every heading ``[-pi, pi]``."""
    b = np.asarray(map_bounds, dtype=np.float64)
    if b.shape != (2, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise IntervalError(f"map bounds must be a finite (2, 2) box, got {b.tolist()}")
    return np.array([b[0], b[1], [-np.pi, np.pi]])


@dataclass(frozen=True)
class IntervalTracker:
    """The tracker's fixed parts; :meth:`step` is pure (previous set in, result out).

    ``settings``; ``map_bounds (2, 2)`` for the global search; ``motion``: the IMAGESP
    inclusion function ``(boxes (N, 3, 2), dt_s) -> (N, 3, 2)`` (None: inflation by the
    physical limits, the paper's prediction).
    """

    settings: TrackerSettings
    map_bounds: np.ndarray
    motion: Callable[[np.ndarray, float], np.ndarray] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "map_bounds", global_box(self.map_bounds)[:2])

    def limits(self, boxes: np.ndarray, dt_s: float) -> np.ndarray:
        """Boxes grown by the physical limits: ``v_max dt`` in x and y, ``omega_max dt`` in
        heading (every pose reachable in ``dt_s`` from a pose of the box), then cut to the map
        bounds in x and y (:meth:`in_bounds`)."""
        return self.in_bounds(self._grown(boxes, dt_s))

    def _grown(self, boxes: np.ndarray, dt_s: float) -> np.ndarray:
        """:meth:`limits` before the cut to the bounds: one grown box ``(N, 3, 2)`` a box (the
        IMAGESP inclusion function's shape; its cells are cut afterwards)."""
        s = self.settings
        reach = s.v_max_m_s * dt_s
        return inflate(boxes, [reach, reach, s.omega_max_rad_s * dt_s])

    def in_bounds(self, boxes: np.ndarray) -> np.ndarray:
        """``boxes (N, 3, 2)`` cut to the map bounds in x and y, those left empty dropped: the
        robot is inside the outer wall, so every pose a set must hold lies in the bounds (the
        global search's premise). Without it a set the sonar cannot constrain grows by the
        limits every epoch past the walls: big_hall with half its echoes lost, 600 s, a set of
        25 000 m² in a 3600 m² hall."""
        lo = np.maximum(boxes[:, :2, 0], self.map_bounds[:, 0])
        hi = np.minimum(boxes[:, :2, 1], self.map_bounds[:, 1])
        cut = boxes.copy()
        cut[:, :2, 0], cut[:, :2, 1] = lo, hi
        return cut[(lo <= hi).all(axis=1)]

    def groups(self, boxes: np.ndarray, apart: bool = False) -> np.ndarray:
        """Boxes ``(M, 3, 2)`` whose union holds ``boxes (N, 3, 2)`` (headings unwrapped near
        the first box), for the prediction: their hull when it is at most
        :data:`SPREAD_FACTOR` times their volume (and, with ``apart``, every box is no wider
        than ``eps_m``); else the hull of each connected component (:func:`component_hulls`)
        of the boxes, those wider than ``eps_m`` each alone with ``apart`` (the boxes a
        budget left whole, in a :class:`Refinement`: their finer neighbours stay apart)."""
        s = self.settings
        whole = hull(boxes)
        wide = np.zeros(boxes.shape[0], dtype=bool)
        if apart:
            wide = max_width(boxes, pose_scale(s.heading_scale_m_per_rad)) > s.eps_m
        spread = volume(whole[None]) > SPREAD_FACTOR * volume(boxes)
        if not (spread or wide.any()):  # the sum counts overlaps again: checked on a grid
            spread = volume(whole[None]) > SPREAD_FACTOR * covered_volume(boxes)
        if not (spread or wide.any()):
            return whole[None]
        fine = boxes[~wide]
        hulls = component_hulls(fine) if fine.shape[0] else fine
        return np.concatenate([hulls, boxes[wide]])

    def predict(
        self, previous: Subpaving, dt_s: float, apart: bool = False, each_box: bool = False
    ) -> np.ndarray:
        """Boxes ``(N, 3, 2)`` holding every pose reachable from ``previous`` in ``dt_s``
        (``apart``: see :meth:`groups`). ``each_box`` (``sivia`` prediction): each box of
        ``previous`` grown by the limits alone, coarsened to at most
        :data:`LOST_ECHO_PREDICTED_BOXES` boxes (their union holds every grown box)."""
        if not (np.isfinite(dt_s) and dt_s >= 0):
            raise IntervalError(f"tracker: dt_s must be finite and >= 0, got {dt_s!r}")
        boxes = previous.outer
        boxes = _unwrapped(boxes)
        s = self.settings
        scale = pose_scale(s.heading_scale_m_per_rad)
        if s.tracker == Tracker.SIVIA and each_box:
            grown = wrap_headings(self.limits(boxes, dt_s))
            return self.in_bounds(coarsen(grown, LOST_ECHO_PREDICTED_BOXES, scale))
        if s.tracker == Tracker.SIVIA:
            return wrap_headings(self.limits(self.groups(boxes, apart), dt_s))
        motion = self.motion if self.motion is not None else self._grown
        try:
            cells = imagesp(
                lambda b: motion(b, dt_s),
                boxes,
                s.eps_m,
                scale,
                pitch=s.imagesp_pitch_m / scale,
                max_cells=TESTS_PER_BOX * s.max_boxes,
            )
        except IntervalError:  # more cells than the budget: the image of the groups' hulls
            cells = motion(self.groups(boxes, apart), dt_s)
        return wrap_headings(self.in_bounds(cells))

    def epoch_eps(self, previous: Subpaving) -> float:
        """The precision of a tracking epoch from ``previous`` (and of its paving again when
        the scan shrank the set to half that size or less, :meth:`step`), m: ``eps_m``, or
        the set's size over ``eps_cells`` when that is larger (``eps_cells`` 0: ``eps_m``).
        The size is the smallest of the widths ``w_x, w_y`` of the set's hull, the square root
        of its (x, y) area ``A`` and its thickness ``2 A / (w_x + w_y)``, ``A`` taken as the
        set's volume over its hull's heading width (at most the projected area). A square
        blob of side ``D`` gives ``D``; a strip its width; an L of two strips along two walls
        about twice their width; several small places far apart, or scattered pieces over
        a wide hull, a small fraction of the hull: only a set wide in every direction is
        paved coarser than ``eps_m``."""
        s = self.settings
        if s.eps_cells == 0:
            return s.eps_m
        boxes = previous.outer
        whole = hull(_unwrapped(boxes))
        width = whole[:, 1] - whole[:, 0]
        span_m = float(width[0] + width[1])
        if not (width[2] > 0 and span_m > 0):
            return s.eps_m
        area_m2 = float(volume(boxes) / width[2])
        size_m = min(float(width[0]), float(width[1]), np.sqrt(area_m2), 2 * area_m2 / span_m)
        return max(s.eps_m, size_m / s.eps_cells)

    def rejects_nothing(self, scan: SonarScan) -> bool:
        """Whether the sonar can reject no pose on ``scan``: at most ``q_max`` of its readings
        constrain (echoes, and no-echo readings when echoes are never lost), so every pose is
        explained with at most ``q_max`` readings unexplained (only the in-room test remains)."""
        return int(np.count_nonzero(scan.kind != IGNORED)) <= self.settings.q_max

    def _hull_prediction(self, previous: Subpaving, dt_s: float) -> np.ndarray:
        """The hull of ``previous`` (headings unwrapped near its first box) grown by the
        limits over ``dt_s``, headings wrapped."""
        boxes = previous.outer
        boxes = _unwrapped(boxes)
        return wrap_headings(self.limits(hull(boxes)[None], dt_s))

    def _search(
        self,
        scan: SonarScan,
        initial: np.ndarray,
        splits_per_level: int = 3,
        within=None,
        tests_per_box: float = TESTS_PER_BOX,
        eps_m: float | None = None,
    ):
        """GOMNE on ``initial`` under the budget (``tests_per_box`` tests a box of it), keeping
        up to :data:`KEPT_PER_BOX` ``* max_boxes`` boxes (for a :class:`Refinement`)."""
        s = self.settings
        return gomne(
            scan,
            initial,
            s.eps_m if eps_m is None else eps_m,
            s.q_max,
            s.heading_scale_m_per_rad,
            guaranteed=s.guaranteed,
            ray_test=s.ray_test,
            max_boxes=s.max_boxes,
            contract=s.contractor,
            shave_rounds=s.shave_rounds,
            tighten_levels=s.tighten_levels,
            tighten_max_tested=s.tighten_max_tested,
            max_kept=KEPT_PER_BOX * s.max_boxes,
            splits_per_level=splits_per_level,
            within=within,
            whole_boxes=s.whole_boxes,
            tests_per_box=tests_per_box,
        )

    def step(
        self,
        previous: Subpaving | None,
        scan: SonarScan,
        dt_s: float,
        refinement: Refinement | None = None,
    ) -> EpochResult:
        """One epoch from the previous set (None: the start, or the epoch after one without a
        set: search globally), on the scan taken ``dt_s`` seconds after the previous one.
        ``refinement``: the previous result's (:class:`Refinement`; None when it had none):
        the epoch then refines that set on its own scan and predicts from it instead of from
        ``previous`` (its coarse, merged report)."""
        start = time.perf_counter()
        s = self.settings
        lossy = not scan.belt.echoes_never_lost
        pending, apart = None, refinement is not None
        if refinement is not None and not refinement.paving.coarse:
            previous, dt_s = refinement.paving, refinement.age_s + dt_s
        elif refinement is not None:  # refined on its own scan first (a budget of its own)
            older = self._search(refinement.scan, refinement.paving.outer)
            if older.consistent:  # else (a sound cover of a consistent set): search globally
                previous, dt_s = older.paving, refinement.age_s + dt_s
                if older.paving.coarse and not older.merged:  # merged: too large to refine
                    pending = Refinement(refinement.scan, older.paving, dt_s)
            else:
                previous = None
        if previous is None or previous.is_empty:
            eps_m = max(s.eps_m, LOST_ECHO_GLOBAL_EPS_M) if lossy else s.eps_m
            found = self._search(
                scan, global_box(self.map_bounds), GLOBAL_SPLITS_PER_LEVEL, eps_m=eps_m
            )
            status = EpochStatus.GLOBAL if found.consistent else EpochStatus.LOST
        else:
            # a refinement's chain keeps the full budget (it refines a set cut short for want
            # of budget, e.g. a global search); other tracking epochs the smaller one
            # (a lossy belt's scan that can reject no pose: the prediction itself, cheaply, even
            # in a refinement's chain: no budget can split what the sonar does not constrain)
            blind = lossy and s.tracker == Tracker.SIVIA and self.rejects_nothing(scan)
            cheap = s.whole_boxes and (refinement is None or blind)
            within = None
            if cheap and blind:
                predicted, joined = self.predict(previous, dt_s, each_box=True), False
            else:
                predicted = self.predict(previous, dt_s, apart)
                joined = not apart or s.whole_boxes  # overlapping boxes kept whole would overlap
            if predicted.shape[0] == 0:  # no pose reachable within the map: the motion failed
                return EpochResult(
                    None, None, EpochStatus.INCONSISTENT, time.perf_counter() - start
                )
            predicted = as_boxes(predicted)
            if s.tracker == Tracker.SIVIA and joined and predicted.shape[0] > 1:
                # paved from the whole hull, as for one component (the same bisections, so
                # never a looser set), every box outside the components' predictions rejected
                # (with more regions than a test call compares, a coarser cover of them)
                within = predicted
                if within.shape[0] > MAX_WITHIN_REGIONS:
                    scale = pose_scale(s.heading_scale_m_per_rad)
                    within = coarsen(within, MAX_WITHIN_REGIONS, scale)
                predicted = self._hull_prediction(previous, dt_s)
            tests = float(TESTS_PER_BOX)
            if cheap and lossy:
                tests = min(tests, LOST_ECHO_TRACKING_TESTS / s.max_boxes)
            elif cheap:
                floor = min(float(TESTS_PER_BOX), TRACKING_MIN_TESTS / s.max_boxes)
                tests = max(float(TRACKING_TESTS_PER_BOX), floor)
            eps_m = self.epoch_eps(previous)
            found = self._search(scan, predicted, within=within, tests_per_box=tests, eps_m=eps_m)
            # a scan that shrank the set (walls back in reach) has it paved again at the
            # precision of its new size, from its own cover: one epoch is not left coarse
            while found.consistent and eps_m > s.eps_m:
                finer_m = self.epoch_eps(found.paving)
                if finer_m > 0.5 * eps_m:
                    break
                eps_m = finer_m
                found = self._search(scan, found.paving.outer, tests_per_box=tests, eps_m=eps_m)
            status = EpochStatus.TRACKING if found.consistent else EpochStatus.INCONSISTENT
        if not found.consistent:
            return EpochResult(None, None, status, time.perf_counter() - start)
        coarse = found.paving.coarse
        inner, boundary = wrap_headings(found.paving.inner), wrap_headings(found.paving.boundary)
        if not coarse and inner.shape[0] + boundary.shape[0] <= s.max_boxes:
            pending = None  # a fine set, reported whole: an older refinement is done with
        elif found.merged:
            pending = None  # a set the budget had to merge is too large to refine: none
        elif (
            s.whole_boxes
            and status == EpochStatus.TRACKING
            and (lossy or (coarse and refinement is None))
        ):
            # a tracking set the budget cut short is large by nature (its prediction holds it,
            # as the parts the scan cannot split are kept whole): refining it on its scan next
            # epoch would double that epoch's cost for a set the next scan paves anyway. A
            # lossy belt's tracking sets are never handed on, fine or cut short: on big_hall
            # with half its echoes lost (seeds 1, 2) chains of them, fine sets of 10 000 to
            # 30 000 boxes growing under two or three echoes, then cut short, cost 50 to 960 ms
            # an epoch for 8 epochs (BENCHMARKS.md, "Lost echoes: the slow epochs were a
            # refinement's chain")
            pending = None
        elif pending is None or not coarse:
            # kept for the next epoch: this set, finer than the report merged to max_boxes
            # (while an older refinement is still coarse, that one goes on instead)
            pending = Refinement(scan, Subpaving(inner, boundary, coarse))
        # the report: adjacent boxes joined (the same union, fewer boxes), then, if still too
        # many, merged into a coarser cover
        inner, boundary = merge_adjacent(inner), merge_adjacent(boundary)
        if inner.shape[0] + boundary.shape[0] > s.max_boxes:
            scale = pose_scale(s.heading_scale_m_per_rad)
            merged = coarsen(np.concatenate([inner, boundary]), s.max_boxes // 2, scale)
            merged = self.in_bounds(wrap_headings(merged))
            # the merged cells tested once: those the sonar or the room reject hold no pose
            # of the set (box_test, at the set's relaxation), the rest is the report
            held = box_test(merged, scan.restricted_to(merged), found.q_set, False)
            if (held != OUTSIDE).any():
                merged = merged[held != OUTSIDE]
            inner, boundary, coarse = np.zeros((0, 3, 2)), merged, True
        paving = Subpaving(inner, boundary, coarse)
        if lossy and status == EpochStatus.GLOBAL and not coarse:
            # the report, the same union as the finer set in fewer boxes (a refinement of
            # those would cost the next epoch's prediction more for the same poses)
            pending = Refinement(scan, paving)
        elapsed_s = time.perf_counter() - start
        return EpochResult(paving, found.q, status, elapsed_s, coarse, pending)

"""The interval epochs of one run: the tracker stepped on the sonar scans, recorded as arrays.

``intervals.tracker`` does the work (global localisation, tracking by SIVIA or IMAGESP,
GOMNE, inconsistency, relocalisation at the next epoch); this module feeds it the scans of a
run and keeps what each epoch gave. An epoch's state is an index of :data:`STATUS`
(``global``, ``tracking``, ``inconsistent``, ``lost``); the fusion clamps only at the first
two (:data:`CLAMPED`), the only ones with a set. Box arrays of all epochs are concatenated
(``boxes (B, 3, 2)``) with ``box_counts (E,)`` giving each epoch's share.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from intervals.boxes import Subpaving, area_xy, contains_points
from intervals.sonar.scan import SonarBelt, SonarScene
from intervals.tracker import (
    EpochResult,
    EpochStatus,
    IntervalTracker,
    Refinement,
    TrackerSettings,
)

#: The epoch states in the order of their codes in :attr:`EpochLog.status`.
STATUS = tuple(EpochStatus)
GLOBAL, TRACKING, INCONSISTENT, LOST = (
    STATUS.index(status)
    for status in (
        EpochStatus.GLOBAL,
        EpochStatus.TRACKING,
        EpochStatus.INCONSISTENT,
        EpochStatus.LOST,
    )
)

#: Epoch states with a set, the ones the fusion clamps to.
CLAMPED = (GLOBAL, TRACKING)


class EpochRunner:
    """The tracker of one run, stepped scan by scan (holds the previous set between calls).

    ``tracker_settings``; ``segments (m, 2, 2)`` and ``boundary (p, 2) | None`` of the map;
    ``map_bounds (2, 2)``; ``belt``: the sonar belt seen by the interval tests.
    """

    def __init__(
        self, tracker_settings: TrackerSettings, segments, boundary, map_bounds, belt: SonarBelt
    ):
        self._tracker = IntervalTracker(tracker_settings, map_bounds)
        self._scene = SonarScene(segments, belt, boundary)  # the map checked once per run
        self._previous: Subpaving | None = None
        self._refinement: Refinement | None = None  # a coarse set's finer one, never logged

    def step(self, readings_m: np.ndarray, dt_s: float) -> EpochResult:
        """One epoch on the scan ``readings_m (k,)`` taken ``dt_s`` after the previous one."""
        scan = self._scene.scan(readings_m)
        result = self._tracker.step(self._previous, scan, dt_s, self._refinement)
        self._previous, self._refinement = result.paving, result.refinement
        return dataclasses.replace(result, refinement=None)


@dataclasses.dataclass(frozen=True, eq=False)
class EpochLog:
    """Every epoch of a run as arrays (E epochs, B boxes in all).

    ``t_s (E,)`` scan times; ``status (E,)`` int8 (:data:`STATUS`); ``q_used (E,)`` GOMNE's
    minimal number of outliers (-1: no set); ``box_counts (E,)``; ``boxes (B, 3, 2)``,
    ``inner (B,)``, ``labels (B,)`` (connected component within its epoch); ``hull (E, 3, 2)``
    the hull of the outer set (NaN without a set; heading within one turn of the first box);
    ``components (E,)``; ``area_m2 (E,)`` (x, y) area of the union of the outer boxes (NaN
    without a set); ``contains_truth (E,)`` bool: some outer box holds the true pose (False
    without a set); ``elapsed_s (E,)`` wall time per epoch (timing); ``coarse (E,)`` bool: a
    budget of the tracker (``max_boxes``, or with lost echoes a tracking epoch's
    :data:`intervals.tracker.LOST_ECHO_TRACKING_TESTS`) made the epoch's set a coarser cover.
    """

    t_s: np.ndarray
    status: np.ndarray
    q_used: np.ndarray
    box_counts: np.ndarray
    boxes: np.ndarray
    inner: np.ndarray
    labels: np.ndarray
    hull: np.ndarray
    components: np.ndarray
    area_m2: np.ndarray
    contains_truth: np.ndarray
    elapsed_s: np.ndarray
    coarse: np.ndarray

    @classmethod
    def collect(
        cls,
        t_s: np.ndarray,
        results: list[EpochResult],
        truth: np.ndarray,
        known_components: list[tuple[int, np.ndarray] | None] | None = None,
    ) -> EpochLog:
        """The log of the tracker's ``results`` (one per scan time ``t_s (E,)``), checked
        against the true poses ``truth (E, 3)`` at the scans (for the containment figure).
        ``known_components``: each result's ``components()`` where already computed (the
        fusion's), None where not."""
        count = len(results)
        known = known_components if known_components is not None else [None] * count
        components = [
            r.components() if done is None else done for r, done in zip(results, known, strict=True)
        ]
        outer = [r.outer for r in results]
        contains = np.array(
            [
                bool(len(b)) and bool(contains_points(b, p[None]).any())
                for b, p in zip(outer, truth, strict=True)
            ]
        )
        return cls(
            t_s=np.asarray(t_s, dtype=np.float64),
            status=np.array([STATUS.index(r.status) for r in results], dtype=np.int8),
            q_used=np.array([-1 if r.q is None else r.q for r in results], dtype=np.int64),
            box_counts=np.array([len(b) for b in outer], dtype=np.int64),
            boxes=np.concatenate(outer) if count else np.zeros((0, 3, 2)),
            inner=np.concatenate([r.inner_mask for r in results]) if count else np.zeros(0, bool),
            labels=np.concatenate([labels for _, labels in components])
            if count
            else np.zeros(0, np.int64),
            hull=np.array([r.hull() for r in results]).reshape(count, 3, 2),
            components=np.array([n for n, _ in components], dtype=np.int64),
            area_m2=np.array([area_xy(b) if len(b) else np.nan for b in outer]),
            contains_truth=contains.astype(bool).reshape(count),
            elapsed_s=np.array([r.elapsed_s for r in results]),
            coarse=np.array([r.coarse for r in results], dtype=bool).reshape(count),
        )

    def epoch_boxes(self, e: int) -> np.ndarray:
        """Outer boxes ``(K, 3, 2)`` of epoch ``e``."""
        ends = np.cumsum(self.box_counts)
        return self.boxes[ends[e] - self.box_counts[e] : ends[e]]

    @property
    def has_set(self) -> np.ndarray:
        """``(E,)`` bool: the epoch produced a set (``global`` or ``tracking``)."""
        return np.isin(self.status, CLAMPED)

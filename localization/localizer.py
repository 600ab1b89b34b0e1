"""The online localiser of paper 002: sensor samples in as they come, the estimate out at any time.

:class:`OnlineLocalizer` holds the whole estimator of one robot: the 100 Hz dead reckoning of
two branches batched as one belief ``(2, 8)`` (row :data:`UKF_ONLY`, row :data:`FUSED`;
:mod:`localization.dead_reckoning`), the interval tracker stepped at the sonar scans
(:mod:`intervals.tracker`), and the fusion of the fused branch with the set when an epoch
is consistent (:mod:`localization.fusion`). It sees what a robot sees: the nominal robot,
the sonar belt, the map, and the samples pushed to it::

    loc = OnlineLocalizer(robot, belt, segments, boundary, map_bounds, settings, start_pose)
    loc.push_odometry(t, ticks, gyro, accel)     # every sample, in order
    loc.push_scan(t, readings)                   # at a scan: an interval epoch, the fusion
    loc.estimate()                               # mean and covariance of both branches

Samples are buffered and the compiled dead-reckoning step runs them in one call when a scan
or an estimate needs them, so pushing a sample costs a few microseconds and the stretch
between two scans stays one kernel call. Fed a run's samples in order (each scan after the
odometry sample it was taken at), the localiser computes exactly what the batch pipeline
computes on the whole arrays, bit for bit (``tests/localization/test_localizer.py``).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from intervals.boxes import Subpaving
from intervals.sonar.scan import SonarBelt, SonarScene
from intervals.tracker import (
    EpochResult,
    EpochStatus,
    IntervalTracker,
    Refinement,
    TrackerSettings,
)
from localization.compiled.samples import (
    APPENDED,
    GYRO_NOT_FINITE,
    OFF_GRID,
    append_samples,
)
from localization.dead_reckoning import (
    DeadReckoning,
    DeadReckoningHistory,
    DeadReckoningNoise,
    DeadReckoningSettings,
    NominalRobot,
    initial_belief,
    odometry_data,
    odometry_inputs,
)
from localization.errors import EstimationError
from localization.fusion import FusionRule, fuse
from localization.gaussian import Gaussian
from validated_records import bounded, validate_fields

#: The two dead-reckoning branches, in batch order.
BRANCHES = ("ukf_only", "fused")
UKF_ONLY, FUSED = 0, 1

#: Standard deviations of the starting pose (m, m, rad): where a person places the robot.
START_POSE_STD = (0.02, 0.02, math.radians(1.0))


@dataclasses.dataclass(frozen=True)
class LocalizerSettings:
    """How the localiser runs (validated at construction).

    ``tracker``: the interval tracker (with the robot's limits); ``dead_reckoning``: the filter;
    ``fusion``: the rule; ``noise``: the filter's noise model; ``rate_hz``: the odometry sample
    rate; ``scan_stride``: an interval epoch every ``scan_stride`` scans (1: every scan);
    ``start_pose_std``: standard deviations of the start pose (m, m, rad).
    """

    tracker: TrackerSettings
    dead_reckoning: DeadReckoningSettings = dataclasses.field(default_factory=DeadReckoningSettings)
    fusion: FusionRule = FusionRule.CLAMP
    noise: DeadReckoningNoise = dataclasses.field(default_factory=DeadReckoningNoise)
    rate_hz: float = bounded(100.0, above=0.0)
    scan_stride: int = bounded(1, minimum=1, integer=True)
    start_pose_std: tuple[float, float, float] = START_POSE_STD

    def __post_init__(self) -> None:
        validate_fields(self, EstimationError)
        for name, kind in (
            ("tracker", TrackerSettings),
            ("dead_reckoning", DeadReckoningSettings),
            ("noise", DeadReckoningNoise),
        ):
            if not isinstance(getattr(self, name), kind):
                raise EstimationError(f"LocalizerSettings.{name} must be a {kind.__name__}")
        object.__setattr__(self, "fusion", FusionRule(self.fusion))

    @property
    def dt_s(self) -> float:
        """The odometry sample period, seconds."""
        return 1.0 / self.rate_hz


@dataclasses.dataclass(frozen=True)
class PoseEstimate:
    """The estimate at sample ``sample`` (time ``t_s``): ``pose (2, 3)`` and ``pose_cov
    (2, 3, 3)`` of both branches (row order :data:`BRANCHES`; heading wrapped)."""

    t_s: float
    sample: int
    pose: np.ndarray
    pose_cov: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class EpochRecord:
    """One interval epoch: the scan time ``t_s`` and its odometry ``sample``; the tracker's
    ``result``; the fused branch's pose ``before (3,)`` and ``after (3,)`` the fusion;
    ``fused_box (3, 2)``, the hull the fusion used (NaN without fusion), and ``component``, its
    label (-1: no fusion); ``components``: ``result.components()`` as the fusion took them
    (None where the epoch was not fused: not computed)."""

    t_s: float
    sample: int
    result: EpochResult
    before: np.ndarray
    after: np.ndarray
    fused_box: np.ndarray
    component: int
    components: tuple[int, np.ndarray] | None = None


class _Samples:
    """Raw odometry samples, appended one by one or in blocks (arrays grown by doubling)."""

    def __init__(self) -> None:
        self.count = 0
        self.t_s = np.empty(64)
        self.ticks = np.empty((64, 2), dtype=np.int64)
        self.gyro = np.empty(64)
        self.accel = np.empty((64, 2))

    def reserve(self, count: int) -> None:
        if count > self.t_s.shape[0]:
            capacity = max(count, 2 * self.t_s.shape[0])
            for name in ("t_s", "ticks", "gyro", "accel"):
                old = getattr(self, name)
                new = np.empty((capacity,) + old.shape[1:], dtype=old.dtype)
                new[: self.count] = old[: self.count]
                setattr(self, name, new)


class OnlineLocalizer:
    """The estimator of one robot, fed samples as they come (module docstring).

    Args:
        robot: the nominal robot; belt: the sonar belt as the interval tests see it.
        segments: ``(m, 2, 2)`` the map's walls, m; boundary: ``(p, 2)`` its outer wall or None;
        map_bounds: ``(2, 2)`` the box of the global search.
        settings: :class:`LocalizerSettings`; start_pose: ``(x_m, y_m, theta_rad)`` at the
            first odometry sample.

    Attributes (timing, wall seconds; not results): ``dead_reckoning_s``, ``fusion_s`` and
    ``step_us``, the wall time per dead-reckoning step of each stretch run, microseconds.
    """

    def __init__(
        self,
        robot: NominalRobot,
        belt: SonarBelt,
        segments,
        boundary,
        map_bounds,
        settings: LocalizerSettings,
        start_pose,
    ) -> None:
        self.robot, self.belt, self.settings = robot, belt, settings
        self._scene = SonarScene(  # the map checked and indexed once per run
            np.asarray(segments, dtype=np.float64),
            belt,
            None if boundary is None else np.asarray(boundary, dtype=np.float64),
        )
        self._tracker = IntervalTracker(settings.tracker, map_bounds)
        self._initial = initial_belief(start_pose, settings.start_pose_std, settings.noise)
        self._samples = _Samples()
        self._dr: DeadReckoning | None = None  # built at the first stretch run
        self._previous: Subpaving | None = None
        self._refinement: Refinement | None = None  # a coarse set's finer one, never kept
        self._scans = 0
        self._last_epoch_t: float | None = None
        self.epochs: list[EpochRecord] = []
        self.dead_reckoning_s = 0.0
        self.fusion_s = 0.0
        self.step_us: list[float] = []

    # ------------------------------------------------------------------ samples in
    def push_odometry(self, t_s: float, ticks, gyro_rad_s: float, accel_m_s2) -> None:
        """One odometry sample at ``t_s``: tick increments ``(2,)`` (left, right) since the
        previous sample (the first sample's are unused), the gyro's yaw rate and the
        accelerometer's specific force ``(2,)`` (body x, y)."""
        self.push_odometry_block(
            np.array([t_s], dtype=np.float64),
            np.asarray(ticks).reshape(1, 2),
            np.array([gyro_rad_s], dtype=np.float64),
            np.asarray(accel_m_s2, dtype=np.float64).reshape(1, 2),
        )

    def push_odometry_block(self, t_s, ticks, gyro_rad_s, accel_m_s2) -> None:
        """Consecutive odometry samples at once: ``t_s (n,)``, ``ticks (n, 2)``, ``gyro_rad_s
        (n,)``, ``accel_m_s2 (n, 2)`` (as :meth:`push_odometry`).

        Raises:
            EstimationError: shapes that disagree, non-integer ticks, times off the regular
                grid ``t_0 + k / rate_hz`` (by more than half a period, or NaN), a non-finite
                gyro or accelerometer reading; the message names the first such sample, and
                none of the block is appended.
        """
        t_s = np.asarray(t_s, dtype=np.float64).reshape(-1)
        ticks, gyro = np.asarray(ticks), np.asarray(gyro_rad_s, dtype=np.float64)
        accel = np.asarray(accel_m_s2, dtype=np.float64)
        n = t_s.shape[0]
        if ticks.shape != (n, 2) or gyro.shape != (n,) or accel.shape != (n, 2):
            raise EstimationError(
                f"push_odometry: t_s (n,), ticks (n, 2), gyro (n,), accel (n, 2) expected, got "
                f"{t_s.shape}, {ticks.shape}, {gyro.shape}, {accel.shape}"
            )
        if n and ticks.dtype.kind not in "iu":  # np.integer, without the type lookup
            raise EstimationError(f"push_odometry: ticks must be integers, got {ticks.dtype}")
        ticks = ticks.astype(np.int64, copy=False)  # the buffer's type: one compiled signature
        samples = self._samples
        first = samples.t_s[0] if samples.count else t_s[0] if n else 0.0
        samples.reserve(samples.count + n)
        found, k = append_samples(
            t_s,
            ticks,
            gyro,
            accel,
            samples.count,
            first,
            self.settings.dt_s,
            samples.t_s,
            samples.ticks,
            samples.gyro,
            samples.accel,
        )
        if found != APPENDED:  # the count stays: nothing of the block is appended
            index = samples.count + k
            if found == OFF_GRID:
                expected = first + index * self.settings.dt_s
                raise EstimationError(
                    f"push_odometry: sample {index} at t = {t_s[k]!r} s is off the "
                    f"{self.settings.rate_hz:g} Hz grid (expected {expected!r} s)"
                )
            field, value = ("gyro", gyro[k]) if found == GYRO_NOT_FINITE else ("accel", accel[k])
            raise EstimationError(
                f"push_odometry: sample {index} at t = {t_s[k]!r} s has a non-finite {field} "
                f"reading {value}"
            )
        samples.count += n

    def push_scan(self, t_s: float, readings_m) -> EpochRecord | None:
        """A sonar scan ``readings_m (k,)`` (inf: no echo) taken at ``t_s``, after the odometry
        sample it was taken at (the latest pushed, within half a period). Every
        ``scan_stride``-th scan (from the first) is an interval epoch, fused when consistent;
        returns its record, or None for a scan between epochs.

        Raises:
            EstimationError: a scan not at the latest odometry sample, readings of the wrong
                shape.
            IntervalError: an impossible tracker setting met at run time (a box explosion).
        """
        samples = self._samples
        t_s = float(t_s)
        readings = np.asarray(readings_m, dtype=np.float64)
        if readings.shape != (self.belt.count,):
            raise EstimationError(
                f"push_scan: readings must have shape ({self.belt.count},), got {readings.shape}"
            )
        half = 0.5 * self.settings.dt_s
        if not samples.count or not (
            samples.t_s[samples.count - 1] >= t_s - half
            and (samples.count == 1 or samples.t_s[samples.count - 2] < t_s - half)
        ):
            latest = samples.t_s[samples.count - 1] if samples.count else None
            raise EstimationError(
                f"push_scan: the scan at t = {t_s!r} s must follow the odometry sample it was "
                f"taken at (latest sample: t = {latest!r} s)"
            )
        scan_number = self._scans
        self._scans += 1
        if scan_number % self.settings.scan_stride:
            return None
        belief = self._advance()
        dt_s = 0.0 if self._last_epoch_t is None else t_s - self._last_epoch_t
        self._last_epoch_t = t_s
        scan = self._scene.scan(readings)
        found = self._tracker.step(self._previous, scan, dt_s, self._refinement)
        self._previous, self._refinement = found.paving, found.refinement
        found = dataclasses.replace(found, refinement=None)
        tick = time.perf_counter()
        before = np.array(belief.mean[FUSED, :3])
        box, component, components = np.full((3, 2), np.nan), -1, None
        if found.consistent:
            outer, components = found.outer, found.components()
            belief, report = fuse(
                belief, outer, components[1], rows=(FUSED,), rule=self.settings.fusion
            )
            self._dr_or_fail().replace(belief)
            component, box = int(report.component[0]), report.hull[0]
        record = EpochRecord(
            t_s,
            samples.count - 1,
            found,
            before,
            np.array(belief.mean[FUSED, :3]),
            box,
            component,
            components,
        )
        self.epochs.append(record)
        self.fusion_s += time.perf_counter() - tick
        return record

    # ------------------------------------------------------------------ estimate out
    def belief(self) -> Gaussian:
        """The whole belief ``(2, 8)`` at the latest sample (the start belief before any)."""
        if not self._samples.count:
            return self._initial
        return self._advance()

    def estimate(self) -> PoseEstimate:
        """Mean and covariance of the pose of both branches at the latest sample."""
        belief = self.belief()
        sample = max(self._samples.count - 1, 0)
        t_s = float(self._samples.t_s[sample]) if self._samples.count else 0.0
        return PoseEstimate(
            t_s, sample, np.array(belief.mean[:, :3]), np.array(belief.cov[:, :3, :3])
        )

    def pose(self, branch: int) -> tuple[float, float, float]:
        """The mean pose ``(x_m, y_m, theta_rad)`` of row ``branch`` at the latest sample:
        ``estimate().pose[branch]`` without the covariances (what a controller steers on,
        at every control tick)."""
        if not self._samples.count:
            x, y, theta = self._initial.mean[branch, :3].tolist()
            return x, y, theta
        return self._dead_reckoning_at_latest().mean_pose(branch)

    @property
    def map_segments(self) -> np.ndarray:
        """``(m, 2, 2)`` the walls the localiser knows, m (read-only): its map, nothing else."""
        return self._scene.segments

    @property
    def last_set(self) -> Subpaving | None:
        """The latest epoch's set (None before the first epoch and after one without a set)."""
        return self._previous

    @property
    def status(self) -> EpochStatus | None:
        """How the latest epoch ended (None before the first)."""
        return self.epochs[-1].result.status if self.epochs else None

    @property
    def history(self) -> DeadReckoningHistory:
        """The belief of both branches at every sample so far (rows = samples; the fused row
        after the fusion at the epoch samples)."""
        self.belief()
        if self._dr is None:
            mean, cov = self._initial.mean[None], self._initial.cov[None, :, :3, :3]
            return DeadReckoningHistory(
                np.array(mean[:0]), np.array(cov[:0]), np.zeros((0, mean.shape[1]))
            )
        return self._dr.history

    # ------------------------------------------------------------------ the dead reckoning
    def _dr_or_fail(self) -> DeadReckoning:
        if self._dr is None:
            raise EstimationError("the localiser has no odometry sample yet")
        return self._dr

    def _advance(self) -> Gaussian:
        """Run the dead reckoning over the samples pushed since the last run (one call)."""
        return self._dead_reckoning_at_latest().belief

    def _dead_reckoning_at_latest(self) -> DeadReckoning:
        """The dead reckoning run over the samples pushed since the last run (one call)."""
        samples = self._samples
        dr = self._dr
        done = 0 if dr is None else dr.count
        if done < samples.count:
            # one sample of overlap: the accelerometer input of a step averages two readings
            start = max(done - 1, 0)
            rows = slice(start, samples.count)
            if dr is None:
                data = odometry_data(
                    samples.ticks[rows],
                    samples.gyro[rows],
                    samples.accel[rows],
                    self.settings.dt_s,
                    self.robot,
                    self.settings.noise,
                )
                dr = self._dr = DeadReckoning(data, self._initial, self.settings.dead_reckoning)
            else:  # the same model: the inputs only
                accel_input, z = odometry_inputs(
                    samples.ticks[rows],
                    samples.gyro[rows],
                    samples.accel[rows],
                    self.settings.dt_s,
                    self.robot,
                )
                dr.append_inputs(accel_input[1:], z[1:])
        dr = self._dr_or_fail()
        steps = samples.count - 1 - dr.index
        tick = time.perf_counter()
        dr.advance(samples.count - 1)
        elapsed = time.perf_counter() - tick
        self.dead_reckoning_s += elapsed
        if steps > 0:
            self.step_us.append(elapsed / steps * 1e6)
        return dr

"""The localisation pipeline of paper 002 on one run's sensor data: the localiser, fed, summarised.

:func:`estimate` builds the online localiser (:class:`localization.localizer.OnlineLocalizer`)
from the scenario's nominal robot, sonar belt, map and ``[estimation]`` settings, feeds it
the run's samples in the order a robot receives them (the odometry samples up to a scan,
then the scan), and gathers what it did into an :class:`Estimation`:

1. dead reckoning at the sensor rate (100 Hz) with the nominal parameters only, two branches
   batched as one belief ``(2, 8)``: row 0 the UKF-only branch, row 1 the fused one;
2. at every interval epoch (a sonar scan) the interval tracker and, when the epoch is
   consistent, the fusion of the fused branch with the set (the paper's clamp by default).

:func:`estimate_offline` is the same pipeline written over the whole arrays at once (the
dead reckoning advanced from epoch to epoch on the finished log): the reference the online
localiser equals bit for bit, and the batch figure of ``benchmarks/pipeline.py``.
:func:`estimation_summary` gives the estimation figures of the summary.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from intervals.sonar.scan import SonarBelt
from localization.compiled.dead_reckoning import N_MEASUREMENTS
from localization.dead_reckoning import (
    DeadReckoning,
    DeadReckoningNoise,
    NominalRobot,
    initial_belief,
    odometry_data,
)
from localization.fusion import fuse
from localization.localizer import (
    BRANCHES,
    FUSED,
    START_POSE_STD,
    UKF_ONLY,
    LocalizerSettings,
    OnlineLocalizer,
)
from scenarios.epochs import EpochLog, EpochRunner
from scenarios.metrics import (
    RECOVERY_DISTANCE_M,
    RECOVERY_HOLD_S,
    consistency_stats,
    interval_stats,
    nees_stats,
    recovery_time_s,
    rmse_heading_rad,
    rmse_position_m,
)
from scenarios.spec import ScenarioSpec

__all__ = [
    "BRANCHES",
    "FUSED",
    "RECOVERY_DISTANCE_M",
    "RECOVERY_HOLD_S",
    "START_POSE_STD",
    "UKF_ONLY",
    "Estimation",
    "SensorData",
    "StageTimes",
    "Steering",
    "dead_reckoning_noise",
    "estimate",
    "estimate_offline",
    "estimation_summary",
    "gathered",
    "localizer_for",
    "recovery_s",
    "scan_samples",
]


class SensorData(Protocol):
    """What the pipeline reads of a run (``robotsim.simulation.SimulationLog``, or a sensor
    log read back by ``scenarios.sensor_log``): the samples at ``rate_hz``, the scans, and
    the truth for the scores (``pose``, ``sonar_pose``, ``kidnap_t_s``)."""

    @property
    def t_s(self) -> np.ndarray: ...
    @property
    def wheel_ticks(self) -> np.ndarray: ...
    @property
    def gyro_rad_s(self) -> np.ndarray: ...
    @property
    def accel_m_s2(self) -> np.ndarray: ...
    @property
    def sonar_t_s(self) -> np.ndarray: ...
    @property
    def sonar_range_m(self) -> np.ndarray: ...
    @property
    def pose(self) -> np.ndarray: ...
    @property
    def sonar_pose(self) -> np.ndarray: ...
    @property
    def kidnap_t_s(self) -> np.ndarray: ...
    @property
    def rate_hz(self) -> float: ...


@dataclasses.dataclass(frozen=True, eq=False)
class Estimation:
    """What the localisation pipeline produced for one run (N samples, E epochs).

    ``pose (2, N, 3)`` and ``pose_cov (2, N, 3, 3)``: the branches' pose estimates and their
    covariances at every sample (row order :data:`BRANCHES`; the fused row after the fusion
    at the epoch samples); ``epochs``: the interval epochs; ``epoch_index (E,)``: their
    sample indices; ``before (E, 3)``, ``after (E, 3)``: the fused branch's pose just before
    and after the fusion; ``fused_box (E, 3, 2)``: the box the fusion used (the hull of the
    outer boxes of the component nearest the estimate, as ``localization.fusion`` takes it;
    NaN where the epoch does not clamp); ``component (E,)``: that component's label (-1: no
    fusion at the epoch); ``nis (2, N)``: the normalised innovation squared of each branch's
    measurement update (encoders and gyro, 3 degrees of freedom) at every sample (NaN at 0).
    """

    pose: np.ndarray
    pose_cov: np.ndarray
    nis: np.ndarray
    epochs: EpochLog
    epoch_index: np.ndarray
    before: np.ndarray
    after: np.ndarray
    fused_box: np.ndarray
    component: np.ndarray


@dataclasses.dataclass(frozen=True)
class StageTimes:
    """Wall times of the stages of one run, seconds, and per-step figures."""

    simulate_s: float
    dead_reckoning_s: float
    intervals_s: float
    fusion_s: float
    dr_step_us: np.ndarray
    """Wall time per dead-reckoning step (both branches), one value per stretch run,
    microseconds."""
    mcl_s: float = 0.0
    """The particle filter's wall time (``estimator = "mcl"``; then the others are 0)."""


def dead_reckoning_noise(spec: ScenarioSpec) -> DeadReckoningNoise:
    """The filter's noise model from the sensors' declared (datasheet) figures.

    The encoder increment error is the quantisation (``1/sqrt(6)`` tick) plus the declared
    slip at full speed; figures declared as 0 get a floor of 1e-9 (the filter needs
    positive variances).
    """
    s, robot = spec.sensors, spec.robot
    ticks_at_v_max = (
        robot.v_max_m_s
        / (2.0 * math.pi * robot.wheel_radius_m)
        * robot.ticks_per_rev
        / spec.run.rate_hz
    )
    floor = 1e-9
    return DeadReckoningNoise(
        tick_std=math.hypot(1.0 / math.sqrt(6.0), s.encoders.slip_std * ticks_at_v_max),
        gyro_noise_density_rad_s_sqrt_hz=max(s.gyro.noise_density_rad_s_sqrt_hz, floor),
        gyro_bias_std_rad_s=max(s.gyro.turn_on_bias_std_rad_s, floor),
        gyro_bias_random_walk_rad_s_sqrt_s=max(s.gyro.bias_random_walk_rad_s_sqrt_s, floor),
        accel_noise_density_m_s2_sqrt_hz=max(s.accelerometer.noise_density_m_s2_sqrt_hz, floor),
        accel_bias_std_m_s2=max(s.accelerometer.turn_on_bias_std_m_s2, floor),
        accel_bias_random_walk_m_s2_sqrt_s=max(s.accelerometer.bias_random_walk_m_s2_sqrt_s, floor),
        yaw_accel_std_rad_s2=robot.alpha_max_rad_s2,
    )


def _nominal_robot(spec: ScenarioSpec) -> NominalRobot:
    robot = spec.robot
    return NominalRobot(robot.wheel_radius_m, robot.wheel_base_m, robot.ticks_per_rev)


def _belt(spec: ScenarioSpec) -> SonarBelt:
    return SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=spec.estimation.free_space)


def localizer_for(spec: ScenarioSpec) -> OnlineLocalizer:
    """The online localiser of ``spec``'s robot: what the robot knows (nominal parameters,
    datasheet noise, the map, the start pose) and the ``[estimation]`` settings."""
    est = spec.estimation
    settings = LocalizerSettings(
        tracker=est.intervals,
        dead_reckoning=est.dead_reckoning,
        fusion=est.fusion,
        noise=dead_reckoning_noise(spec),
        rate_hz=spec.run.rate_hz,
        scan_stride=est.scan_stride(spec.sensors.sonar.rate_hz),
    )
    return OnlineLocalizer(
        _nominal_robot(spec),
        _belt(spec),
        spec.map.segments,
        spec.map.boundary,
        spec.map.bounds,
        settings,
        spec.start_pose,
    )


class Steering:
    """The localiser as the simulator's observer in a closed loop (``robotsim.simulation``):
    fed every sample as it comes, it gives the controller the estimate of row ``branch``
    (:data:`FUSED` or :data:`UKF_ONLY`)."""

    def __init__(self, localizer: OnlineLocalizer, branch: int) -> None:
        self.localizer, self.branch = localizer, branch

    def odometry_block(self, t_s, ticks, gyro_rad_s, accel_m_s2) -> None:
        self.localizer.push_odometry_block(t_s, ticks, gyro_rad_s, accel_m_s2)

    def scan(self, t_s: float, readings_m) -> None:
        self.localizer.push_scan(t_s, readings_m)

    def pose(self) -> tuple[float, float, float]:
        return self.localizer.pose(self.branch)


def scan_samples(log: SensorData) -> np.ndarray:
    """``(M,)`` the sample index of each scan (the sample it was taken at)."""
    return np.searchsorted(log.t_s, log.sonar_t_s - 0.5 / log.rate_hz)


def estimate(
    spec: ScenarioSpec, log: SensorData, progress: Callable[[float], None] | None = None
) -> tuple[Estimation, StageTimes]:
    """The online localiser fed ``log``'s sensor data in the order a robot receives them.

    The estimator sees only the sensor arrays, the nominal robot parameters and the
    scenario's start pose; the true poses at the scans are used afterwards, for the
    containment figure only. ``progress(fraction)`` is told the share of the scans done.
    """
    localizer = localizer_for(spec)
    at_sample = scan_samples(log)
    done = 0
    for scan, sample in enumerate(at_sample):
        stop = int(sample) + 1
        if stop > done:
            _push(localizer, log, done, stop)
            done = stop
        localizer.push_scan(log.sonar_t_s[scan], log.sonar_range_m[scan])
        if progress:
            progress((scan + 1) / len(at_sample))
    _push(localizer, log, done, len(log.t_s))
    return gathered(localizer, log)


def _push(localizer: OnlineLocalizer, log: SensorData, start: int, stop: int) -> None:
    localizer.push_odometry_block(
        log.t_s[start:stop],
        log.wheel_ticks[start:stop],
        log.gyro_rad_s[start:stop],
        log.accel_m_s2[start:stop],
    )


def gathered(localizer: OnlineLocalizer, log: SensorData) -> tuple[Estimation, StageTimes]:
    """What ``localizer`` did over the run of ``log`` (its true poses at the epochs give the
    containment figure), and the stage wall times (without the simulation)."""
    history = localizer.history
    records = localizer.epochs
    epoch_index = np.array([r.sample for r in records], dtype=np.int64)
    epoch_scans = np.searchsorted(log.sonar_t_s, [r.t_s for r in records])
    empty = np.zeros((0, 3))
    estimation = Estimation(
        pose=np.ascontiguousarray(history.mean[:, :, :3].swapaxes(0, 1)),
        pose_cov=np.ascontiguousarray(history.pose_cov.swapaxes(0, 1)),
        nis=np.ascontiguousarray(history.nis.swapaxes(0, 1)),
        epochs=EpochLog.collect(
            np.array([r.t_s for r in records]),
            [r.result for r in records],
            log.sonar_pose[epoch_scans],
            [r.components for r in records],
        ),
        epoch_index=epoch_index,
        before=np.array([r.before for r in records]) if records else empty,
        after=np.array([r.after for r in records]) if records else empty,
        fused_box=np.array([r.fused_box for r in records]) if records else np.zeros((0, 3, 2)),
        component=np.array([r.component for r in records], dtype=np.int64),
    )
    ia_s = float(estimation.epochs.elapsed_s.sum())
    times = StageTimes(
        0.0, localizer.dead_reckoning_s, ia_s, localizer.fusion_s, np.array(localizer.step_us)
    )
    return estimation, times


def estimate_offline(
    spec: ScenarioSpec, log: SensorData, progress: Callable[[float], None] | None = None
) -> tuple[Estimation, StageTimes]:
    """The same pipeline on the finished log: the dead reckoning built over the whole arrays
    and advanced from epoch to epoch (the reference of :func:`estimate`)."""
    est = spec.estimation
    noise = dead_reckoning_noise(spec)
    data = odometry_data(
        log.wheel_ticks,
        log.gyro_rad_s,
        log.accel_m_s2,
        1.0 / log.rate_hz,
        _nominal_robot(spec),
        noise,
    )
    dr = DeadReckoning(
        data, initial_belief(spec.start_pose, START_POSE_STD, noise), est.dead_reckoning
    )
    epochs = EpochRunner(
        est.intervals, spec.map.segments, spec.map.boundary, spec.map.bounds, _belt(spec)
    )
    stride = est.scan_stride(spec.sensors.sonar.rate_hz)
    scans = np.arange(0, len(log.sonar_t_s), stride)
    epoch_index = scan_samples(log)[scans]

    results, before, after, boxes, chosen = [], [], [], [], []
    fuse_s = 0.0
    clock = _DeadReckoningClock(dr)
    last_t = log.sonar_t_s[scans[0]] if len(scans) else 0.0
    for count, (scan, index) in enumerate(zip(scans, epoch_index, strict=True)):
        belief = clock.run(int(index))
        found = epochs.step(log.sonar_range_m[scan], float(log.sonar_t_s[scan] - last_t))
        last_t = log.sonar_t_s[scan]
        tick = time.perf_counter()
        before.append(np.array(belief.mean[FUSED, :3]))
        box, component = np.full((3, 2), np.nan), -1
        if found.consistent:
            outer, labels = found.outer, found.components()[1]
            belief, report = fuse(belief, outer, labels, rows=(FUSED,), rule=est.fusion)
            dr.replace(belief)
            component, box = int(report.component[0]), report.hull[0]
        after.append(np.array(belief.mean[FUSED, :3]))
        boxes.append(box)
        chosen.append(component)
        results.append(found)
        fuse_s += time.perf_counter() - tick
        if progress:
            progress((count + 1) / len(scans))
    clock.run(data.count - 1)
    history = dr.history
    empty = np.zeros((0, 3))
    estimation = Estimation(
        pose=np.ascontiguousarray(history.mean[:, :, :3].swapaxes(0, 1)),
        pose_cov=np.ascontiguousarray(history.pose_cov.swapaxes(0, 1)),
        nis=np.ascontiguousarray(history.nis.swapaxes(0, 1)),
        epochs=EpochLog.collect(log.sonar_t_s[scans], results, log.sonar_pose[scans]),
        epoch_index=epoch_index.astype(np.int64),
        before=np.array(before) if before else empty,
        after=np.array(after) if after else empty,
        fused_box=np.array(boxes) if boxes else np.zeros((0, 3, 2)),
        component=np.array(chosen, dtype=np.int64),
    )
    ia_s = float(estimation.epochs.elapsed_s.sum())
    times = StageTimes(0.0, clock.total_s, ia_s, fuse_s, np.array(clock.step_us))
    return estimation, times


class _DeadReckoningClock:
    """Runs the dead reckoning stretch by stretch and times it (total, and per step)."""

    def __init__(self, dr: DeadReckoning):
        self._dr = dr
        self.total_s = 0.0
        self.step_us: list[float] = []

    def run(self, index: int):
        """Advance to sample ``index``; returns the belief there."""
        steps = index - self._dr.index
        tick = time.perf_counter()
        belief = self._dr.run(index)
        elapsed = time.perf_counter() - tick
        self.total_s += elapsed
        if steps > 0:
            self.step_us.append(elapsed / steps * 1e6)
        return belief


def estimation_summary(log: SensorData, estimation: Estimation) -> dict[str, Any]:
    """The estimation figures of the summary: RMSE of both branches over every sample, the
    interval figures, and how the fusion went (deterministic)."""
    truth = log.pose
    rmse_pos = {name: rmse_position_m(estimation.pose[b], truth) for b, name in enumerate(BRANCHES)}
    rmse_head = {
        name: rmse_heading_rad(estimation.pose[b], truth) for b, name in enumerate(BRANCHES)
    }
    clamped = estimation.component >= 0
    moved = np.any(estimation.after[:, :2] != estimation.before[:, :2], axis=1)
    in_box = _in_box(estimation.after[clamped, :2], estimation.fused_box[clamped, :2])
    summary = {
        "rmse_position_m": rmse_pos,
        "rmse_heading_rad": rmse_head,
        "fused_to_ukf_only_position_rmse": rmse_pos["fused"] / rmse_pos["ukf_only"]
        if rmse_pos["ukf_only"] > 0
        else None,
        "nees": consistency_stats(estimation.pose, estimation.pose_cov, truth, BRANCHES),
        "nis": {
            name: nees_stats(estimation.nis[b], N_MEASUREMENTS) for b, name in enumerate(BRANCHES)
        },
        **interval_stats(estimation.epochs),
        "fusion": {
            "clamped_epochs": int(clamped.sum()),
            "moved_epochs": int(np.count_nonzero(moved & clamped)),
            "fused_in_box": bool(in_box.all()),
        },
        "kidnaps": [
            {"t_s": float(t), "recovery_s": recovery_s(log, estimation, float(t))}
            for t in log.kidnap_t_s
        ],
    }
    return summary


def recovery_s(log: SensorData, estimation: Estimation, t_s: float) -> float | None:
    """Seconds from ``t_s`` (a kidnapping, the onset of a fault) until the fused position is
    back near the truth for good (:func:`scenarios.metrics.recovery_time_s`; None: not within
    the run; 0: it never left)."""
    return recovery_time_s(log.t_s, log.rate_hz, estimation.pose[FUSED, :, :2], log.pose, t_s)


def _in_box(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(P,)``: point ``p (2,)`` lies in the closed box ``(2, 2)`` of the same row."""
    return np.all((boxes[..., 0] <= points) & (points <= boxes[..., 1]), axis=-1)

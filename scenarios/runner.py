"""One run of a scenario, without I/O: the whole localisation pipeline of paper 002.

``run_scenario(spec)``:

1. simulates the scenario (``robotsim``): the truth and every sensor;
2. dead-reckons at the sensor rate (100 Hz) with the nominal parameters only
   (``localization.dead_reckoning``), two branches batched as one belief ``(2, 8)``: row 0
   the UKF-only branch, row 1 the fused one, on the same sensor data;
3. at every interval epoch (a sonar scan) pauses the dead reckoning, steps the interval
   tracker (``scenarios.epochs`` over ``intervals.tracker``) and, when the epoch is
   consistent, fuses the fused branch with the set (``localization.fusion``; the paper's
   clamp of the position to the nearest point of the box by default);
4. summarises (``scenarios.metrics``).

Randomness comes from one ``numpy.random.Generator`` seeded with the scenario's seed, so the
same spec gives the same log, estimates and summary. Wall times are kept apart (``timing``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from intervals.errors import IntervalError
from intervals.sonar.scan import SonarBelt
from intervals.tracker import TrackerSettings
from localization.dead_reckoning import (
    DeadReckoning,
    DeadReckoningNoise,
    DeadReckoningSettings,
    NominalRobot,
    initial_belief,
    odometry_data,
)
from localization.fusion import fuse
from robotsim.simulation import KidnapEvent, SensorSuite, SimulationLog, simulate
from robotsim.world import WorldParams
from scenarios.epochs import EpochLog, EpochRunner
from scenarios.errors import ScenarioError
from scenarios.metrics import interval_stats, rmse_heading_rad, rmse_position_m, summarize
from scenarios.spec import ScenarioSpec

#: The two dead-reckoning branches, in batch order.
BRANCHES = ("ukf_only", "fused")
UKF_ONLY, FUSED = 0, 1

#: Standard deviations of the starting pose (m, m, rad): the scenario states where the robot
#: starts, up to how well a person places it.
START_POSE_STD = (0.02, 0.02, math.radians(1.0))

#: Share of the progress bar the simulation fills (the estimation fills the rest).
SIMULATION_PROGRESS = 0.3


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
    fusion at the epoch).
    """

    pose: np.ndarray
    pose_cov: np.ndarray
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
    """Wall time per dead-reckoning step (both branches), one value per stretch between
    epochs, microseconds."""


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What one run gives: the log, the estimates, the summary (no timing) and wall times."""

    log: SimulationLog
    estimation: Estimation
    summary: dict[str, Any]
    """The deterministic figures (``scenarios.metrics``)."""
    times: StageTimes
    duration_s: float
    """Simulated time, seconds."""

    def summary_with_timing(self, *, recording_s: float, wall_s: float) -> dict[str, Any]:
        """The summary with its ``timing`` block: per-stage wall times, the median dead-
        reckoning step, the interval epoch's median and 95th percentile, and the real-time
        factor of the whole command (``wall_s``: simulation, estimation, summary, recording)."""
        times = self.times
        epoch_ms = self.estimation.epochs.elapsed_s * 1e3
        timing = {
            "simulate_s": round(times.simulate_s, 4),
            "dead_reckoning_s": round(times.dead_reckoning_s, 4),
            "intervals_s": round(times.intervals_s, 4),
            "fusion_s": round(times.fusion_s, 4),
            "recording_s": round(recording_s, 4),
            "wall_s": round(wall_s, 4),
            "ukf_step_us_median": _rounded(np.median(times.dr_step_us), 2)
            if times.dr_step_us.size
            else None,
            "ia_epoch_ms_median": _rounded(np.median(epoch_ms), 3) if epoch_ms.size else None,
            "ia_epoch_ms_p95": _rounded(np.percentile(epoch_ms, 95), 3) if epoch_ms.size else None,
            "realtime_factor": round(self.duration_s / wall_s, 1) if wall_s > 0 else None,
        }
        return {**self.summary, "timing": timing}


def _rounded(value: float, digits: int) -> float:
    return round(float(value), digits)


def run_scenario(
    spec: ScenarioSpec,
    progress: Callable[[float], None] | None = None,
    kidnaps: tuple[KidnapEvent, ...] = (),
) -> RunResult:
    """Simulate ``spec``, run the localisation pipeline on its sensor data, summarise.

    ``progress(fraction)`` is told the share of the run done (simulation, then epochs);
    ``kidnaps``: robots moved without odometry during the run (``robotsim.simulation``).
    """
    start = time.perf_counter()
    log = simulate_spec(
        spec,
        kidnaps=kidnaps,
        progress=(lambda f: progress(SIMULATION_PROGRESS * f)) if progress else None,
    )
    simulate_s = time.perf_counter() - start
    try:
        estimation, times = estimate(spec, log, progress=progress)
    except (
        IntervalError
    ) as exc:  # an impossible [estimation] setting met at run time (a box explosion)
        raise ScenarioError(spec.source, "estimation", str(exc)) from None
    times = dataclasses.replace(times, simulate_s=simulate_s)
    summary = summarize(spec, log)
    summary.update(estimation_summary(log, estimation))
    return RunResult(
        log=log, estimation=estimation, summary=summary, times=times, duration_s=spec.run.duration_s
    )


def simulate_spec(
    spec: ScenarioSpec,
    kidnaps: tuple[KidnapEvent, ...] = (),
    progress: Callable[[float], None] | None = None,
) -> SimulationLog:
    """The simulator run ``spec`` describes, its randomness seeded by the spec's seed."""
    sensors = spec.sensors
    return simulate(
        spec.map,
        spec.plan,
        start_pose=spec.start_pose,
        duration_s=spec.run.duration_s,
        rng=np.random.default_rng(spec.run.seed),
        robot=spec.robot,
        sensors=SensorSuite(
            encoders=sensors.encoders,
            gyro=sensors.gyro,
            accelerometer=sensors.accelerometer,
            sonar=sensors.sonar,
        ),
        world=WorldParams(step_hz=spec.run.rate_hz),
        kidnaps=kidnaps,
        progress=progress,
    )


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


def tracker_settings(spec: ScenarioSpec) -> TrackerSettings:
    """The interval tracker's settings: the scenario's ``[estimation]`` and the robot's limits."""
    est = spec.estimation
    return TrackerSettings(
        v_max_m_s=spec.robot.v_max_m_s,
        omega_max_rad_s=spec.robot.omega_max_rad_s,
        eps_m=est.eps_m,
        heading_scale_m_per_rad=est.heading_scale_m_per_rad,
        q_max=est.q_max,
        tracker=est.tracker,
        imagesp_pitch_m=est.imagesp_pitch_m,
        guaranteed=est.guaranteed,
        ray_test=est.ray_test,
    )


def estimate(
    spec: ScenarioSpec, log: SimulationLog, progress: Callable[[float], None] | None = None
) -> tuple[Estimation, StageTimes]:
    """Dead reckoning on both branches, an interval epoch at the chosen scans, the fusion.

    The estimator sees only the sensor arrays, the nominal robot parameters and the
    scenario's start pose; the true poses at the scans are used afterwards, for the
    containment figure only.
    """
    est = spec.estimation
    robot = spec.robot
    nominal = NominalRobot(robot.wheel_radius_m, robot.wheel_base_m, robot.ticks_per_rev)
    noise = dead_reckoning_noise(spec)
    data = odometry_data(
        log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2, 1.0 / log.rate_hz, nominal, noise
    )
    dr = DeadReckoning(
        data,
        initial_belief(spec.start_pose, START_POSE_STD, noise),
        DeadReckoningSettings(est.filter),
    )

    belt = SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=est.free_space)
    epochs = EpochRunner(
        tracker_settings(spec), spec.map.segments, spec.map.boundary, spec.map.bounds, belt
    )
    stride = est.scan_stride(spec.sensors.sonar.rate_hz)
    scans = np.arange(0, len(log.sonar_t_s), stride)
    epoch_index = np.searchsorted(log.t_s, log.sonar_t_s[scans] - 0.5 / log.rate_hz)

    results, before, after, boxes, chosen = [], [], [], [], []
    fuse_s = 0.0
    clock = _DeadReckoningClock(dr)
    last_t = log.sonar_t_s[scans[0]] if len(scans) else 0.0
    for count, (scan, index) in enumerate(zip(scans, epoch_index)):
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
            progress(SIMULATION_PROGRESS + (1.0 - SIMULATION_PROGRESS) * (count + 1) / len(scans))
    clock.run(data.count - 1)
    history = dr.history
    empty = np.zeros((0, 3))
    estimation = Estimation(
        pose=np.ascontiguousarray(history.mean[:, :, :3].swapaxes(0, 1)),
        pose_cov=np.ascontiguousarray(history.pose_cov.swapaxes(0, 1)),
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


def estimation_summary(log: SimulationLog, estimation: Estimation) -> dict[str, Any]:
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
        **interval_stats(estimation.epochs),
        "fusion": {
            "clamped_epochs": int(clamped.sum()),
            "moved_epochs": int(np.count_nonzero(moved & clamped)),
            "fused_in_box": bool(in_box.all()),
        },
    }
    return summary


def _in_box(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(P,)``: point ``p (2,)`` lies in the closed box ``(2, 2)`` of the same row."""
    return np.all((boxes[..., 0] <= points) & (points <= boxes[..., 1]), axis=-1)

"""One run of a scenario, without I/O: spec -> simulate -> pipeline -> summary.

``run_scenario(spec)``:

1. simulates the scenario (``robotsim``): the truth and every sensor;
2. runs the localisation pipeline of paper 002 on its sensor data (``scenarios.pipeline``:
   the online localiser fed the samples in order), or with ``estimator = "mcl"`` the
   particle filter (``scenarios.mcl_pipeline``);
3. summarises (``scenarios.metrics``, ``scenarios.pipeline.estimation_summary``).

Randomness comes from one ``numpy.random.Generator`` seeded with the scenario's seed, so the
same spec gives the same log, estimates and summary. Wall times are kept apart (``timing``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from intervals.errors import IntervalBudgetError
from robotsim.simulation import KidnapEvent, Observer, SensorSuite, SimulationLog, simulate
from robotsim.world import WorldParams
from scenarios.errors import ScenarioError
from scenarios.mcl_pipeline import Estimator, MclEstimation, estimate_mcl, mcl_summary
from scenarios.metrics import route_stats, safety_stats, summarize, wall_distance_m
from scenarios.pipeline import (
    BRANCHES,
    FUSED,
    UKF_ONLY,
    Estimation,
    StageTimes,
    Steering,
    estimate,
    estimation_summary,
    gathered,
    localizer_for,
    recovery_s,
)
from scenarios.spec import Follow, ScenarioSpec

#: What other modules take from here: the run, and the pipeline's records of it.
__all__ = ["BRANCHES", "Estimation", "RunResult", "StageTimes", "run_scenario", "simulate_spec"]

#: Share of the progress bar the simulation fills (the estimation fills the rest).
SIMULATION_PROGRESS = 0.3


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What one run gives: the log, the estimates, the summary (no timing) and wall times."""

    log: SimulationLog
    estimation: Estimation | MclEstimation
    """The interval pipeline's estimates, or the particle filter's (``estimator = "mcl"``)."""
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
        if isinstance(self.estimation, MclEstimation):
            epoch_ms = np.zeros(0)
            update_ms = self.estimation.update_s * 1e3
        else:
            epoch_ms = self.estimation.epochs.elapsed_s * 1e3
            update_ms = np.zeros(0)
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
            "mcl_s": round(times.mcl_s, 4),
            "mcl_update_ms_median": _rounded(np.median(update_ms), 3) if update_ms.size else None,
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
    ``kidnaps``: robots moved without odometry during the run (``robotsim.simulation``),
    beside the scenario's own ``kidnap`` events.
    """
    kidnaps = spec.kidnaps + tuple(kidnaps)
    start = time.perf_counter()
    simulation_progress = (lambda f: progress(SIMULATION_PROGRESS * f)) if progress else None
    try:
        if spec.estimation.estimator == Estimator.MCL:  # beside the motion (never closed loop)
            log = simulate_spec(spec, kidnaps=kidnaps, progress=simulation_progress)
            simulate_s = time.perf_counter() - start
            mcl_estimation = estimate_mcl(
                spec,
                log,
                progress=(
                    (lambda f: progress(SIMULATION_PROGRESS + (1.0 - SIMULATION_PROGRESS) * f))
                    if progress
                    else None
                ),
            )
            summary = summarize(spec, log)
            summary["estimator"] = str(Estimator.MCL)
            summary.update(mcl_summary(log, mcl_estimation))
            summary["route"] = route_stats(spec, log)
            mcl_s = time.perf_counter() - start - simulate_s
            return RunResult(
                log=log,
                estimation=mcl_estimation,
                summary=summary,
                times=StageTimes(simulate_s, 0.0, 0.0, 0.0, np.zeros(0), mcl_s=mcl_s),
                duration_s=spec.run.duration_s,
            )
        if spec.follow == Follow.TRUTH:
            log = simulate_spec(spec, kidnaps=kidnaps, progress=simulation_progress)
            simulate_s = time.perf_counter() - start
            estimation, times = estimate(
                spec,
                log,
                progress=(
                    (lambda f: progress(SIMULATION_PROGRESS + (1.0 - SIMULATION_PROGRESS) * f))
                    if progress
                    else None
                ),
            )
        else:  # closed loop: the simulator and the localiser stepped together
            localizer = localizer_for(spec)
            branch = UKF_ONLY if spec.follow == Follow.UKF_ONLY else FUSED
            log = simulate_spec(
                spec,
                kidnaps=kidnaps,
                progress=progress,
                observer=Steering(localizer, branch),
            )
            estimation, times = gathered(localizer, log)
            estimation_s = times.dead_reckoning_s + times.intervals_s + times.fusion_s
            simulate_s = time.perf_counter() - start - estimation_s
    except IntervalBudgetError as exc:  # a precision too fine for the map, met at run time
        raise ScenarioError(spec.source, "estimation.eps_m", str(exc)) from None
    times = dataclasses.replace(times, simulate_s=simulate_s)
    wall_distance = wall_distance_m(spec, log)
    summary = summarize(spec, log, wall_distance)
    summary["estimator"] = str(Estimator.INTERVALS)
    summary.update(estimation_summary(log, estimation))
    summary["route"] = route_stats(spec, log)
    summary["safety"] = safety_stats(
        spec, log, estimation.epochs, estimation.epoch_index, wall_distance
    )
    summary["sonar_failures"] = [
        {
            "start_s": failure.start_s,
            "end_s": failure.end_s,
            "sensors": list(failure.sensors),
            "recovery_s": recovery_s(log, estimation, failure.start_s),
        }
        for failure in spec.sonar_failures
    ]
    return RunResult(
        log=log, estimation=estimation, summary=summary, times=times, duration_s=spec.run.duration_s
    )


def simulate_spec(
    spec: ScenarioSpec,
    kidnaps: tuple[KidnapEvent, ...] = (),
    progress: Callable[[float], None] | None = None,
    observer: Observer | None = None,
) -> SimulationLog:
    """The simulator run ``spec`` describes, its randomness seeded by the spec's seed
    (``observer``: the estimator the controller steers on, None for the true pose)."""
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
        observer=observer,
        obstacles=spec.obstacles,
        sonar_failures=spec.sonar_failures,
        control_stride=spec.control_stride,
    )

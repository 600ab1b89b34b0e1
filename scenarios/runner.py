"""One run of a scenario, without I/O: spec -> simulator -> ``SimulationLog`` -> summary.

``run_scenario(spec)`` builds the simulator objects the spec describes, simulates, and
returns the log with its summary. Randomness comes from one ``numpy.random.Generator``
seeded with the scenario's seed, so the same spec gives the same log and summary.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from robotsim.simulation import SensorSuite, SimulationLog, simulate
from robotsim.world import WorldParams
from scenarios.metrics import summarize
from scenarios.spec import ScenarioSpec


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What one run gives: the log, its summary (no timing) and the simulation wall time."""

    log: SimulationLog
    summary: dict[str, Any]
    """The deterministic figures of ``scenarios.metrics.summarize``."""
    simulate_s: float
    """Wall time of the simulation, seconds."""
    duration_s: float
    """Simulated time, seconds."""

    def summary_with_timing(self, *, recording_s: float, wall_s: float) -> dict[str, Any]:
        """The summary with its ``timing`` block: stage wall times and the real-time factor.

        ``wall_s`` covers the whole command (simulation, summary and recording).
        """
        timing = {
            "simulate_s": round(self.simulate_s, 4),
            "recording_s": round(recording_s, 4),
            "wall_s": round(wall_s, 4),
            "realtime_factor": round(self.duration_s / wall_s, 1) if wall_s > 0 else None,
        }
        return {**self.summary, "timing": timing}


def run_scenario(spec: ScenarioSpec, progress: Callable[[float], None] | None = None) -> RunResult:
    """Simulate ``spec`` and summarise it.

    ``progress(fraction)`` is told 0 before the simulation and 1 after it (the simulator
    does not report its progress within a run).
    """
    if progress:
        progress(0.0)
    start = time.perf_counter()
    log = simulate_spec(spec)
    simulate_s = time.perf_counter() - start
    if progress:
        progress(1.0)
    return RunResult(log=log, summary=summarize(spec, log), simulate_s=simulate_s, duration_s=spec.run.duration_s)


def simulate_spec(spec: ScenarioSpec) -> SimulationLog:
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
            encoders=sensors.encoders, gyro=sensors.gyro, accelerometer=sensors.accelerometer, sonar=sensors.sonar
        ),
        world=WorldParams(step_hz=spec.run.rate_hz),
    )

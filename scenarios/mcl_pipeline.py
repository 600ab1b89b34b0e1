"""The particle-filter baseline (:mod:`localization.mcl`) run on one run's sensor data.

``[estimation] estimator = "mcl"`` (:class:`Estimator`) replaces the interval pipeline of
``scenarios.pipeline`` by Monte Carlo localisation, fed the same sensor data:

- the odometry integrated from the wheel encoders alone, with the nominal wheel radius and
  base (:func:`localization.mcl.odometry_poses`; ``amcl`` takes the wheel odometry the same
  way, the gyro is not used);
- every sonar scan, weighted against the ranges the simulator's exact cone model expects
  (:func:`scenarios.mcl_ranges.cone_range_function`);
- a uniform prior over the free space (global localisation: the filter is not told the
  start pose), with the ``[estimation.mcl]`` settings (:class:`localization.mcl.MclSettings`).

Between two filter updates the estimate is carried by the odometry moved since the last
update (``amcl``'s map-to-odometry transform, :meth:`MonteCarloLocalization.pose_at`), so
there is an estimate at every sample, scored as the interval pipeline's branches are (RMSE
and NEES over every sample, kidnap recovery). The covariance at a sample is the particles'
covariance at the last update.
"""

from __future__ import annotations

import dataclasses
import math
import time
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from localization.mcl import MonteCarloLocalization, odometry_poses
from scenarios.mcl_ranges import cone_range_function, free_space_sampler
from scenarios.metrics import consistency_stats, recovery_time_s, rmse_heading_rad, rmse_position_m

if TYPE_CHECKING:
    from scenarios.pipeline import SensorData
    from scenarios.spec import ScenarioSpec


class Estimator(StrEnum):
    """What localises the robot (``[estimation] estimator``)."""

    INTERVALS = "intervals"
    """The pipeline of paper 002 (``scenarios.pipeline``): dead reckoning (UKF) fused with
    the guaranteed interval sets; branches ``ukf_only`` and ``fused``."""
    MCL = "mcl"
    """Monte Carlo localisation (this module) from a uniform prior; one branch, ``mcl``."""


#: The name of MCL's estimate in the summary (``rmse_position_m.mcl``, ``nees.mcl``, ...).
MCL_BRANCH = "mcl"

#: The spawn key of the filter's random stream: independent of the simulator's stream,
#: which is seeded with the same run seed.
MCL_STREAM = 1


@dataclasses.dataclass(frozen=True, eq=False)
class MclEstimation:
    """What the particle filter produced over one run (N samples, U snapshots: the prior at
    sample 0, then one per filter update).

    ``pose (N, 3)``, ``pose_cov (N, 3, 3)``: the estimate at every sample (carried by the
    odometry from the last update) and the particle covariance of that update;
    ``update_index (U,)``: the sample of each snapshot; ``particle_count (U,)``: the set's
    size; ``particles (P, 3)`` with ``shown_count (U,)``: at most ``shown`` particles of
    each snapshot, in snapshot order (for the recording); ``update_s (U - 1,)``: wall time
    of each filter update, seconds (timing only, not in the summary).
    """

    pose: np.ndarray
    pose_cov: np.ndarray
    update_index: np.ndarray
    particle_count: np.ndarray
    particles: np.ndarray
    shown_count: np.ndarray
    update_s: np.ndarray

    @property
    def updates(self) -> int:
        """Filter updates (the scans that passed the ``update_min_*`` gate)."""
        return len(self.update_index) - 1


#: At most this many particles per snapshot are kept for the recording.
PARTICLES_SHOWN = 300


def mcl_filter(spec: ScenarioSpec) -> MonteCarloLocalization:
    """The particle filter of ``spec``: its map, its belt, its ``[estimation.mcl]``
    settings, its own random stream (from the run seed), the uniform prior spread."""
    sonar = spec.sensors.sonar
    rng = np.random.default_rng(np.random.SeedSequence(spec.run.seed, spawn_key=(MCL_STREAM,)))
    mcl = MonteCarloLocalization(
        spec.estimation.mcl,
        cone_range_function(spec.map.segments, sonar),
        free_space_sampler(spec.map, spec.robot.radius_m),
        spec.map.bounds,
        sonar.d_max_m,
        rng,
    )
    mcl.global_localization()
    return mcl


def encoder_odometry(spec: ScenarioSpec, log: SensorData) -> np.ndarray:
    """Odometry poses ``(N, 3)`` from the encoder ticks and the nominal robot."""
    robot = spec.robot
    return odometry_poses(
        log.wheel_ticks,
        2 * math.pi * robot.wheel_radius_m / robot.ticks_per_rev,
        robot.wheel_base_m,
    )


def estimate_mcl(spec: ScenarioSpec, log: SensorData, progress=None) -> MclEstimation:
    """Run the particle filter of ``spec`` on ``log``'s encoders and scans (module docstring);
    ``progress(fraction)`` is told the share of the scans done."""
    from scenarios.pipeline import scan_samples

    mcl = mcl_filter(spec)
    odom = encoder_odometry(spec, log)
    shown = PARTICLES_SHOWN
    means, covs, index, counts, kept, kept_counts, update_s = [], [], [0], [], [], [], []

    def snapshot() -> None:
        estimate = mcl.estimate()
        means.append(estimate.mean)
        covs.append(estimate.cov)
        particles = mcl.particles
        counts.append(len(particles))
        step = -(-len(particles) // shown)
        kept.append(particles[::step])
        kept_counts.append(len(kept[-1]))

    snapshot()  # the prior, at sample 0
    at_sample = scan_samples(log)
    for scan, sample in enumerate(at_sample):
        start = time.perf_counter()
        updated = mcl.update(odom[sample], log.sonar_range_m[scan])
        if updated:
            update_s.append(time.perf_counter() - start)
            index.append(int(sample))
            snapshot()
        if progress:
            progress((scan + 1) / len(at_sample))
    update_index = np.array(index, dtype=np.int64)
    mean = np.array(means)
    pose = carried_poses(mean, odom[update_index], odom, update_index)
    last = np.searchsorted(update_index, np.arange(len(odom)), side="right") - 1
    return MclEstimation(
        pose=pose,
        pose_cov=np.array(covs)[last],
        update_index=update_index,
        particle_count=np.array(counts, dtype=np.int64),
        particles=np.concatenate(kept),
        shown_count=np.array(kept_counts, dtype=np.int64),
        update_s=np.array(update_s),
    )


def carried_poses(
    mean: np.ndarray, odom_at_update: np.ndarray, odom: np.ndarray, update_index: np.ndarray
) -> np.ndarray:
    """The estimate at every sample ``(N, 3)``: the estimate ``mean (U, 3)`` of the last
    update at or before the sample, composed with the odometry increment since that update,
    ``mean (+) (odom_at_update^-1 (+) odom)`` (``odom (N, 3)``, ``odom_at_update (U, 3)``,
    ``update_index (U,)`` sorted, its first entry 0); as :meth:`MonteCarloLocalization.pose_at`."""
    last = np.searchsorted(update_index, np.arange(len(odom)), side="right") - 1
    base, ref = mean[last], odom_at_update[last]
    dx, dy = odom[:, 0] - ref[:, 0], odom[:, 1] - ref[:, 1]
    c, s = np.cos(ref[:, 2]), np.sin(ref[:, 2])
    local_x, local_y = c * dx + s * dy, -s * dx + c * dy  # the increment in the update's frame
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    theta = base[:, 2] + odom[:, 2] - ref[:, 2]
    return np.column_stack(
        [
            base[:, 0] + c * local_x - s * local_y,
            base[:, 1] + s * local_x + c * local_y,
            (theta + math.pi) % (2 * math.pi) - math.pi,
        ]
    )


def mcl_summary(log: SensorData, estimation: MclEstimation) -> dict[str, Any]:
    """The estimation figures of an MCL run, under the names the interval pipeline uses
    (its branch named :data:`MCL_BRANCH`): RMSE and NEES over every sample, ``epochs`` (the
    filter updates), the kidnap recoveries, and the particle counts (deterministic)."""
    truth = log.pose
    pose, cov = estimation.pose, estimation.pose_cov
    counts = estimation.particle_count[1:]
    return {
        "rmse_position_m": {MCL_BRANCH: rmse_position_m(pose, truth)},
        "rmse_heading_rad": {MCL_BRANCH: rmse_heading_rad(pose, truth)},
        "nees": consistency_stats(pose[None], cov[None], truth, (MCL_BRANCH,)),
        "epochs": estimation.updates,
        "mcl": {
            "updates": estimation.updates,
            "particles_mean": float(counts.mean()) if counts.size else None,
            "particles_final": int(estimation.particle_count[-1]),
        },
        "kidnaps": [
            {
                "t_s": float(t),
                "recovery_s": recovery_time_s(log.t_s, log.rate_hz, pose, truth, float(t)),
            }
            for t in log.kidnap_t_s
        ],
    }

"""Monte Carlo localisation (a particle filter) with the semantics of ROS ``amcl``.

The baseline users reach for first for global localisation with range sensors. One
:meth:`MonteCarloLocalization.update` takes the robot's odometry pose (odometry frame) and
one sonar scan and, when the robot has moved enough since the last filter update
(``update_min_d`` / ``update_min_a``, as ``amcl``):

1. moves every particle by the odometry increment with the sampled odometry motion model
   (``alpha1..alpha4``; PR table 5.6, :func:`localization.compiled.mcl.sample_motion_odometry`);
2. weights it by the beam model mixture ``z_hit, z_short, z_max, z_rand`` with
   ``sigma_hit`` and ``lambda_short`` on the scan, against the ranges it expects
   (:func:`localization.compiled.mcl.beam_log_likelihoods`; no-echo readings count as
   max-range readings);
3. tracks the short- and long-term average likelihood ``w_fast``, ``w_slow``
   (``recovery_alpha_fast/slow``, PR table 8.3) and resamples every ``resample_interval``
   updates: a share ``max(0, 1 - w_fast / w_slow)`` of the new set is drawn uniformly over
   the free space (recovery from a wrong convergence or a kidnapping), the rest by
   low-variance (systematic) resampling; the size of the new set comes from KLD-sampling
   (``kld_err``, ``kld_z``, ``min_particles``..``max_particles``, histogram cells
   ``kld_bin_*``; Fox 2003).

References and kernel details: :mod:`localization.compiled.mcl` ("PR": Thrun, Burgard, Fox,
*Probabilistic Robotics*). Global localisation (:meth:`MonteCarloLocalization.global_localization`)
spreads ``max_particles`` uniformly over the free space with uniform headings, as
``amcl``'s ``global_localization`` service.

What this module does not know: the map and the sensor. The caller passes

- ``expected_ranges(particles (N, 3)) -> (N, S)``: the distance each of the S sonars of the
  belt would read without noise from each particle pose (``inf``: no echo), e.g.
  :func:`scenarios.mcl_ranges.cone_range_function` (the simulator's exact cone model);
- ``sample_free(rng, n) -> (n, 2)``: positions drawn uniformly over the free space;
- the map's bounds (the KLD histogram's extent),

so ``localization`` imports no simulator.

Where this differs from ``amcl`` (on purpose): the per-scan likelihood is by default the
product of the beam likelihoods (``BeamCombination.PRODUCT``; ``amcl``'s ``1 + sum p^3`` is
``BeamCombination.AMCL_CUBE``); the average likelihood that drives the recovery is the
prior-weighted mean likelihood (``amcl`` divides by the particle count, which then changes
with KLD-sampling); the KLD loop draws from a systematic resample in random order and then
the new set is a systematic resample of the size found (``amcl`` draws multinomially); a
histogram with one occupied bin asks for ``min_particles`` (``amcl``: ``max_particles``).
``w_slow`` and ``w_fast`` run on after an injection of random particles, as PR table 8.3
(``pf.c`` sets both to 0 after each injection: they then restart from 0 and, with
``recovery_alpha_slow = 0.001``, ``w_fast`` stays above ``w_slow`` for a long time; on hall,
seed 0, the robot kidnapped at 100 s, that variant had not found the robot 100 s later,
this one had after 18 s).
The estimate is the weighted mean of all particles (``amcl`` reports its heaviest cluster).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from localization.compiled import mcl as mcl_kernels
from localization.errors import EstimationError
from localization.linalg import wrap_angle
from validated_records import bounded, validate_fields

ExpectedRanges = Callable[[np.ndarray], np.ndarray]
"""``particles (N, 3) -> (N, S)`` expected ranges in metres (``inf``: no echo)."""

FreeSpaceSampler = Callable[[np.random.Generator, int], np.ndarray]
"""``(rng, n) -> (n, 2)`` positions uniform over the map's free space, metres."""


class BeamCombination(StrEnum):
    """How the beams of a scan combine into one likelihood."""

    PRODUCT = "product"
    """``p = prod_s p_s``: independent beams (PR table 6.1)."""
    AMCL_CUBE = "amcl_cube"
    """``p = 1 + sum_s p_s^3``: ``amcl_laser.cpp``'s beam model."""


_COMBINATION_CODE = {
    BeamCombination.PRODUCT: mcl_kernels.COMBINE_PRODUCT,
    BeamCombination.AMCL_CUBE: mcl_kernels.COMBINE_AMCL_CUBE,
}


@dataclass(frozen=True)
class MclSettings:
    """The particle filter's settings; names and defaults of nav2's ``amcl`` (``nav2_params``).

    Attributes:
        alpha1: rotation noise from rotation, rad^2 per rad^2 (variance of ``rot1``, ``rot2``).
        alpha2: rotation noise from translation, rad^2 per m^2.
        alpha3: translation noise from translation, m^2 per m^2.
        alpha4: translation noise from rotation, m^2 per rad^2.
        z_hit, z_short, z_max, z_rand: mixture weights of the beam model (>= 0, sum > 0;
            not renormalised, as ``amcl``).
        sigma_hit_m: standard deviation of the hit Gaussian, m.
        lambda_short_per_m: rate of the exponential of short readings, 1/m.
        beam_combination: :class:`BeamCombination`.
        min_particles, max_particles: bounds of the KLD-sampled set size.
        kld_err: bound ``eps`` on the K-L divergence between the particle set and the posterior.
        kld_z: upper standard normal quantile ``z_{1-delta}`` of the probability that the
            bound holds (``amcl`` reads 0.99 as the quantile itself: ``1 - delta = 0.84``).
        kld_bin_xy_m, kld_bin_theta_rad: histogram cells of KLD-sampling (``amcl``: 0.5 m,
            10 degrees).
        recovery_alpha_slow, recovery_alpha_fast: smoothing rates of ``w_slow``, ``w_fast``
            (``0 <= slow < fast <= 1``, or both 0 to turn the random particles off; ``amcl``
            suggests 0.001 and 0.1).
        update_min_d_m: translation (along either odometry axis) that triggers an update, m.
        update_min_a_rad: rotation that triggers an update, rad.
        resample_interval: filter updates between resamplings (>= 1).
    """

    alpha1: float = bounded(0.2, minimum=0.0, maximum=100.0)
    alpha2: float = bounded(0.2, minimum=0.0, maximum=100.0)
    alpha3: float = bounded(0.2, minimum=0.0, maximum=100.0)
    alpha4: float = bounded(0.2, minimum=0.0, maximum=100.0)
    z_hit: float = bounded(0.5, minimum=0.0, maximum=1e6)
    z_short: float = bounded(0.05, minimum=0.0, maximum=1e6)
    z_max: float = bounded(0.05, minimum=0.0, maximum=1e6)
    z_rand: float = bounded(0.5, minimum=0.0, maximum=1e6)
    sigma_hit_m: float = bounded(0.2, above=0.0, maximum=100.0)
    lambda_short_per_m: float = bounded(0.1, above=0.0, maximum=1e6)
    beam_combination: BeamCombination = BeamCombination.PRODUCT
    min_particles: int = bounded(500, minimum=1, maximum=10_000_000, integer=True)
    max_particles: int = bounded(2000, minimum=1, maximum=10_000_000, integer=True)
    kld_err: float = bounded(0.05, above=0.0, maximum=1.0)
    kld_z: float = bounded(0.99, minimum=0.0, maximum=10.0)
    kld_bin_xy_m: float = bounded(0.5, above=0.0, maximum=1e3)
    kld_bin_theta_rad: float = bounded(math.radians(10.0), above=0.0, maximum=2 * math.pi)
    recovery_alpha_slow: float = bounded(0.0, minimum=0.0, maximum=1.0)
    recovery_alpha_fast: float = bounded(0.0, minimum=0.0, maximum=1.0)
    update_min_d_m: float = bounded(0.25, minimum=0.0, maximum=1e3)
    update_min_a_rad: float = bounded(0.2, minimum=0.0, maximum=2 * math.pi)
    resample_interval: int = bounded(1, minimum=1, maximum=1_000_000, integer=True)

    def __post_init__(self) -> None:
        validate_fields(self, EstimationError)
        checks = [
            (self.z_hit + self.z_short + self.z_max + self.z_rand > 0, "z_* must not all be 0"),
            (
                1 <= self.min_particles <= self.max_particles,
                "need 1 <= min_particles <= max_particles",
            ),
            (
                (self.recovery_alpha_slow == self.recovery_alpha_fast == 0.0)
                or (0 < self.recovery_alpha_slow < self.recovery_alpha_fast <= 1),
                "need 0 < recovery_alpha_slow < recovery_alpha_fast <= 1, or both 0",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise EstimationError(f"MclSettings: {message}")

    @property
    def alphas(self) -> np.ndarray:
        """``(alpha1, alpha2, alpha3, alpha4)`` as an array ``(4,)``."""
        return np.array([self.alpha1, self.alpha2, self.alpha3, self.alpha4])

    @property
    def mixture(self) -> np.ndarray:
        """``(z_hit, z_short, z_max, z_rand, sigma_hit_m, lambda_short_per_m)`` ``(6,)``."""
        return np.array(
            [
                self.z_hit,
                self.z_short,
                self.z_max,
                self.z_rand,
                self.sigma_hit_m,
                self.lambda_short_per_m,
            ]
        )

    @property
    def recovery(self) -> bool:
        """Whether random particles are injected (the recovery rates are set)."""
        return self.recovery_alpha_fast > 0


@dataclass(frozen=True)
class PoseEstimate:
    """The filter's pose estimate: weighted mean ``mean (3,)`` ``(x_m, y_m, theta_rad)``
    (circular mean for the heading) and covariance ``cov (3, 3)`` of the particles."""

    mean: np.ndarray
    cov: np.ndarray


def odometry_poses(
    ticks,
    metres_per_tick: float,
    wheel_base_m: float,
    gyro_rad_s=None,
    dt_s: float | None = None,
) -> np.ndarray:
    """Odometry poses ``(N, 3)`` integrated from the encoder tick increments ``(N, 2)``.

    Differential drive with the nominal wheel travel per tick: per sample
    ``ds = (dl + dr) / 2``, ``dtheta = (dr - dl) / L`` (or ``gyro dt`` when the gyro readings
    ``(N,)`` and ``dt_s`` are given: the usual wheel-gyro odometry), and the pose moves along
    the mid-step heading ``x += ds cos(theta + dtheta / 2)``. Starts at ``(0, 0, 0)`` (the
    odometry frame); row 0 of ``ticks`` is not used. Heading wrapped to ``[-pi, pi)``.
    """
    ticks = np.asarray(ticks, dtype=np.float64)
    if ticks.ndim != 2 or ticks.shape[1] != 2 or len(ticks) < 1:
        raise EstimationError(f"odometry_poses: ticks must have shape (N, 2), got {ticks.shape}")
    travel = ticks[1:] * metres_per_tick  # (N-1, 2) left, right, m
    ds = travel.mean(axis=1)
    if gyro_rad_s is None:
        dtheta = (travel[:, 1] - travel[:, 0]) / wheel_base_m
    else:
        gyro = np.asarray(gyro_rad_s, dtype=np.float64)
        if gyro.shape != ticks.shape[:1] or dt_s is None or not dt_s > 0:
            raise EstimationError(
                f"odometry_poses: gyro_rad_s must have shape {ticks.shape[:1]} and dt_s > 0"
            )
        dtheta = 0.5 * (gyro[:-1] + gyro[1:]) * dt_s  # the mean rate over the step
    theta = np.concatenate([[0.0], np.cumsum(dtheta)])
    mid = theta[:-1] + 0.5 * dtheta
    x = np.concatenate([[0.0], np.cumsum(ds * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(ds * np.sin(mid))])
    return np.stack([x, y, wrap_angle(theta)], axis=1)


class MonteCarloLocalization:
    """The particle filter (module docstring). Not thread-safe; one instance per run.

    Args:
        settings: :class:`MclSettings`.
        expected_ranges: ``(N, 3) -> (N, S)`` expected ranges, m (``inf``: no echo).
        sample_free: ``(rng, n) -> (n, 2)`` free-space positions, m.
        bounds_m: ``(2, 2)`` ``[[xmin, xmax], [ymin, ymax]]`` of the map (KLD histogram).
        max_range_m: the sonar's range limit; readings and expectations beyond count as max.
        rng: the filter's random generator (all its draws come from it).
    """

    def __init__(
        self,
        settings: MclSettings,
        expected_ranges: ExpectedRanges,
        sample_free: FreeSpaceSampler,
        bounds_m,
        max_range_m: float,
        rng: np.random.Generator,
    ):
        bounds = np.asarray(bounds_m, dtype=np.float64)
        if (
            bounds.shape != (2, 2)
            or not np.isfinite(bounds).all()
            or np.any(bounds[:, 1] <= bounds[:, 0])
        ):
            raise EstimationError(
                f"MonteCarloLocalization: bounds_m must be a (2, 2) box, got {bounds_m!r}"
            )
        if not (math.isfinite(max_range_m) and max_range_m > 0):
            raise EstimationError(
                f"MonteCarloLocalization: max_range_m must be positive and finite, got {max_range_m!r}"
            )
        self.settings = settings
        self._expected_ranges = expected_ranges
        self._sample_free = sample_free
        self._max_range_m = float(max_range_m)
        self._rng = rng
        cell = np.array([settings.kld_bin_xy_m, settings.kld_bin_xy_m, settings.kld_bin_theta_rad])
        self._kld_origin = np.array([bounds[0, 0], bounds[1, 0], -math.pi])
        extent = np.array([bounds[0, 1] - bounds[0, 0], bounds[1, 1] - bounds[1, 0], 2 * math.pi])
        self._kld_cell = cell
        self._kld_shape = np.maximum(np.ceil(extent / cell), 1).astype(np.int64)
        self._particles = np.zeros((0, 3))
        self._weights = np.zeros(0)
        self._odom_at_update: np.ndarray | None = None
        self._updates_since_resample = 0
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.updates = 0
        """Filter updates done (scans that passed the ``update_min_*`` gate)."""

    # -- the particle set -------------------------------------------------------------
    @property
    def particles(self) -> np.ndarray:
        """``(N, 3)`` particle poses (a copy)."""
        return self._particles.copy()

    @property
    def weights(self) -> np.ndarray:
        """``(N,)`` normalised weights (a copy)."""
        return self._weights.copy()

    def set_particles(self, particles, weights=None) -> None:
        """Replace the particle set (``(N, 3)``; uniform weights unless ``weights (N,)``)."""
        particles = np.array(particles, dtype=np.float64)
        if particles.ndim != 2 or particles.shape[1] != 3 or len(particles) == 0:
            raise EstimationError(
                f"MonteCarloLocalization: particles must be (N, 3), got {particles.shape}"
            )
        if weights is None:
            weights = np.full(len(particles), 1.0 / len(particles))
        weights = np.array(weights, dtype=np.float64)
        if weights.shape != (len(particles),) or np.any(weights < 0) or not weights.sum() > 0:
            raise EstimationError("MonteCarloLocalization: weights must be (N,), >= 0, not all 0")
        particles[:, 2] = wrap_angle(particles[:, 2])
        self._particles = np.ascontiguousarray(particles)
        self._weights = weights / weights.sum()

    def uniform_poses(self, count: int) -> np.ndarray:
        """``count`` poses uniform over the free space and the headings ``(count, 3)``."""
        xy = np.asarray(self._sample_free(self._rng, count), dtype=np.float64)
        if xy.shape != (count, 2):
            raise EstimationError(f"sample_free returned shape {xy.shape}, expected ({count}, 2)")
        theta = self._rng.uniform(-math.pi, math.pi, size=count)
        return np.column_stack([xy, theta])

    def global_localization(self) -> None:
        """The uniform prior: ``max_particles`` poses over the free space, equal weights."""
        self.set_particles(self.uniform_poses(self.settings.max_particles))
        self.w_slow = self.w_fast = 0.0

    # -- one scan ---------------------------------------------------------------------
    def update(self, odom_pose, readings_m) -> bool:
        """Feed the odometry pose ``(3,)`` and the scan ``readings_m (S,)`` (``inf``: no echo).

        The first call weights the prior by the scan without moving it; later calls update
        the filter only when the odometry moved more than ``update_min_d_m`` along x or y or
        turned more than ``update_min_a_rad`` since the last update (else nothing changes).
        Returns whether the filter was updated.
        """
        if len(self._particles) == 0:
            raise EstimationError(
                "MonteCarloLocalization.update: no particles (call global_localization)"
            )
        odom = np.asarray(odom_pose, dtype=np.float64)
        readings = np.ascontiguousarray(readings_m, dtype=np.float64)
        if odom.shape != (3,) or not np.isfinite(odom).all():
            raise EstimationError(
                f"MonteCarloLocalization.update: odom_pose must be 3 finite numbers, got {odom_pose!r}"
            )
        if readings.ndim != 1:
            raise EstimationError(
                f"MonteCarloLocalization.update: readings must be (S,), got {readings.shape}"
            )
        s = self.settings
        if self._odom_at_update is not None:
            delta = odom - self._odom_at_update
            moved = (
                abs(delta[0]) > s.update_min_d_m
                or abs(delta[1]) > s.update_min_d_m
                or abs(float(wrap_angle(delta[2]))) > s.update_min_a_rad
            )
            if not moved:
                return False
            normals = self._rng.standard_normal((len(self._particles), 3))
            self._particles = mcl_kernels.sample_motion_odometry(
                self._particles, self._odom_at_update, odom, s.alphas, normals
            )
        self._odom_at_update = odom.copy()
        self._weigh(readings)
        self.updates += 1
        self._updates_since_resample += 1
        if self._updates_since_resample >= s.resample_interval:
            self._resample()
            self._updates_since_resample = 0
        return True

    def _weigh(self, readings: np.ndarray) -> None:
        """Multiply the weights by the scan likelihood; update ``w_slow``, ``w_fast``."""
        s = self.settings
        expected = np.ascontiguousarray(self._expected_ranges(self._particles), dtype=np.float64)
        if expected.shape != (len(self._particles), len(readings)):
            raise EstimationError(
                f"expected_ranges returned {expected.shape}, expected "
                f"({len(self._particles)}, {len(readings)})"
            )
        log_p = mcl_kernels.beam_log_likelihoods(
            readings, expected, s.mixture, self._max_range_m, _COMBINATION_CODE[s.beam_combination]
        )
        with np.errstate(divide="ignore"):
            log_w = np.log(self._weights) + log_p  # log(w_prior p); w_prior 0 gives -inf
        top = np.max(log_w)
        if not np.isfinite(top):
            raise EstimationError(
                "MonteCarloLocalization.update: the scan has likelihood 0 (or NaN) at every "
                "particle; with z_rand > 0 every reading has a positive likelihood"
            )
        scaled = np.exp(log_w - top)
        total = scaled.sum()
        self._weights = scaled / total
        # average likelihood sum_i w_prior_i p_i (PR table 8.3, line 8), w_slow/w_fast (line 10)
        w_avg = math.exp(top) * total
        if s.recovery:  # from 0, as PR table 8.3 and pf.c: no injection until w_slow grows
            self.w_slow += s.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast += s.recovery_alpha_fast * (w_avg - self.w_fast)

    @property
    def random_share(self) -> float:
        """Share of random particles the next resampling injects, ``max(0, 1 - w_fast / w_slow)``."""
        if not self.settings.recovery or self.w_slow <= 0.0:
            return 0.0
        return max(0.0, 1.0 - self.w_fast / self.w_slow)

    def _resample(self) -> None:
        """KLD-sized systematic resampling with random-particle recovery (module docstring)."""
        s = self.settings
        # KLD: visit a systematic resample of max_particles in random order until the
        # histogram bound is met (each draw distributed as the weights)
        comb = mcl_kernels.systematic_indices(self._weights, s.max_particles, self._rng.random())
        draws = self._particles[comb[self._rng.permutation(s.max_particles)]]
        count = mcl_kernels.kld_sample_count(
            np.ascontiguousarray(draws),
            self._kld_origin,
            self._kld_cell,
            self._kld_shape,
            s.kld_err,
            s.kld_z,
            s.min_particles,
            s.max_particles,
        )
        share = self.random_share
        n_random = int(self._rng.binomial(count, share)) if share > 0 else 0
        kept = mcl_kernels.systematic_indices(self._weights, count - n_random, self._rng.random())
        new = self._particles[kept]
        if n_random:
            new = np.concatenate([new, self.uniform_poses(n_random)])
        self._particles = np.ascontiguousarray(new)
        self._weights = np.full(count, 1.0 / count)

    # -- the estimate -----------------------------------------------------------------
    def estimate(self) -> PoseEstimate:
        """Weighted mean and covariance of the particles (at the last filter update)."""
        mean, cov = mcl_kernels.weighted_pose_moments(self._particles, self._weights)
        return PoseEstimate(mean=mean, cov=cov)

    def pose_at(self, odom_pose) -> np.ndarray:
        """The estimate carried to odometry pose ``odom_pose (3,)`` by the odometry moved
        since the last update (what ``amcl`` publishes between updates through its
        map-to-odometry transform): ``estimate (+) (odom_at_update^-1 (+) odom_pose)``."""
        mean = self.estimate().mean
        if self._odom_at_update is None:
            return mean
        odom = np.asarray(odom_pose, dtype=np.float64)
        ref = self._odom_at_update
        dx, dy = odom[0] - ref[0], odom[1] - ref[1]
        c, s_ = math.cos(ref[2]), math.sin(ref[2])
        local_x, local_y = c * dx + s_ * dy, -s_ * dx + c * dy  # the increment in the old frame
        c, s_ = math.cos(mean[2]), math.sin(mean[2])
        return np.array(
            [
                mean[0] + c * local_x - s_ * local_y,
                mean[1] + s_ * local_x + c * local_y,
                float(wrap_angle(mean[2] + odom[2] - ref[2])),
            ]
        )

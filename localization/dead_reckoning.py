"""The robot's 100 Hz dead-reckoning filter (paper 002 section 2), nominal parameters only.

Two independent sources for the speed and the yaw rate (paper 002 section 2): the wheel
encoders (speed and yaw rate from the tick increments with the NOMINAL radius) and the IMU
(gyro yaw rate, accelerometer forward specific force).

State (``N_STATES = 8``, indices below; the pose first so that ``mean[..., :3]`` is the pose)::

    s = (x_m, y_m, theta_rad, v_m_s, omega_rad_s, b_gyro_rad_s, b_accel_m_s2, d_wheel)

- ``(x, y, theta)`` the pose, ``(v, omega)`` the body velocity;
- ``b_gyro``: the gyro bias. Its turn-on value (about 0.1 deg/s) alone turns the heading by
  6 degrees a minute, and it is observable from the encoder yaw rate;
- ``b_accel``: the forward accelerometer bias. It is 20 milli-g (0.2 m/s^2) at turn-on, so
  integrating the accelerometer without it is useless after a second; observable from the
  encoder speed;
- ``d_wheel = e_r - e_l``: the difference of the relative errors of the true wheel radii
  (``r = r_nominal (1 + e)``). It matters: with 1 % between the wheels the encoder yaw rate is
  off by ``v d / L`` (0.017 rad/s at 0.5 m/s, ten times the gyro bias), and without this state
  the filter would explain that error as gyro bias and turn the heading by a degree a second.
  It is separable from ``b_gyro`` because it scales with the speed.
  The common radius error ``(e_r + e_l) / 2`` (a scale of the distance, 0.1 % on the default
  robot) is not observable from these sensors: it is not modelled (the fusion corrects it).
  The lateral specific force ``a_y = v omega`` is not used: it adds nothing about ``v`` and
  ``omega`` that the gyro and encoders do not give, and would need its own bias state.

How each sensor enters (the sample ``k`` is at ``t_k = k dt``; the log's row ``k`` of
ticks counts the turn from ``k - 1`` to ``k``):

- The accelerometer is an INPUT of the speed, ``v(k) = v(k-1) + dt (a(k) - b_accel)`` with
  ``a(k)`` the mean of the readings at ``k - 1`` and ``k``: it measures the derivative of a
  state, and using it as an input spares an acceleration state with a guessed jerk noise.
  Its white noise is process noise of ``v``.
- The pose moves along the unicycle with the mid-step heading (second-order in ``dt``)::

      x(k) = x + dt v cos(theta + dt omega / 2),  y(k) = y + dt v sin(theta + dt omega / 2)
      theta(k) = theta + dt omega,  omega(k) = omega + w_omega  (random walk, the yaw
      acceleration as noise), biases and d_wheel: random walks / constant.

- The encoders and the gyro are MEASUREMENTS, ``z(k) = (v_enc, omega_enc, gyro)``::

      v_enc     = v - (L / 4) omega d_wheel           (first order in the radius errors)
      omega_enc = omega - (v / L) d_wheel
      gyro      = omega + b_gyro

  The products ``omega d_wheel`` and ``v d_wheel`` are taken with ESTIMATES made before the
  step's encoder data in place of ``omega`` and ``v`` (``measurement_matrix``): the
  predicted ``omega^-(k)``, and the speed predicted from two steps back, ``v^-(k)`` less the
  update's correction of ``v`` at ``k - 1`` (the neglected ``d (v - v^) / L`` is ~1e-5 rad/s),
  so the measurement is linear in the state with a matrix ``H(k)`` fixed before the update.
  For a linear ``h`` the unscented update IS the Kalman update (the unscented transform of a
  linear map is exact), so every filter of the family updates in closed form, and the
  iterated updates (IEKF, IUKF) converge at their first iteration: ``iekf`` equals ``ekf``
  and ``iukf`` equals ``ukf`` with its own sigma points.

  Why not the MEASURED encoder speed ``v_enc(k)`` (the first design): its quantisation error
  is made of the same two wheel errors as that of ``omega_enc(k)``, and the two wheels'
  quantisation variances differ (they turn at different tick rates: 0.107 and 0.156 tick^2 on
  the default ``hall`` run), so the regressor's noise correlates with the measurement's noise.
  At a cruise speed the speed barely varies (std 8.5 mm/s on ``hall``, against 3.9 mm/s of
  quantisation per sample), so ``b_gyro`` and ``d_wheel`` are separated only along
  ``gyro - omega_enc = b_gyro + v d_wheel / L`` and this correlation dragged them along the
  unobservable direction (``b_gyro`` to 0.0085 rad/s, ten times the truth, the heading off by
  a turn in 600 s). The prediction ``v^-(k)`` does not contain sample ``k``'s quantisation,
  but its correction at ``k - 1`` holds the remainder ``q(k-1)`` that the increment ``k``
  subtracts (``n(k) = q(k) - q(k-1)``: the increments' errors are anti-correlated), which
  still pulled ``b_gyro`` by -0.27 turn-on sigma against the true speed as regressor (600 s
  of ``hall``, 6 seeds); without that correction, by -0.09 sigma.

Noise: encoder quantisation gives each wheel's increment an error that is the difference of
two uniform tick fractions, standard deviation ``1 / sqrt(6)`` tick (treated as white: it is
in fact anti-correlated, so the filter is conservative about it); the IMU white noise has the
per-sample standard deviation ``density * sqrt(rate_hz)`` (docs/models.md section 2).

Speed: the generic filter classes (``localization.ukf``, ``iukf``, ``ekf``), step by step, take
190-380 us a step for the batch of two branches (``ekf`` .. ``iukf``; 16 s for 600 s of ``ukf``
at 100 Hz, against a budget of 6 s for the whole pipeline). :class:`DeadReckoning` therefore
runs a compiled step specialised to this model (:mod:`localization.compiled.dead_reckoning`,
numba), still the same filter: the unscented prediction with the same sigma points and moments
as the generic one (or the EKF prediction), and the closed-form update that equals the unscented
one for the linear ``h`` (``tests/localization/test_dead_reckoning.py`` checks it against the
generic filter classes, run by the reference
:class:`localization.reference.dead_reckoning.GenericDeadReckoning`: ~1e-13 for the EKF and the
kappa points; ~1e-8 over 300 steps for the scaled points, whose ``1 / gamma^2`` amplifies
rounding, as between any two implementations). One call runs a whole ``run()`` stretch, all
samples and all runs, and writes the history in place. Measured
(``benchmarks/dead_reckoning.py``, 600 s of ``hall``, batch of two): 3.3 us a step for
``ukf``/``iukf``, 1.9 us for ``ekf``, 80-115 times the generic filters; in the pipeline (600
calls) 0.23 s instead of 4.4 s. The first run on a machine compiles the kernel (about 3 s;
cached beside the module after that). The heading is kept unwrapped inside the loop (the model
is periodic in it) and wrapped in the history and the belief; sigma-point heading offsets are
wrapped as in the generic filter when the points are wide (``gamma >= 0.01``, e.g. the IUKF's
kappa points), and not for the scaled points (``gamma ~ 3e-3``), where that needs ``sigma_theta
< pi / gamma`` (1000 rad; checked)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from localization.compiled import dead_reckoning as kernel
from localization.compiled.dead_reckoning import N_STATES, THETA, run_steps
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import wrap_angle
from localization.sigma_points import KappaSigmaPoints, ScaledSigmaPoints, SigmaPointScheme
from validated_records import bounded, validate_fields

STATE_NAMES = (
    "x_m",
    "y_m",
    "theta_rad",
    "v_m_s",
    "omega_rad_s",
    "b_gyro_rad_s",
    "b_accel_m_s2",
    "d_wheel",
)
ANGLE_INDICES = (THETA,)
_G_M_S2 = 9.80665
_WRAP_GAMMA = 0.01  # sigma-point spread from which the compiled step wraps heading offsets


def _positive(owner: str, **values) -> None:
    for name, value in values.items():
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not (math.isfinite(value) and value > 0)
        ):
            raise EstimationError(
                f"{owner}: {name} must be a positive finite number, got {value!r}"
            )


@dataclass(frozen=True)
class NominalRobot:
    """What the estimator knows of the robot (never the true radii).

    Attributes:
        wheel_radius_m: nominal radius of both wheels.
        wheel_base_m: distance between the wheel contact points ``L``.
        ticks_per_rev: encoder ticks per wheel revolution.
    """

    wheel_radius_m: float = bounded(above=0.0)
    wheel_base_m: float = bounded(above=0.0)
    ticks_per_rev: int = bounded(minimum=1, integer=True)

    def __post_init__(self) -> None:
        validate_fields(self, EstimationError)

    @property
    def metres_per_tick(self) -> float:
        """Wheel travel of one tick with the nominal radius, m."""
        return 2.0 * math.pi * self.wheel_radius_m / self.ticks_per_rev


@dataclass(frozen=True)
class DeadReckoningNoise:
    """The filter's noise model (defaults: the simulator's default low-cost sensors).

    Attributes:
        tick_std: standard deviation of one wheel's tick increment per sample, ticks
            (quantisation: ``1 / sqrt(6)``; add slip here if the wheels slip).
        gyro_noise_density_rad_s_sqrt_hz: gyro white noise density.
        gyro_bias_std_rad_s: prior standard deviation of the gyro bias (turn-on).
        gyro_bias_random_walk_rad_s_sqrt_s: gyro bias random walk.
        accel_noise_density_m_s2_sqrt_hz: forward accelerometer white noise density.
        accel_bias_std_m_s2: prior standard deviation of the accelerometer bias (turn-on).
        accel_bias_random_walk_m_s2_sqrt_s: accelerometer bias random walk.
        wheel_radius_rel_std: prior standard deviation of each wheel's relative radius error
            (``d_wheel`` gets ``sqrt(2)`` times it).
        yaw_accel_std_rad_s2: standard deviation of the yaw acceleration driving ``omega``
            (the robot's ``alpha_max`` is a safe value).
        position_std_m_sqrt_s, heading_std_rad_sqrt_s: model error of the pose kinematics
            (small; keeps the pose covariance positive definite).
    """

    tick_std: float = bounded(1.0 / math.sqrt(6.0), above=0.0)
    gyro_noise_density_rad_s_sqrt_hz: float = bounded(math.radians(0.005), above=0.0)
    gyro_bias_std_rad_s: float = bounded(math.radians(0.1), above=0.0)
    gyro_bias_random_walk_rad_s_sqrt_s: float = bounded(math.radians(0.002), above=0.0)
    accel_noise_density_m_s2_sqrt_hz: float = bounded(400e-6 * _G_M_S2, above=0.0)
    accel_bias_std_m_s2: float = bounded(20e-3 * _G_M_S2, above=0.0)
    accel_bias_random_walk_m_s2_sqrt_s: float = bounded(0.05e-3 * _G_M_S2, above=0.0)
    wheel_radius_rel_std: float = bounded(0.01, above=0.0)
    yaw_accel_std_rad_s2: float = bounded(2.0 * 0.5 / 0.30, above=0.0)
    position_std_m_sqrt_s: float = bounded(1e-4, above=0.0)
    heading_std_rad_sqrt_s: float = bounded(1e-4, above=0.0)

    def __post_init__(self) -> None:
        validate_fields(self, EstimationError)

    def process_cov(self, dt_s: float) -> np.ndarray:
        """``Q (8, 8)``, diagonal, of one step of ``dt_s`` seconds."""
        accel_std = self.accel_noise_density_m_s2_sqrt_hz / math.sqrt(dt_s)  # per sample
        return np.diag(
            [
                self.position_std_m_sqrt_s**2 * dt_s,
                self.position_std_m_sqrt_s**2 * dt_s,
                self.heading_std_rad_sqrt_s**2 * dt_s,
                (accel_std * dt_s) ** 2,
                (self.yaw_accel_std_rad_s2 * dt_s) ** 2,
                self.gyro_bias_random_walk_rad_s_sqrt_s**2 * dt_s,
                self.accel_bias_random_walk_m_s2_sqrt_s**2 * dt_s,
                1e-12 * dt_s,  # the radii are constant; a trace of noise keeps the filter awake
            ]
        )

    def measurement_cov(self, robot: NominalRobot, dt_s: float) -> np.ndarray:
        """``R (3, 3)`` of ``(v_enc, omega_enc, gyro)``: the wheels' errors are independent,
        so the speed (their mean) and the yaw rate (their difference) are uncorrelated."""
        wheel_std = self.tick_std * robot.metres_per_tick / dt_s  # one wheel's rim speed, m/s
        gyro_std = self.gyro_noise_density_rad_s_sqrt_hz / math.sqrt(dt_s)
        return np.diag(
            [0.5 * wheel_std**2, 2.0 * wheel_std**2 / robot.wheel_base_m**2, gyro_std**2]
        )

    def prior_std(self) -> np.ndarray:
        """``(5,)`` prior standard deviations of the sensor states
        ``(b_gyro, b_accel, d_wheel)`` preceded by those of ``(v, omega)`` at rest (small)."""
        return np.array(
            [
                1e-3,
                1e-3,
                self.gyro_bias_std_rad_s,
                self.accel_bias_std_m_s2,
                math.sqrt(2.0) * self.wheel_radius_rel_std,
            ]
        )


def initial_belief(
    pose, pose_std, noise: DeadReckoningNoise = DeadReckoningNoise(), batch: int | None = 2
) -> Gaussian:
    """The starting belief: the robot at rest at ``pose (3,)`` with standard deviations
    ``pose_std (3,)`` (m, m, rad), sensor states at their priors; ``batch`` copies (default 2:
    the UKF-only and the fused branch), ``None`` for one unbatched belief."""
    pose = np.asarray(pose, dtype=float)
    pose_std = np.asarray(pose_std, dtype=float)
    if (
        pose.shape != (3,)
        or pose_std.shape != (3,)
        or not (np.isfinite(pose).all() and (pose_std > 0).all())
    ):
        raise EstimationError(
            f"initial_belief: pose and pose_std must be finite (3,) arrays, pose_std > 0; "
            f"got {pose!r}, {pose_std!r}"
        )
    mean = np.concatenate([pose, np.zeros(5)])
    cov = np.diag(np.concatenate([pose_std, noise.prior_std()]) ** 2)
    if batch is not None:
        mean, cov = (
            np.broadcast_to(mean, (batch, N_STATES)),
            np.broadcast_to(cov, (batch, N_STATES, N_STATES)),
        )
    return Gaussian(mean, cov, ANGLE_INDICES)


# --------------------------------------------------------------------------- the models


def transition(state: np.ndarray, accel_m_s2, dt_s: float) -> np.ndarray:
    """``f(s) (..., 8)``: one step of ``dt_s`` with the forward accelerometer input
    ``accel_m_s2`` (broadcast against ``state[..., 0]``); see the module docstring (the kernel
    :func:`localization.compiled.dead_reckoning.transition` per state)."""
    state = np.asarray(state, dtype=float)
    shape = np.broadcast_shapes(state.shape[:-1], np.shape(accel_m_s2))
    rows = np.array(np.broadcast_to(state, shape + (N_STATES,)), order="C").reshape(-1, N_STATES)
    accel = np.array(np.broadcast_to(accel_m_s2, shape), dtype=np.float64, order="C").reshape(-1)
    out = np.empty_like(rows)
    kernel.transition_rows(rows, accel, float(dt_s), out)
    return out.reshape(shape + (N_STATES,))


def transition_jacobian(state: np.ndarray, accel_m_s2, dt_s: float) -> np.ndarray:
    """``df/ds (..., 8, 8)`` (:func:`localization.compiled.dead_reckoning.transition_jacobian`
    per state; ``accel_m_s2`` does not enter it)."""
    state = np.asarray(state, dtype=float)
    rows = np.array(state, dtype=np.float64, order="C").reshape(-1, N_STATES)
    out = np.empty((rows.shape[0], N_STATES, N_STATES))
    kernel.jacobian_rows(rows, float(dt_s), out)
    return out.reshape(state.shape[:-1] + (N_STATES, N_STATES))


@dataclass(frozen=True, eq=False)
class OdometryData:
    """The sensor arrays turned into the filter's per-sample inputs (one vectorised pass).

    Attributes (``N`` samples; a batch axis ``B`` after the time axis when the runs have
    their own data, none when all batch rows share the data):
        dt_s: sample period.
        accel_input_m_s2: ``(N,)`` or ``(N, B)`` forward accelerometer input of the step
            ending at ``k`` (mean of readings ``k - 1`` and ``k``; row 0 unused).
        z: ``(N, [B,] 3)`` measurements ``(v_enc_m_s, omega_enc_rad_s, gyro_rad_s)``.
        wheel_base_m: ``L``, for the measurement matrices ``H(k)``.
        R: ``(3, 3)`` measurement noise; Q: ``(8, 8)`` process noise per step.
    """

    dt_s: float
    accel_input_m_s2: np.ndarray
    z: np.ndarray
    wheel_base_m: float
    R: np.ndarray
    Q: np.ndarray

    @property
    def count(self) -> int:
        """Number of samples ``N``."""
        return self.z.shape[0]

    @property
    def per_run(self) -> bool:
        """True when the data carry a batch axis ``(N, B, ...)``."""
        return self.z.ndim == 3


def odometry_data(
    ticks,
    gyro_rad_s,
    accel_m_s2,
    dt_s: float,
    robot: NominalRobot,
    noise: DeadReckoningNoise = DeadReckoningNoise(),
) -> OdometryData:
    """The per-sample inputs from the raw sensor arrays.

    Args:
        ticks: ``(N, 2)`` or ``(N, B, 2)`` integer tick increments (left, right); row 0 unused.
        gyro_rad_s: ``(N,)`` or ``(N, B)`` yaw-rate readings.
        accel_m_s2: ``(N, 2)`` or ``(N, B, 2)`` specific force (body x, y); only x is used.
        dt_s: sample period (``1 / rate_hz``).
        robot: the nominal parameters; noise: the noise model.

    Raises:
        EstimationError: shapes that do not agree, a non-finite reading (naming the array and
            the first bad sample), a bad ``dt_s``.
    """
    accel_input, z = odometry_inputs(ticks, gyro_rad_s, accel_m_s2, dt_s, robot)
    return OdometryData(
        dt_s,
        accel_input,
        z,
        robot.wheel_base_m,
        noise.measurement_cov(robot, dt_s),
        noise.process_cov(dt_s),
    )


def odometry_inputs(
    ticks, gyro_rad_s, accel_m_s2, dt_s: float, robot: NominalRobot
) -> tuple[np.ndarray, np.ndarray]:
    """The per-sample inputs of :func:`odometry_data` without the noise model (the online
    localiser's stretches, appended to the data it started with): the forward acceleration
    input ``(N,)`` or ``(N, B)`` and the measurements ``z (N, 3)`` or ``(N, B, 3)``.

    Raises:
        EstimationError: as :func:`odometry_data`.
    """
    _positive("odometry_data", dt_s=dt_s)
    ticks = np.asarray(ticks)
    gyro = np.asarray(gyro_rad_s, dtype=float)
    accel = np.asarray(accel_m_s2, dtype=float)
    if ticks.ndim not in (2, 3) or ticks.shape[-1] != 2 or ticks.shape[0] < 1:
        raise EstimationError(
            f"odometry_data: ticks must have shape (N, 2) or (N, B, 2), got {ticks.shape}"
        )
    lead = ticks.shape[:-1]
    if gyro.shape != lead or accel.shape != lead + (2,):
        raise EstimationError(
            f"odometry_data: gyro {gyro.shape} and accel {accel.shape} must be {lead} and {lead + (2,)} "
            f"to match ticks {ticks.shape}"
        )
    for name, values in (("ticks", ticks), ("gyro_rad_s", gyro), ("accel_m_s2", accel)):
        if values.dtype.kind not in "iub" and not np.isfinite(values).all():  # integers: finite
            bad = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)
            raise EstimationError(
                f"odometry_data: {name} is not finite at sample {int(np.argmax(bad))}"
            )
    rim = ticks.astype(float) * (robot.metres_per_tick / dt_s)  # wheel rim speeds, m/s
    z = np.empty(lead + (3,))
    z[..., 0] = 0.5 * (rim[..., 0] + rim[..., 1])  # v_enc
    z[..., 1] = (rim[..., 1] - rim[..., 0]) / robot.wheel_base_m  # omega_enc
    z[..., 2] = gyro
    forward = accel[..., 0]
    accel_input = forward.copy()
    accel_input[1:] = 0.5 * (forward[1:] + forward[:-1])
    return accel_input, z


# --------------------------------------------------------------------------- the filters


class Filter(StrEnum):
    """The filter running the dead reckoning (the scenario's ``estimation.filter``)."""

    UKF = "ukf"
    """Unscented Kalman filter (scaled sigma points ``alpha = 1e-3`` by default)."""
    IUKF = "iukf"
    """Iterated UKF (paper 000; kappa sigma points by default)."""
    EKF = "ekf"
    """Extended Kalman filter."""
    IEKF = "iekf"
    """Iterated EKF."""

    @property
    def unscented(self) -> bool:
        """True for the UKF and IUKF (unscented prediction)."""
        return self in (Filter.UKF, Filter.IUKF)


@dataclass(frozen=True)
class DeadReckoningSettings:
    """Which filter runs the dead reckoning, and how (validated at construction).

    Attributes:
        filter: a :class:`Filter` (or its value; the scenario's ``estimation.filter``).
        points: sigma points of the unscented filters; ``None`` takes each filter's default
            (scaled points ``alpha = 1e-3`` for the UKF, kappa points for the IUKF, paper 000).
    """

    filter: Filter = Filter.UKF
    points: SigmaPointScheme | None = None

    def __post_init__(self) -> None:
        validate_fields(self, EstimationError)
        if self.points is not None and not isinstance(self.points, SigmaPointScheme):
            raise EstimationError(
                f"DeadReckoningSettings.points must be a sigma-point scheme or None, got {self.points!r}"
            )

    @property
    def unscented(self) -> bool:
        """True for the UKF and IUKF (unscented prediction)."""
        return self.filter.unscented

    def sigma_points(self) -> SigmaPointScheme:
        """The sigma-point scheme in use (unscented filters)."""
        if self.points is not None:
            return self.points
        return KappaSigmaPoints() if self.filter == Filter.IUKF else ScaledSigmaPoints(alpha=1e-3)


@dataclass(frozen=True, eq=False)
class DeadReckoningHistory:
    """What a run recorded, rows ``0..count-1`` (row ``k`` = the belief at sample ``k``
    after its update and after any replacement at ``k``).

    Attributes:
        mean: ``(count, B, 8)`` state means (heading wrapped).
        cov: ``(count, B, c, c)`` the covariance of the first ``c`` states: ``c = 3`` (the
            pose, default) or ``c = 8`` (the whole state, ``record_full_cov=True``).
        nis: ``(count, B)`` the normalised innovation squared ``nu^T S^-1 nu`` of the
            measurement update at each sample (3 degrees of freedom: ``v_enc``, ``omega_enc``,
            gyro); NaN at sample 0 (the initial belief, no update).
    """

    mean: np.ndarray
    cov: np.ndarray
    nis: np.ndarray

    @property
    def pose_cov(self) -> np.ndarray:
        """``(count, B, 3, 3)`` covariance of ``(x, y, theta)``."""
        return self.cov[..., :3, :3]


class DeadReckoning:
    """Runs the filter over whole sensor arrays, one batched belief ``(B, 8)``.

    Typical pipeline use: row 0 the UKF-only branch, row 1 the fused one, on the same data::

        dr = DeadReckoning(data, initial_belief(start, std))
        for k in epochs:
            belief = dr.run(k)                           # advance to sample k
            fused, report = fuse(belief, boxes, labels, rows=[1])
            dr.replace(fused)                            # or leave it
        dr.run(data.count - 1)
        history = dr.history                         # preallocated, filled in place

    Args:
        data: from :func:`odometry_data`; initial: the belief ``(B, 8)`` at sample 0.
        settings: the filter.
        record_full_cov: record the whole ``(8, 8)`` covariance per sample, not only the
            pose block (memory: ``N B 512`` bytes).

    Attributes:
        index: the sample of the current belief (starts at 0, the initial belief).
    """

    def __init__(
        self,
        data: OdometryData,
        initial: Gaussian,
        settings: DeadReckoningSettings = DeadReckoningSettings(),
        record_full_cov: bool = False,
    ) -> None:
        if not isinstance(initial, Gaussian) or initial.mean.ndim != 2 or initial.dim != N_STATES:
            raise EstimationError(
                f"DeadReckoning: initial must be a batched Gaussian (B, {N_STATES})"
            )
        if initial.angle_indices != ANGLE_INDICES:
            raise EstimationError(
                f"DeadReckoning: initial must declare angle_indices {ANGLE_INDICES}"
            )
        batch = initial.mean.shape[0]
        if data.per_run and data.z.shape[1] != batch:
            raise EstimationError(
                f"DeadReckoning: the data hold {data.z.shape[1]} runs, the belief {batch}"
            )
        self._data = data
        self._count = data.count  # samples held (the buffers may hold more rows)
        self.settings = settings
        self.index = 0
        count = data.count
        self._mean_hist = np.empty((count, batch, N_STATES))
        recorded = N_STATES if record_full_cov else 3
        self._cov_hist = np.empty((count, batch, recorded, recorded))
        self._nis_hist = np.full((count, batch), np.nan)
        self._mean = np.array(initial.mean)
        self._cov = np.array(initial.cov)
        self._record(0)
        self._buffers: tuple[np.ndarray, np.ndarray] | None = None  # (accel, z) grown by extend
        self._speed_correction = np.zeros(batch)  # the last update's correction of v, m/s
        self._compiled = _CompiledStep(data, settings)

    @property
    def data(self) -> OdometryData:
        """The per-sample inputs so far (views of the buffers :meth:`extend` grows)."""
        if self._data.count != self._count:
            accel, z = self._buffers  # type: ignore[misc]
            self._data = dataclasses.replace(
                self._data, accel_input_m_s2=accel[: self._count], z=z[: self._count]
            )
        return self._data

    @property
    def count(self) -> int:
        """Number of samples held (``data.count``)."""
        return self._count

    @property
    def belief(self) -> Gaussian:
        """The current belief (a copy; heading wrapped)."""
        mean = self._mean.copy()
        mean[:, THETA] = wrap_angle(mean[:, THETA])
        return Gaussian.trusted(mean, 0.5 * (self._cov + self._cov.mT), ANGLE_INDICES)

    @property
    def history(self) -> DeadReckoningHistory:
        """Rows ``0..index`` of the recorded history (views of the preallocated arrays)."""
        end = self.index + 1
        return DeadReckoningHistory(
            self._mean_hist[:end], self._cov_hist[:end], self._nis_hist[:end]
        )

    def replace(self, belief: Gaussian) -> None:
        """Replace the current belief (e.g. by the fused one) and re-record the current row.

        Raises:
            EstimationError: a belief of another shape or with non-finite values.
        """
        if (
            not isinstance(belief, Gaussian)
            or belief.mean.shape != self._mean.shape
            or belief.angle_indices != ANGLE_INDICES
        ):
            raise EstimationError(
                f"DeadReckoning.replace: the belief must be a Gaussian {self._mean.shape}"
            )
        if not (np.isfinite(belief.mean).all() and np.isfinite(belief.cov).all()):
            raise EstimationError("DeadReckoning.replace: the belief is not finite")
        self._mean = np.array(belief.mean)
        self._cov = np.array(belief.cov)
        self._record(self.index)

    def extend(self, more: OdometryData) -> None:
        """Append the samples of ``more`` after the data's last (the online localiser's data
        arrive stretch by stretch). The arrays grow by doubling, so appending ``N`` samples in
        any number of stretches costs ``O(N)``; the filter and the history are unchanged.

        Raises:
            EstimationError: data with another period, wheel base, noise or batch layout.
        """
        data = self.data
        if (
            more.dt_s != data.dt_s
            or more.wheel_base_m != data.wheel_base_m
            or more.z.shape[1:] != data.z.shape[1:]
            or not (np.array_equal(more.R, data.R) and np.array_equal(more.Q, data.Q))
        ):
            raise EstimationError(
                "DeadReckoning.extend: the samples must have the period, wheel base, noise and "
                "batch layout of the data"
            )
        self.append_inputs(more.accel_input_m_s2, more.z)

    def append_inputs(self, accel_input_m_s2: np.ndarray, z: np.ndarray) -> None:
        """Append per-sample inputs ``(n, ...)`` of the data's own model (from
        :func:`odometry_inputs` with the data's robot and period; :meth:`extend` checks the
        model, this does not: the online localiser's stretches of one run)."""
        old, new = self._count, self._count + z.shape[0]
        if self._buffers is None or new > self._buffers[0].shape[0]:
            data = self.data
            capacity = max(new, 2 * old)
            accel_rows, z_rows = (
                np.empty((capacity,) + data.accel_input_m_s2.shape[1:]),
                np.empty((capacity,) + data.z.shape[1:]),
            )
            accel_rows[:old], z_rows[:old] = data.accel_input_m_s2, data.z
            self._buffers = (accel_rows, z_rows)
            self._mean_hist = _grown(self._mean_hist, capacity)
            self._cov_hist = _grown(self._cov_hist, capacity)
            self._nis_hist = _grown(self._nis_hist, capacity)
            self._compiled.bind_rows(accel_rows, z_rows)  # views of the buffers, not copies
        accel_rows, z_rows = self._buffers
        accel_rows[old:new], z_rows[old:new] = accel_input_m_s2, z
        self._count = new

    def run(self, until_index: int) -> Gaussian:
        """Advance to sample ``until_index`` (inclusive) and return the belief there.

        Raises:
            EstimationError: an index behind the current one or past the data; a heading
                too uncertain for the compiled step's scaled points; a covariance (or, in the
                compiled step, an innovation covariance) that stops being positive definite
                (from the Cholesky factorisation). The belief and ``index`` then stay where
                they were.
        """
        self.advance(until_index)
        return self.belief

    def advance(self, until_index: int) -> None:
        """:meth:`run` without building the belief (read it with :meth:`mean_pose`)."""
        if not (self.index <= until_index < self._count):
            raise EstimationError(
                f"DeadReckoning.run: until_index must be in [{self.index}, {self._count - 1}], got {until_index}"
            )
        start = self.index + 1
        if until_index >= start:
            self._steps(start, until_index + 1)
            self.index = until_index

    def mean_pose(self, row: int) -> tuple[float, float, float]:
        """The current mean ``(x_m, y_m, theta_rad)`` of batch row ``row``, heading wrapped:
        ``belief.mean[row, :3]`` without building the belief."""
        theta = wrap_angle(self._mean[:, THETA])  # the whole column, as :attr:`belief` wraps it
        x, y = self._mean[row, :2].tolist()
        return x, y, float(theta[row])

    def _steps(self, start: int, stop: int) -> None:
        """Samples ``start..stop-1`` from the current belief, recorded (the compiled step)."""
        self._mean, self._cov, self._speed_correction = self._compiled.run(
            self._mean,
            self._cov,
            self._speed_correction,
            start,
            stop,
            self._mean_hist,
            self._cov_hist,
            self._nis_hist,
        )

    def _record(self, k: int) -> None:
        self._mean_hist[k] = self._mean
        self._mean_hist[k, :, THETA] = wrap_angle(self._mean[:, THETA])
        recorded = self._cov_hist.shape[-1]
        self._cov_hist[k] = self._cov[:, :recorded, :recorded]


def _compiled_input(values) -> np.ndarray:
    """``values`` as a writable C-contiguous float64 array (a read-only array would be a
    second signature to compile); the array itself when it already is one."""
    return np.require(values, dtype=float, requirements=("C", "W"))


def _grown(values: np.ndarray, capacity: int) -> np.ndarray:
    """``values`` copied into the first rows of an array of ``capacity`` rows."""
    out = np.empty((capacity,) + values.shape[1:], dtype=values.dtype)
    out[: values.shape[0]] = values
    return out


class _CompiledStep:
    """The arguments of :func:`~localization.compiled.dead_reckoning.run_steps` that stay fixed
    over a run (contiguous float64 arrays, one compiled signature), and the checks around it.

    The unscented filters pass their sigma points' ``gamma``, ``W_i = 1 / (2 gamma^2)`` and
    ``c0``; heading offsets are wrapped (as in the generic filter) when the points are wide
    (``gamma >= 0.01``, e.g. the IUKF's kappa points) and not for the scaled points
    (``gamma ~ 3e-3``), which needs ``gamma sigma_theta < pi``, checked after each stretch.
    """

    def __init__(self, data: OdometryData, settings: DeadReckoningSettings) -> None:
        self.bind(data)
        self.q_cov, self.r_cov = _compiled_input(data.Q), _compiled_input(data.R)
        self.dt_s = float(data.dt_s)
        self.wheel_base_m = float(data.wheel_base_m)
        self.unscented = settings.unscented
        if self.unscented:
            weights = settings.sigma_points().weights(N_STATES)
            self.gamma, self.weight, self.c0 = (
                float(weights.gamma),
                float(weights.wi),
                float(weights.c0),
            )
        else:
            self.gamma = self.weight = self.c0 = 0.0
        self.wrap_offsets = self.gamma >= _WRAP_GAMMA

    def bind(self, data: OdometryData) -> None:
        """Take the per-sample inputs of ``data`` (the same model: :meth:`DeadReckoning.extend`)."""
        self.bind_rows(data.accel_input_m_s2, data.z)

    def bind_rows(self, accel_input_m_s2: np.ndarray, z: np.ndarray) -> None:
        """Take per-sample input rows (possibly more than the data hold: the steps read the
        rows they run only)."""
        count = z.shape[0]
        self.accel = _compiled_input(accel_input_m_s2).reshape(count, -1)  # (N, B|1)
        self.z = _compiled_input(z).reshape(count, -1, 3)  # (N, B|1, 3)

    def run(self, mean, cov, speed_correction, start, stop, mean_hist, cov_hist, nis_hist):
        """Samples ``start..stop-1`` from the belief ``mean (B, 8)``, ``cov (B, 8, 8)`` at
        ``start - 1`` (left unchanged); records rows ``start..stop-1`` of the history arrays
        and returns the new ``(mean, cov, speed_correction)``."""
        mean, cov, speed_correction = mean.copy(), cov.copy(), speed_correction.copy()
        failed = run_steps(
            mean,
            cov,
            speed_correction,
            start,
            stop,
            self.accel,
            self.z,
            self.q_cov,
            self.r_cov,
            self.dt_s,
            self.wheel_base_m,
            self.unscented,
            self.gamma,
            self.weight,
            self.c0,
            self.wrap_offsets,
            mean_hist,
            cov_hist,
            nis_hist,
        )
        if failed >= 0:
            raise EstimationError(
                f"dead reckoning: at sample {failed} the covariance is not positive definite or the mean not finite"
            )
        if (
            self.unscented
            and not self.wrap_offsets
            and (self.gamma**2 * cov[:, THETA, THETA]).max() >= math.pi**2
        ):
            raise EstimationError(
                "dead reckoning: the heading is too uncertain for the scaled sigma points (gamma * sigma_theta >= pi); "
                "use sigma points with gamma >= 0.01 (e.g. the IUKF's kappa points)"
            )
        return mean, cov, speed_correction


def run_dead_reckoning(
    data: OdometryData,
    initial: Gaussian,
    settings: DeadReckoningSettings = DeadReckoningSettings(),
    epochs=(),
    on_epoch=None,
    record_full_cov: bool = False,
) -> DeadReckoningHistory:
    """Run the filter over all samples of ``data``.

    Args:
        data: from :func:`odometry_data`; initial: the belief ``(B, 8)`` at sample 0.
        settings: the filter.
        epochs: increasing sample indices where ``on_epoch(index, belief) -> Gaussian | None``
            is called; a returned belief replaces the current one (the fusion).
        record_full_cov: see :class:`DeadReckoning`.

    Returns:
        The history of all ``N`` samples.
    """
    runner = DeadReckoning(data, initial, settings, record_full_cov)
    for index in epochs:
        belief = runner.run(int(index))
        if on_epoch is not None:
            replacement = on_epoch(int(index), belief)
            if replacement is not None:
                runner.replace(replacement)
    runner.run(data.count - 1)
    return runner.history

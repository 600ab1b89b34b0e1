"""Compiled (numba) kernels of the particle filter in :mod:`localization.mcl`.

Each kernel takes arrays and scalars and loops over the particles in machine code; the
random numbers are drawn by the caller's ``numpy.random.Generator`` and passed in, so a run
is reproducible from its seed whatever numba's own generator does. Shapes: ``N`` particles,
``S`` sonar readings; poses are ``(x_m, y_m, theta_rad)``. All arrays float64 (the bin
indices int64), C-contiguous. The kernels use nothing from other files, so numba's disk
cache (keyed on this file) cannot serve stale code.

References: Thrun, Burgard, Fox, *Probabilistic Robotics* (2005), "PR" below: table 5.6
(sample_motion_model_odometry), table 6.1 and eq. 6.4-6.13 (beam model), table 4.4
(low-variance sampler); Fox, "Adapting the sample size in particle filters through
KLD-sampling", IJRR 22(12), 2003 (eq. 8); and ROS ``amcl`` (``amcl_odom.cpp``,
``amcl_laser.cpp``, ``pf.c``) for the conventions its users know.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: Translations below this (m) leave ``rot1`` at 0: the bearing of a tiny step is noise
#: (``amcl_odom.cpp`` uses the same 1 cm).
MIN_TRANSLATION_FOR_BEARING_M = 0.01

#: Beam combinations (the codes of :class:`localization.mcl.BeamCombination`).
COMBINE_PRODUCT = 0
COMBINE_AMCL_CUBE = 1


@numba.njit(cache=True)
def wrap(angle_rad: float) -> float:
    """``angle_rad`` wrapped to ``[-pi, pi)``."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@numba.njit(cache=True)
def odometry_increment(old_pose: np.ndarray, new_pose: np.ndarray) -> tuple[float, float, float]:
    """``(rot1, trans, rot2)`` between two odometry poses (PR table 5.6, lines 2-4)::

    rot1 = atan2(y' - y, x' - x) - theta,  trans = |(x', y') - (x, y)|,
    rot2 = theta' - theta - rot1            (angles wrapped; rot1 = 0 for trans < 1 cm)
    """
    dx = new_pose[0] - old_pose[0]
    dy = new_pose[1] - old_pose[1]
    trans = math.hypot(dx, dy)
    rot1 = 0.0
    if trans >= MIN_TRANSLATION_FOR_BEARING_M:
        rot1 = wrap(math.atan2(dy, dx) - old_pose[2])
    rot2 = wrap(wrap(new_pose[2] - old_pose[2]) - rot1)
    return rot1, trans, rot2


@numba.njit(cache=True)
def motion_std(
    rot1: float, trans: float, rot2: float, alphas: np.ndarray
) -> tuple[float, float, float]:
    """Standard deviations of the noise on ``(rot1, trans, rot2)`` (PR table 5.6, lines 5-7)::

    var_rot1  = a1 r1^2 + a2 t^2
    var_trans = a3 t^2 + a4 (r1^2 + r2^2)
    var_rot2  = a1 r2^2 + a2 t^2

    with, as ``amcl_odom.cpp``, each rotation taken modulo a half turn (``min(|r|, pi - |r|)``)
    so that driving backwards is not read as two half turns.
    """
    r1 = min(abs(rot1), math.pi - abs(rot1))
    r2 = min(abs(rot2), math.pi - abs(rot2))
    a1, a2, a3, a4 = alphas[0], alphas[1], alphas[2], alphas[3]
    return (
        math.sqrt(a1 * r1 * r1 + a2 * trans * trans),
        math.sqrt(a3 * trans * trans + a4 * (r1 * r1 + r2 * r2)),
        math.sqrt(a1 * r2 * r2 + a2 * trans * trans),
    )


@numba.njit(cache=True)
def sample_motion_odometry(
    particles: np.ndarray,
    old_odom: np.ndarray,
    new_odom: np.ndarray,
    alphas: np.ndarray,
    normals: np.ndarray,
) -> np.ndarray:
    """Particles ``(N, 3)`` moved by the odometry step ``old_odom -> new_odom`` ``(3,)``.

    PR table 5.6 with the standard normal draws ``normals (N, 3)``::

        r1^ = r1 - s_r1 n0,  t^ = t - s_t n1,  r2^ = r2 - s_r2 n2
        x' = x + t^ cos(theta + r1^),  y' = y + t^ sin(theta + r1^),
        theta' = wrap(theta + r1^ + r2^)

    ``alphas (4,)``: ``alpha1..alpha4`` (rad^2/rad^2, rad^2/m^2, m^2/m^2, m^2/rad^2).
    """
    rot1, trans, rot2 = odometry_increment(old_odom, new_odom)
    s_rot1, s_trans, s_rot2 = motion_std(rot1, trans, rot2, alphas)
    out = np.empty_like(particles)
    for i in range(particles.shape[0]):
        r1 = rot1 - s_rot1 * normals[i, 0]
        t = trans - s_trans * normals[i, 1]
        r2 = rot2 - s_rot2 * normals[i, 2]
        heading = particles[i, 2] + r1
        out[i, 0] = particles[i, 0] + t * math.cos(heading)
        out[i, 1] = particles[i, 1] + t * math.sin(heading)
        out[i, 2] = wrap(heading + r2)
    return out


@numba.njit(cache=True)
def beam_likelihood(
    observed_m: float,
    expected_m: float,
    z_hit: float,
    z_short: float,
    z_max: float,
    z_rand: float,
    sigma_hit_m: float,
    lambda_short_per_m: float,
    max_range_m: float,
) -> float:
    """One beam's mixture ``p(z | z*)`` as ``amcl_laser.cpp``'s beam model (PR eq. 6.4-6.12).

    ``observed_m`` and ``expected_m`` already limited to ``[0, max_range_m]``::

        p = z_hit exp(-(z - z*)^2 / (2 sigma_hit^2))                    (unnormalised, as AMCL)
          + z_short lambda_short exp(-lambda_short z)      if z < z*
          + z_max                                          if z >= max_range
          + z_rand / max_range                             if z < max_range
    """
    gap = observed_m - expected_m
    p = z_hit * math.exp(-(gap * gap) / (2.0 * sigma_hit_m * sigma_hit_m))
    if observed_m < expected_m:
        p += z_short * lambda_short_per_m * math.exp(-lambda_short_per_m * observed_m)
    if observed_m >= max_range_m:
        p += z_max
    else:
        p += z_rand / max_range_m
    return p


@numba.njit(cache=True)
def beam_log_likelihoods(
    observed_m: np.ndarray,
    expected_m: np.ndarray,
    mixture: np.ndarray,
    max_range_m: float,
    combination: int,
) -> np.ndarray:
    """Log-likelihood ``(N,)`` of a scan ``observed_m (S,)`` for each particle's expected
    ranges ``expected_m (N, S)``.

    Ranges are limited to ``[0, max_range_m]`` first (no echo, ``inf``, and anything beyond
    counts as a max-range reading; a cone that meets no wall expects max range); a NaN
    reading is skipped. ``mixture = (z_hit, z_short, z_max, z_rand, sigma_hit_m,
    lambda_short_per_m)``. ``combination``: :data:`COMBINE_PRODUCT`, ``log p = sum_s log p_s``
    (the beams independent, PR table 6.1), or :data:`COMBINE_AMCL_CUBE`,
    ``p = 1 + sum_s p_s^3`` (``amcl_laser.cpp``'s ad-hoc damping of dependent beams).
    """
    n, s = expected_m.shape
    z_hit, z_short, z_max, z_rand = mixture[0], mixture[1], mixture[2], mixture[3]
    sigma_hit, lambda_short = mixture[4], mixture[5]
    out = np.empty(n)
    for i in range(n):
        total = 0.0 if combination == COMBINE_PRODUCT else 1.0
        for j in range(s):
            z = observed_m[j]
            if math.isnan(z):
                continue
            z = min(max(z, 0.0), max_range_m)
            expected = min(max(expected_m[i, j], 0.0), max_range_m)
            p = beam_likelihood(
                z, expected, z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short, max_range_m
            )
            if combination == COMBINE_PRODUCT:
                total += math.log(p)
            else:
                total += p * p * p
        out[i] = total if combination == COMBINE_PRODUCT else math.log(total)
    return out


@numba.njit(cache=True)
def systematic_indices(weights: np.ndarray, count: int, offset: float) -> np.ndarray:
    """Low-variance resampling (PR table 4.4): ``count`` indices into ``weights (N,)``
    (normalised, non-negative) picked by the comb ``u_j = (offset + j) / count``,
    ``j = 0..count-1``, ``offset`` in ``[0, 1)``: index ``i`` is taken once per tooth in
    ``[C_{i-1}, C_i)`` (``C`` the cumulative weights), so ``floor(count w_i)`` or
    ``ceil(count w_i)`` times. Sorted ascending.
    """
    n = weights.shape[0]
    out = np.empty(count, dtype=np.int64)
    i = 0
    cumulative = weights[0]
    for j in range(count):
        u = (offset + j) / count
        while u >= cumulative and i < n - 1:
            i += 1
            cumulative += weights[i]
        out[j] = i
    return out


@numba.njit(cache=True)
def kld_bound(bins: int, kld_err: float, kld_z: float) -> float:
    """Fox (2003) eq. 8: the sample count that keeps the K-L divergence between the sample-
    based and the true posterior under ``kld_err`` with probability ``Phi(kld_z)`` when the
    samples fall in ``bins`` >= 2 histogram bins (Wilson-Hilferty approximation of
    ``chi2_{bins-1, Phi(kld_z)} / (2 kld_err)``)::

        n = (k - 1) / (2 eps) (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3
    """
    km1 = bins - 1.0
    b = 2.0 / (9.0 * km1)
    c = 1.0 - b + math.sqrt(b) * kld_z
    return km1 / (2.0 * kld_err) * c * c * c


@numba.njit(cache=True)
def kld_sample_count(
    poses: np.ndarray,
    origin: np.ndarray,
    cell: np.ndarray,
    shape: np.ndarray,
    kld_err: float,
    kld_z: float,
    min_count: int,
    max_count: int,
) -> int:
    """How many of the draws ``poses (D, 3)`` (in draw order) KLD-sampling keeps.

    Each draw marks its bin of the histogram with cells ``cell (3,)`` (m, m, rad) from
    ``origin (3,)``, ``shape (3,)`` cells (poses outside fall in the border cells); after
    draw ``j`` (1-based) with ``k`` bins marked, sampling stops as soon as
    ``j >= clip(kld_bound(k), min_count, max_count)`` (the bound taken as ``min_count`` while
    ``k < 2``: one bin holds no spread to sample), as ``pf.c``'s resampling loop does. At
    most ``min(D, max_count)``.
    """
    marked = np.zeros((shape[0], shape[1], shape[2]), dtype=np.bool_)
    bins = 0
    limit = min(max_count, poses.shape[0])
    index = np.empty(3, dtype=np.int64)
    for j in range(limit):
        for d in range(3):
            cell_index = math.floor((poses[j, d] - origin[d]) / cell[d])
            index[d] = min(max(cell_index, 0), shape[d] - 1)
        if not marked[index[0], index[1], index[2]]:
            marked[index[0], index[1], index[2]] = True
            bins += 1
        needed = float(min_count)
        if bins >= 2:
            needed = min(max(kld_bound(bins, kld_err, kld_z), float(min_count)), float(max_count))
        if j + 1 >= needed:
            return j + 1
    return limit


@numba.njit(cache=True)
def weighted_pose_moments(particles: np.ndarray, weights: np.ndarray) -> tuple:
    """Weighted mean ``(3,)`` (the heading a circular mean ``atan2(sum w sin, sum w cos)``)
    and covariance ``(3, 3)`` (heading residuals wrapped) of ``particles (N, 3)`` with
    normalised ``weights (N,)``."""
    mean = np.zeros(3)
    sin_sum = 0.0
    cos_sum = 0.0
    for i in range(particles.shape[0]):
        mean[0] += weights[i] * particles[i, 0]
        mean[1] += weights[i] * particles[i, 1]
        sin_sum += weights[i] * math.sin(particles[i, 2])
        cos_sum += weights[i] * math.cos(particles[i, 2])
    mean[2] = math.atan2(sin_sum, cos_sum)
    cov = np.zeros((3, 3))
    residual = np.empty(3)
    for i in range(particles.shape[0]):
        residual[0] = particles[i, 0] - mean[0]
        residual[1] = particles[i, 1] - mean[1]
        residual[2] = wrap(particles[i, 2] - mean[2])
        for a in range(3):
            for b in range(a + 1):
                cov[a, b] += weights[i] * residual[a] * residual[b]
    for a in range(3):
        for b in range(a):
            cov[b, a] = cov[a, b]
    return mean, cov

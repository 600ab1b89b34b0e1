"""The particle-filter baseline (localization.mcl) tested on its own terms, and its inputs.

The kernels against direct formulas written here (beam mixture, systematic counts, the KLD
bound against the chi-square quantile, the motion model's moments), the filter's bookkeeping
(weights, w_slow/w_fast, gating, the estimate), the expected ranges against the simulator's
sonar, and convergence from a uniform prior on the built-in hall.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats
from shapely.geometry import box

from localization.compiled import mcl as kernels
from localization.errors import EstimationError
from localization.mcl import (
    BeamCombination,
    MclSettings,
    MonteCarloLocalization,
    odometry_poses,
)
from robotsim.maps import builtin_map, point_segment_distance
from robotsim.sensors.sonar import SonarBeltParams, cone_distances, simulate_readings
from robotsim.simulation import KidnapEvent
from scenarios.mcl_ranges import cone_range_function, free_space, free_space_sampler
from scenarios.runner import simulate_spec
from scenarios.spec import load_scenario

BELT = SonarBeltParams.default_belt()
HALL = builtin_map("hall")


def _random_poses(segment_map, count, rng):
    bounds = segment_map.bounds
    return np.column_stack(
        [
            rng.uniform(bounds[0, 0], bounds[0, 1], count),
            rng.uniform(bounds[1, 0], bounds[1, 1], count),
            rng.uniform(-math.pi, math.pi, count),
        ]
    )


def _wrap(angle):
    return (np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi


# -- expected ranges ----------------------------------------------------------------------


@pytest.mark.parametrize("name", ["hall", "office", "symmetric"])
def test_cone_ranges_equal_the_simulator_cone_model_on_random_poses(name):
    segment_map = builtin_map(name)
    poses = _random_poses(segment_map, 3000, np.random.default_rng(1))
    expected = cone_range_function(segment_map.segments, BELT)(poses)
    truth = cone_distances(
        poses, segment_map.segments, BELT.mount_xy, BELT.mount_angle_rad, BELT.half_aperture_rad
    )
    assert expected.shape == (3000, BELT.count)
    np.testing.assert_array_equal(np.isinf(expected), np.isinf(truth))
    finite = np.isfinite(truth)
    np.testing.assert_allclose(expected[finite], truth[finite], rtol=1e-12, atol=0.0)


def test_cone_ranges_give_the_noiseless_sonar_reading():
    poses = _random_poses(HALL, 2000, np.random.default_rng(2))
    belt = SonarBeltParams.default_belt(error_abs_bound_m=0.0, error_rel_bound=0.0)
    readings, fault = simulate_readings(
        cone_distances(
            poses, HALL.segments, belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad
        ),
        belt,
        np.random.default_rng(3),
    )
    expected = cone_range_function(HALL.segments, belt)(poses)
    assert not fault.any()
    in_range = expected <= belt.d_max_m
    assert 0.2 < in_range.mean() < 0.9  # both echoes and no-echo readings are exercised
    np.testing.assert_allclose(np.where(in_range, expected, np.inf), readings, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("name", ["hall", "office", "symmetric"])
def test_free_space_samples_keep_the_robot_off_the_walls_and_inside(name):
    segment_map = builtin_map(name)
    xy = free_space_sampler(segment_map, robot_radius_m=0.2)(np.random.default_rng(4), 20000)
    assert xy.shape == (20000, 2)
    gap = np.min(
        [point_segment_distance(xy, s[0], s[1]) for s in segment_map.segments], axis=0
    )  # (P,) distance to the nearest wall
    assert gap.min() >= 0.2 - 1e-3  # shapely's buffer is a polygon: within its tolerance
    upper = segment_map.bounds[:, 1] - 0.2 + 1e-9
    assert np.all((xy > 0.2 - 1e-9) & (xy < upper))  # the outer walls start at (0, 0)


def test_free_space_samples_are_uniform():
    xy = free_space_sampler(HALL, robot_radius_m=0.2)(np.random.default_rng(5), 20000)
    space = free_space(HALL, 0.2)
    # the share in each quarter of the hall is that of the free area there
    for x0, y0 in ((0, 0), (5, 0), (0, 4), (5, 4)):
        area = space.intersection(box(x0, y0, x0 + 5, y0 + 4)).area / space.area
        share = np.mean(
            (xy[:, 0] >= x0) & (xy[:, 0] < x0 + 5) & (xy[:, 1] >= y0) & (xy[:, 1] < y0 + 4)
        )
        assert abs(share - area) < 4 * math.sqrt(area * (1 - area) / len(xy))


# -- beam model ---------------------------------------------------------------------------


def _direct_beam(z, z_star, s: MclSettings, max_range):
    """PR eq. 6.4-6.12 as amcl_laser.cpp evaluates them, one beam at a time."""
    z = min(z, max_range)
    z_star = min(z_star, max_range)
    p = s.z_hit * math.exp(-((z - z_star) ** 2) / (2 * s.sigma_hit_m**2))
    if z < z_star:
        p += s.z_short * s.lambda_short_per_m * math.exp(-s.lambda_short_per_m * z)
    p += s.z_max if z >= max_range else s.z_rand / max_range
    return p


@pytest.mark.parametrize("combination", list(BeamCombination))
def test_beam_log_likelihood_matches_the_direct_mixture(combination):
    rng = np.random.default_rng(5)
    s = MclSettings(z_hit=0.6, z_short=0.1, z_max=0.07, z_rand=0.3, beam_combination=combination)
    observed = rng.uniform(0.0, 3.5, 16)
    observed[[2, 7]] = np.inf  # no echo
    expected = rng.uniform(0.0, 3.4, (50, 16))
    expected[:, 3] = np.inf  # a cone that meets nothing
    expected[::5, 7] = 2.0
    got = kernels.beam_log_likelihoods(
        observed, expected, s.mixture, 3.0, 0 if combination == "product" else 1
    )
    beams = np.array(
        [
            [_direct_beam(z, e, s, 3.0) for z, e in zip(observed, row, strict=True)]
            for row in expected
        ]
    )
    want = np.log(beams).sum(axis=1) if combination == "product" else np.log1p((beams**3).sum(1))
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_no_echo_reading_is_a_max_range_reading():
    s = MclSettings()
    expected = np.array([[1.0, np.inf, 5.0]])
    as_inf = kernels.beam_log_likelihoods(np.array([np.inf] * 3), expected, s.mixture, 3.0, 0)
    as_max = kernels.beam_log_likelihoods(np.array([3.0] * 3), expected, s.mixture, 3.0, 0)
    assert as_inf == as_max
    # the last two beams expect max range: a max reading is as likely as it gets there
    peak = math.log(s.z_hit + s.z_max)
    assert as_inf[0] == pytest.approx(math.log(_direct_beam(3.0, 1.0, s, 3.0)) + 2 * peak)


# -- resampling and KLD -------------------------------------------------------------------


def test_systematic_resampling_counts_are_the_comb_counts():
    rng = np.random.default_rng(6)
    for _ in range(200):
        n, m = int(rng.integers(1, 60)), int(rng.integers(1, 300))
        weights = rng.dirichlet(np.full(n, 0.3))
        offset = rng.random()
        counts = np.bincount(kernels.systematic_indices(weights, m, offset), minlength=n)
        # teeth (offset + j) / m in [C_{i-1}, C_i): ceil(m C_i - u) - ceil(m C_{i-1} - u)
        edges = np.concatenate([[0.0], np.cumsum(weights)])
        edges[-1] = 1.0
        teeth = np.ceil(m * edges - offset)
        np.testing.assert_array_equal(counts, np.diff(teeth))
        assert np.all(counts >= np.floor(m * weights) - 1e-9)
        assert np.all(counts <= np.ceil(m * weights) + 1e-9)


def test_kld_bound_is_the_chi_square_quantile():
    err, z = 0.05, 0.99
    bins = np.array([3, 5, 10, 30, 100, 1000, 10000])
    exact = stats.chi2.ppf(stats.norm.cdf(z), bins - 1) / (2 * err)
    approx = np.array([kernels.kld_bound(int(k), err, z) for k in bins])
    np.testing.assert_allclose(approx, exact, rtol=0.01)


def test_kld_sample_count_stops_at_the_bound_of_the_bins_seen():
    cell = np.array([0.5, 0.5, math.radians(10)])
    shape = np.array([200, 200, 36])
    origin = np.array([0.0, 0.0, -math.pi])
    j = np.arange(6000)
    cells = np.column_stack([(j % 200) * 0.5 + 0.25, (j // 200) * 0.5 + 0.25, np.zeros(6000)])
    quantile = stats.chi2.ppf(stats.norm.cdf(0.99), np.arange(1, 6000)) / 0.1  # chi2_{k-1} / 2eps
    for bins in (10, 40, 200, 500):
        # draws cycling over `bins` bins: after the first `bins` draws the histogram holds k =
        # bins, and sampling stops at the first draw count >= the bound for k
        draws = np.ascontiguousarray(cells[j % bins])
        got = kernels.kld_sample_count(draws, origin, cell, shape, 0.05, 0.99, 10, 6000)
        assert got == math.ceil(kernels.kld_bound(bins, 0.05, 0.99))
        assert abs(got - quantile[bins - 2]) <= 0.01 * got + 1
    # every draw in a new bin: the bound (about 10 k) stays ahead, the cap stops it
    assert kernels.kld_sample_count(cells, origin, cell, shape, 0.05, 0.99, 10, 6000) == 6000
    # all draws in one bin: the minimum
    same = np.tile([1.0, 1.0, 0.0], (3000, 1))
    assert kernels.kld_sample_count(same, origin, cell, shape, 0.05, 0.99, 120, 3000) == 120
    # the cap
    assert kernels.kld_sample_count(cells, origin, cell, shape, 0.05, 0.99, 100, 300) == 300


# -- motion model -------------------------------------------------------------------------


def test_odometry_increment_recovers_the_composed_step():
    rng = np.random.default_rng(7)
    for _ in range(100):
        old = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi)])
        rot1, trans, rot2 = rng.uniform(-2, 2), rng.uniform(0.05, 1.0), rng.uniform(-2, 2)
        new = np.array(
            [
                old[0] + trans * math.cos(old[2] + rot1),
                old[1] + trans * math.sin(old[2] + rot1),
                _wrap(old[2] + rot1 + rot2),
            ]
        )
        got = kernels.odometry_increment(old, new)
        np.testing.assert_allclose(
            [_wrap(got[0] - rot1), got[1] - trans, _wrap(got[2] - rot2)], 0.0, atol=1e-12
        )


def test_motion_samples_have_the_model_mean_and_covariance():
    rng = np.random.default_rng(8)
    alphas = np.array([1e-3, 2e-3, 1.5e-3, 1e-3])
    start = np.array([1.0, 2.0, 0.3])
    old, new = np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.2, 0.6])
    rot1, trans, rot2 = kernels.odometry_increment(old, new)
    n = 400_000
    moved = kernels.sample_motion_odometry(
        np.tile(start, (n, 1)), old, new, alphas, rng.standard_normal((n, 3))
    )
    # the analytic moments to first order in the noise: mean the noiseless step, covariance
    # J diag(var_rot1, var_trans, var_rot2) J^T with PR table 5.6's variances
    var = np.array(
        [
            alphas[0] * rot1**2 + alphas[1] * trans**2,
            alphas[2] * trans**2 + alphas[3] * (rot1**2 + rot2**2),
            alphas[0] * rot2**2 + alphas[1] * trans**2,
        ]
    )
    heading = start[2] + rot1
    mean = np.array(
        [
            start[0] + trans * math.cos(heading),
            start[1] + trans * math.sin(heading),
            start[2] + rot1 + rot2,
        ]
    )
    jac = np.array(
        [
            [-trans * math.sin(heading), math.cos(heading), 0.0],
            [trans * math.cos(heading), math.sin(heading), 0.0],
            [1.0, 0.0, 1.0],
        ]
    )
    cov = jac @ np.diag(var) @ jac.T
    sample_cov = np.cov(moved.T)
    sd = np.sqrt(np.diag(cov))
    # the second-order bias of the mean is ~ trans var_rot1 / 2 (2e-5 m), under 0.02 sd here
    np.testing.assert_allclose((moved.mean(axis=0) - mean) / sd, 0.0, atol=0.02)
    np.testing.assert_allclose(sample_cov / np.outer(sd, sd), cov / np.outer(sd, sd), atol=0.01)


def test_motion_model_with_zero_alphas_follows_the_odometry_exactly():
    old, new = np.array([3.0, -1.0, 2.5]), np.array([3.4, -0.7, -2.9])
    particles = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])
    moved = kernels.sample_motion_odometry(particles, old, new, np.zeros(4), np.ones((2, 3)))
    # the same relative motion in each particle's frame: R(-theta_old) (new - old)
    c, s = math.cos(old[2]), math.sin(old[2])
    local = np.array([c * 0.4 + s * 0.3, -s * 0.4 + c * 0.3])
    for before, after in zip(particles, moved, strict=True):
        c, s = math.cos(before[2]), math.sin(before[2])
        np.testing.assert_allclose(
            after[:2],
            before[:2] + np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]]),
        )
        assert _wrap(after[2] - before[2] - (new[2] - old[2])) == pytest.approx(0.0, abs=1e-12)


def test_odometry_poses_integrate_a_straight_run_and_an_arc():
    ticks = np.zeros((101, 2), dtype=np.int64)
    ticks[1:] = [10, 10]
    straight = odometry_poses(ticks, 0.001, 0.3)
    np.testing.assert_allclose(straight[-1], [1.0, 0.0, 0.0], atol=1e-12)
    ticks[1:] = [10, 12]  # a constant turn: per step ds = 11 mm, dtheta = 2 mm / 0.3 m
    arc = odometry_poses(ticks, 0.001, 0.3)
    turn = 100 * 0.002 / 0.3
    radius = 0.011 / (0.002 / 0.3)
    exact = [radius * math.sin(turn), radius * (1 - math.cos(turn)), turn]
    np.testing.assert_allclose(arc[-1], exact, atol=1e-5)  # the mid-point rule's chord error
    gyro = np.full(101, 0.5)
    with_gyro = odometry_poses(ticks, 0.001, 0.3, gyro_rad_s=gyro, dt_s=0.01)
    assert with_gyro[-1, 2] == pytest.approx(0.5)


# -- the filter's bookkeeping -------------------------------------------------------------


def _constant_ranges(values):
    values = np.asarray(values, dtype=float)

    def expected(particles):
        return np.tile(values, (len(particles), 1))

    return expected


def _filter(settings, expected, seed=0):
    return MonteCarloLocalization(
        settings,
        expected,
        free_space_sampler(HALL, 0.2),
        HALL.bounds,
        3.0,
        np.random.default_rng(seed),
    )


def test_weights_are_prior_times_scan_likelihood():
    settings = MclSettings(resample_interval=2)
    belt_ranges = cone_range_function(HALL.segments, BELT)
    mcl = _filter(settings, belt_ranges)
    rng = np.random.default_rng(9)
    particles = _random_poses(HALL, 300, rng)
    prior = rng.random(300)
    mcl.set_particles(particles, prior)
    scan = np.minimum(belt_ranges(np.array([[4.0, 3.0, 0.5]]))[0], np.inf)
    assert mcl.update(np.zeros(3), scan)  # the first scan: weighted, not resampled
    expected = belt_ranges(particles)
    likelihood = np.array(
        [
            np.prod([_direct_beam(z, e, settings, 3.0) for z, e in zip(scan, row, strict=True)])
            for row in expected
        ]
    )
    want = prior * likelihood / np.sum(prior * likelihood)
    np.testing.assert_allclose(mcl.weights, want, rtol=1e-9)
    np.testing.assert_array_equal(mcl.particles, particles)


def test_recovery_averages_and_random_share_follow_their_recursions():
    settings = MclSettings(
        alpha1=0.0,
        alpha2=0.0,
        alpha3=0.0,
        alpha4=0.0,
        recovery_alpha_slow=0.05,
        recovery_alpha_fast=0.5,
        min_particles=1000,
        max_particles=1000,
    )
    home = np.array([4.0, 3.0, 0.5])
    good, bad = np.array([1.0, 2.0]), np.array([2.5, 0.4])
    p_good = math.prod(
        _direct_beam(z, e, settings, 3.0) for z, e in zip(good, [1.0, 2.0], strict=True)
    )
    p_bad = math.prod(
        _direct_beam(z, e, settings, 3.0) for z, e in zip(bad, [1.0, 2.0], strict=True)
    )
    scans = [good] * 40 + [bad]
    # PR table 8.3: w_slow += a_slow (w_avg - w_slow), w_fast likewise, both from 0
    w_slow = w_fast = 0.0
    for scan in scans:
        w_avg = p_good if scan is good else p_bad
        w_slow += 0.05 * (w_avg - w_slow)
        w_fast += 0.5 * (w_avg - w_fast)
    share = 1 - w_fast / w_slow
    assert 0.3 < share < 0.9

    def run(resample_interval):
        mcl = _filter(
            dataclasses.replace(settings, resample_interval=resample_interval),
            _constant_ranges([1.0, 2.0]),
        )
        mcl.set_particles(np.tile(home, (1000, 1)))
        for step, scan in enumerate(scans):
            assert mcl.update(np.array([0.3 * step, 0.0, 0.0]), scan)
            if step < len(scans) - 1:
                assert mcl.random_share == 0.0  # w_fast rises ahead of w_slow: no injection
        return mcl

    kept = run(resample_interval=100)  # no resampling: the averages as they stand
    assert kept.w_slow == pytest.approx(w_slow, rel=1e-9)
    assert kept.w_fast == pytest.approx(w_fast, rel=1e-9)
    assert kept.random_share == pytest.approx(share, rel=1e-9)
    resampled = run(resample_interval=1)  # the last resampling injected random particles
    assert resampled.w_slow == pytest.approx(w_slow, rel=1e-9)  # they run on (PR table 8.3)
    # the particles that followed the odometry from `home` (straight along their heading) all
    # sit at one pose; the others are the uniform draws, binomial(1000, share) of them
    travel = 0.3 * (len(scans) - 1)
    moved_home = home + travel * np.array([math.cos(home[2]), math.sin(home[2]), 0.0])
    random = ~np.all(np.isclose(resampled.particles, moved_home), axis=1)
    assert abs(random.sum() - 1000 * share) < 5 * math.sqrt(1000 * share * (1 - share))


def test_update_waits_for_update_min_d_or_update_min_a():
    settings = MclSettings(update_min_d_m=0.25, update_min_a_rad=0.2)
    mcl = _filter(settings, _constant_ranges([1.0]))
    mcl.set_particles(_random_poses(HALL, 500, np.random.default_rng(11)))
    assert mcl.update(np.array([0.0, 0.0, 0.0]), [1.0])
    before = mcl.particles
    for small in ([0.2, 0.2, 0.0], [-0.24, 0.1, 0.19], [0.0, 0.0, -0.19]):
        assert not mcl.update(np.array(small), [1.0])
        np.testing.assert_array_equal(mcl.particles, before)
    # measured from the odometry of the last update, along x, y or the heading
    steps = [([0.26, 0.0, 0.0], True), ([0.26, -0.26, 0.0], True), ([0.3, -0.1, 0.1], False)]
    for odom, updated in [*steps, ([0.3, -0.1, 0.21], True)]:
        assert mcl.update(np.array(odom), [1.0]) is updated
    assert mcl.updates == 4


def test_resampled_set_has_a_kld_size_and_equal_weights():
    settings = MclSettings(min_particles=100, max_particles=4000)
    mcl = _filter(settings, cone_range_function(HALL.segments, BELT))
    mcl.global_localization()
    assert len(mcl.weights) == 4000
    # the uniform prior: positions over the hall, headings over the circle
    prior = mcl.particles
    np.testing.assert_allclose(prior[:, :2].std(axis=0), np.array([9.6, 7.6]) / 12**0.5, rtol=0.05)
    assert np.abs(np.mean(np.exp(1j * prior[:, 2]))) < 0.05
    mcl.update(np.zeros(3), np.full(16, np.inf))  # a scan that leaves the set wide
    count = len(mcl.weights)
    assert 100 <= count <= 4000
    np.testing.assert_array_equal(mcl.weights, np.full(count, 1.0 / count))


def test_estimate_is_the_weighted_circular_mean_and_covariance():
    rng = np.random.default_rng(12)
    particles = np.column_stack(
        [
            rng.normal(2, 0.3, 1000),
            rng.normal(3, 0.2, 1000),
            _wrap(math.pi + rng.normal(0, 0.1, 1000)),
        ]
    )
    weights = rng.random(1000)
    mcl = _filter(MclSettings(), _constant_ranges([1.0]))
    mcl.set_particles(particles, weights)
    estimate = mcl.estimate()
    w = weights / weights.sum()
    heading = math.atan2(np.sum(w * np.sin(particles[:, 2])), np.sum(w * np.cos(particles[:, 2])))
    assert abs(_wrap(estimate.mean[2] - math.pi)) < 0.02  # across the +-pi seam
    np.testing.assert_allclose(estimate.mean, [*(w @ particles[:, :2]), heading], rtol=1e-12)
    residual = particles - estimate.mean
    residual[:, 2] = _wrap(residual[:, 2])
    np.testing.assert_allclose(estimate.cov, (residual * w[:, None]).T @ residual, rtol=1e-10)


def test_pose_between_updates_carries_the_estimate_by_the_odometry():
    mcl = _filter(MclSettings(), _constant_ranges([1.0]))
    mcl.set_particles(np.tile([4.0, 2.0, 1.0], (10, 1)))
    odom_at_update = np.array([0.5, -0.3, -0.4])
    mcl.update(odom_at_update, [1.0])
    later = np.array([0.6, -0.25, -0.3])
    assert not mcl.update(later, [1.0])

    def matrix(pose):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([[c, -s, pose[0]], [s, c, pose[1]], [0, 0, 1]])

    want = matrix(mcl.estimate().mean) @ np.linalg.inv(matrix(odom_at_update)) @ matrix(later)
    got = mcl.pose_at(later)
    np.testing.assert_allclose(got[:2], want[:2, 2], atol=1e-12)
    assert got[2] == pytest.approx(math.atan2(want[1, 0], want[0, 0]))


def test_a_scan_no_particle_can_explain_is_refused():
    settings = MclSettings(z_short=0.0, z_max=0.0, z_rand=0.0, sigma_hit_m=0.01)
    mcl = _filter(settings, _constant_ranges([1.0]))
    mcl.set_particles(np.zeros((5, 3)))
    with pytest.raises(EstimationError, match="likelihood 0"):
        mcl.update(np.zeros(3), [2.9])


def test_settings_are_validated():
    assert MclSettings(beam_combination="amcl_cube").beam_combination is BeamCombination.AMCL_CUBE
    bad = [
        {"beam_combination": "sum"},
        {"alpha1": -0.1},
        {"sigma_hit_m": 0.0},
        {"min_particles": 10, "max_particles": 5},
        {"max_particles": 10.5},
        {"kld_err": 0.0},
        {"recovery_alpha_slow": 0.2, "recovery_alpha_fast": 0.1},
        {"recovery_alpha_slow": 0.001},
        {"update_min_d_m": math.inf},
        {"resample_interval": 0},
        {"z_hit": True},
    ]
    for changes in bad:
        with pytest.raises(EstimationError, match="MclSettings"):
            MclSettings(**changes)


# -- on the simulator's data --------------------------------------------------------------


def _track(seed, duration_s, max_particles, kidnaps=()):
    """MCL from a uniform prior on a hall run: (filter, estimates (M, 3), truth (M, 3))."""
    spec = load_scenario("hall").with_run(duration_s=duration_s, seed=seed)
    log = simulate_spec(spec, kidnaps=kidnaps)
    robot, sonar = spec.robot, spec.sensors.sonar
    odom = odometry_poses(
        log.wheel_ticks,
        2 * math.pi * robot.wheel_radius_m / robot.ticks_per_rev,
        robot.wheel_base_m,
        log.gyro_rad_s,
        1.0 / log.rate_hz,
    )
    settings = MclSettings(
        max_particles=max_particles, recovery_alpha_slow=0.001, recovery_alpha_fast=0.1
    )
    mcl = MonteCarloLocalization(
        settings,
        cone_range_function(spec.map.segments, sonar),
        free_space_sampler(spec.map, robot.radius_m),
        spec.map.bounds,
        sonar.d_max_m,
        np.random.default_rng(seed),
    )
    mcl.global_localization()
    samples = np.searchsorted(log.t_s, log.sonar_t_s - 0.5 / log.rate_hz)
    estimates = []
    for sample, scan in zip(samples, log.sonar_range_m, strict=True):
        mcl.update(odom[sample], scan)
        estimates.append(mcl.pose_at(odom[sample]))
    return mcl, np.array(estimates), np.asarray(log.sonar_pose)


def test_same_seed_gives_the_same_particles():
    first, estimates, _ = _track(0, 8.0, 3000)
    again, estimates_again, _ = _track(0, 8.0, 3000)
    np.testing.assert_array_equal(first.particles, again.particles)
    np.testing.assert_array_equal(estimates, estimates_again)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_converges_from_a_uniform_prior_on_hall(seed):
    mcl, estimates, truth = _track(seed, 60.0, 10000)
    position_error = np.hypot(*(estimates[:, :2] - truth[:, :2]).T)
    heading_error = np.abs(_wrap(estimates[:, 2] - truth[:, 2]))
    assert position_error[-1] < 0.3 and heading_error[-1] < 0.1
    # and it stays converged over the last 30 scans
    assert np.all(position_error[-30:] < 0.3) and np.all(heading_error[-30:] < 0.1)
    assert len(mcl.weights) < 10000  # KLD shrank the set once it converged


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_particles_find_a_kidnapped_robot(seed):
    kidnap = KidnapEvent(100.0, (5.0, 4.0, 2.0))  # 3.8 m and 2 rad away, no odometry of it
    _, estimates, truth = _track(seed, 180.0, 10000, kidnaps=(kidnap,))
    position_error = np.hypot(*(estimates[:, :2] - truth[:, :2]).T)
    heading_error = np.abs(_wrap(estimates[:, 2] - truth[:, 2]))
    assert np.all(position_error[80:100] < 0.3)  # converged before
    assert np.all(position_error[100:105] > 1.0)  # lost by the jump
    assert np.all(position_error[-20:] < 0.3) and np.all(heading_error[-20:] < 0.1)

"""Motion models of paper 001: Jacobians, limits, CCA closed form, batching, heading wrap."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate, special

from localization import motion_models as mm
from localization.errors import EstimationError

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

# Turn rates, accelerations and curvatures from exactly zero through tiny to large, so the
# series branch, the recurrence branch and the switch between them are all exercised.
TINY = np.array([0.0, 1e-12, -1e-9, 1e-6, -1e-4, 1e-2, -0.3, 0.8])


def random_states(model: mm.MotionModel, rng: np.random.Generator, count: int) -> np.ndarray:
    """Random states of ``model``; the rate/acceleration/curvature entries often near zero."""
    x = np.empty((count, model.n))
    x[:, 0:2] = rng.uniform(-500.0, 500.0, (count, 2))
    if model is mm.CV:
        x[:, 2:4] = rng.uniform(-30.0, 30.0, (count, 2))
        return x
    x[:, 2] = rng.uniform(-math.pi, math.pi, count)
    x[:, 3] = rng.uniform(-5.0, 35.0, count)
    scale = {"omega_rad_s": 1.0, "a_m_s2": 4.0, "c_1_m": 0.1}
    for i, name in enumerate(model.state_names[4:], start=4):
        x[:, i] = scale[name] * rng.choice(TINY, count) * rng.uniform(0.5, 1.5, count)
    return x


def finite_difference_jacobian(f, x: np.ndarray, angle_out: tuple[int, ...]) -> np.ndarray:
    """Central differences of ``f`` at the states ``x (B, n)`` -> ``(B, m, n)``."""
    cols = []
    for j in range(x.shape[-1]):
        h = 1e-6 * np.maximum(1.0, np.abs(x[:, j]))
        xp, xm = x.copy(), x.copy()
        xp[:, j] += h
        xm[:, j] -= h
        diff = f(xp) - f(xm)
        for i in angle_out:  # a wrapped heading may jump by 2 pi between the two sides
            diff[:, i] = (diff[:, i] + math.pi) % (2 * math.pi) - math.pi
        cols.append(diff / (2 * h[:, None]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("model", list(mm.MODELS.values()), ids=list(mm.MODELS))
@pytest.mark.parametrize("dt_s", [0.01, 0.1, 1.0, 3.0])
def test_transition_jacobian_matches_finite_differences(model, dt_s):
    rng = np.random.default_rng(1)
    x = random_states(model, rng, 400)
    analytic = model.jacobian(x, dt_s)
    numeric = finite_difference_jacobian(
        lambda s: model.transition(s, dt_s), x, model.angle_indices
    )
    scale = 1.0 + np.abs(analytic)
    np.testing.assert_array_less(np.abs(analytic - numeric) / scale, 2e-6)


@pytest.mark.parametrize("model", list(mm.MODELS.values()), ids=list(mm.MODELS))
def test_odometry_jacobian_matches_finite_differences(model):
    rng = np.random.default_rng(2)
    x = random_states(model, rng, 200)
    analytic = model.odometry_jacobian(x)
    numeric = finite_difference_jacobian(model.odometry, x, ())
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(
        mm.gps_jacobian(x), finite_difference_jacobian(mm.gps_position, x, ())
    )


def test_cv_speed_jacobian_at_standstill_is_zero_without_warning():
    x = np.array([3.0, 4.0, 0.0, 0.0])
    assert mm.cv_odometry(x)[0] == 0.0
    assert not mm.cv_odometry_jacobian(x).any()


def moment_integrand(t: float, k: int, u: float, trig) -> float:
    """``t^k trig(u t)``: the integrand of the ``k``-th trigonometric moment over ``[0, 1]``."""
    return t**k * trig(u * t)


def test_trig_moments_match_quadrature_on_both_sides_of_the_series_switch():
    u = np.array(
        [0.0, 1e-300, 1e-10, -1e-5, 0.05, 0.0999999, 0.1, -0.1000001, 0.5, -0.7, 2.0, -6.0, 40.0]
    )
    cos_m, sin_m = mm.trig_moments(u)
    for k in range(3):
        for ui, c_val, s_val in zip(u, cos_m[k], sin_m[k], strict=True):
            c_ref = integrate.quad(moment_integrand, 0.0, 1.0, (k, ui, math.cos), epsabs=1e-15)[0]
            s_ref = integrate.quad(moment_integrand, 0.0, 1.0, (k, ui, math.sin), epsabs=1e-15)[0]
            assert c_val == pytest.approx(c_ref, rel=1e-12, abs=1e-14)
            assert s_val == pytest.approx(s_ref, rel=1e-12, abs=1e-14)


def cca_by_ode(x0: np.ndarray, dt_s: float) -> np.ndarray:
    """The continuous CCA model integrated by scipy's adaptive RK (independent reference)."""
    _, _, theta0, v0, a, c = x0

    def rhs(t, p):
        speed = v0 + a * t
        heading = theta0 + c * (v0 * t + 0.5 * a * t * t)  # heading = integral of c v(t)
        return [speed * math.cos(heading), speed * math.sin(heading)]

    sol = integrate.solve_ivp(rhs, (0.0, dt_s), x0[:2], rtol=1e-11, atol=1e-11)
    return sol.y[:, -1]


def test_cca_closed_form_matches_numerical_integration():
    rng = np.random.default_rng(3)
    x = random_states(mm.CCA, rng, 300)
    for dt_s in (0.1, 1.0, 2.5):
        closed = mm.cca_transition(x, dt_s)
        numeric = mm.cca_transition_numerical(x, dt_s, nodes=40)
        np.testing.assert_allclose(closed[:, :2], numeric[:, :2], rtol=0, atol=1e-9)
        np.testing.assert_allclose(closed[:, 2:], numeric[:, 2:], rtol=0, atol=0)
    for x0 in x[:8]:
        np.testing.assert_allclose(mm.cca_transition(x0, 2.0)[:2], cca_by_ode(x0, 2.0), atol=1e-7)


def paper_eq17_position(x0: np.ndarray, dt_s: float) -> np.ndarray:
    """Paper 001 eq. 17 (our signs: omega = +c v), valid for a > 0, c > 0.

    Its Fresnel terms integrate ``(v + a t) cos(theta + c v t + c a t^2)``, i.e. the heading
    ``theta0 + omega(t) t`` of eq. 15, by completing the square.
    """
    _, _, theta, v, a, c = x0
    zeta1 = (2 * a * dt_s + v) * math.sqrt(c / (2 * a * math.pi))
    zeta2 = v * math.sqrt(c / (2 * a * math.pi))
    gamma1 = theta - c * v * v / (4 * a)
    s1, c1 = special.fresnel(zeta1)
    s2, c2 = special.fresnel(zeta2)
    phase_end = theta + c * v * dt_s + c * a * dt_s**2
    scale = 0.5 * v * math.sqrt(math.pi / (2 * c * a))
    dx = (math.sin(phase_end) - math.sin(theta)) / (2 * c) + scale * (
        math.cos(gamma1) * (c1 - c2) - math.sin(gamma1) * (s1 - s2)
    )
    dy = -(math.cos(phase_end) - math.cos(theta)) / (2 * c) + scale * (
        math.sin(gamma1) * (c1 - c2) + math.cos(gamma1) * (s1 - s2)
    )
    return x0[:2] + np.array([dx, dy])


def test_paper_fresnel_form_integrates_eq15_heading_not_the_cca_model():
    """Documents the derivation: eq. 17 is consistent with eq. 15's heading, not with eq. 17's."""
    x0 = np.array([0.0, 0.0, 0.4, 12.0, 2.0, 0.02])
    dt_s = 3.0
    _, _, theta, v, a, c = x0
    eq15 = [
        integrate.quad(
            lambda t, trig: (v + a * t) * trig(theta + c * (v + a * t) * t), 0, dt_s, (trig,)
        )[0]
        for trig in (math.cos, math.sin)
    ]
    np.testing.assert_allclose(paper_eq17_position(x0, dt_s), eq15, atol=1e-9)
    gap = np.linalg.norm(paper_eq17_position(x0, dt_s) - mm.cca_transition(x0, dt_s)[:2])
    assert gap > 1.0  # metres: eq. 15's heading turns too fast when a != 0
    x0[4] = 1e-9  # without acceleration the two headings agree
    np.testing.assert_allclose(
        paper_eq17_position(x0, dt_s), mm.cca_transition(x0, dt_s)[:2], atol=1e-5
    )


def test_ctra_with_zero_acceleration_is_ctrv():
    rng = np.random.default_rng(4)
    x6 = random_states(mm.CTRA, rng, 200)
    x6[:, 4] = 0.0
    x5 = x6[:, [0, 1, 2, 3, 5]]
    np.testing.assert_allclose(
        mm.ctra_transition(x6, 0.7)[:, [0, 1, 2, 3, 5]], mm.ctrv_transition(x5, 0.7)
    )
    jac6 = mm.ctra_jacobian(x6, 0.7)[:, [0, 1, 2, 3, 5]][:, :, [0, 1, 2, 3, 5]]
    np.testing.assert_allclose(jac6, mm.ctrv_jacobian(x5, 0.7))


def test_ctrv_with_vanishing_turn_rate_is_a_straight_line():
    x = np.array([10.0, -4.0, 2.1, 13.0, 0.0])
    dt_s = 2.0
    straight = x[:2] + 13.0 * dt_s * np.array([math.cos(2.1), math.sin(2.1)])
    np.testing.assert_array_equal(mm.ctrv_transition(x, dt_s)[:2], straight)
    for omega in (1e-13, -1e-9, 1e-7):
        x[4] = omega
        np.testing.assert_allclose(
            mm.ctrv_transition(x, dt_s)[:2], straight, atol=30 * abs(omega) + 1e-12
        )
    # CTRV against the textbook form v/omega (sin(theta + omega T) - sin theta) for a real turn
    x[4] = 0.3
    ref = x[:2] + 13.0 / 0.3 * np.array(
        [math.sin(2.1 + 0.6) - math.sin(2.1), -math.cos(2.1 + 0.6) + math.cos(2.1)]
    )
    np.testing.assert_allclose(mm.ctrv_transition(x, dt_s)[:2], ref, rtol=1e-13)


def test_arc_chord_equals_its_hypot_form_bit_for_bit():
    """The arc's ``sinc(turn / 2)`` takes a branch at no turn; the earlier branch-free form
    ``sin(a) / a``, ``a = hypot(turn / 2, 1e-300)``, written here in plain ``math``, gives the
    same positions bit for bit, at tiny, subnormal and ordinary turns of either sign."""
    rng = np.random.default_rng(7)
    turns = np.concatenate(
        [
            rng.normal(size=400) * 10.0 ** rng.uniform(-320.0, 1.0, 400),
            [0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-290, 1e-150, 3.0, -6.2],
        ]
    )
    x = np.array([10.0, -4.0, 2.1, 13.0, 0.0])
    dt_s = 0.5
    for omega_t in turns:
        x[4] = omega_t / dt_s
        turn = x[4] * dt_s
        half = 0.5 * turn
        a = math.hypot(half, 1e-300)
        chord = math.sin(a) / a * (x[3] * dt_s)
        direction = x[2] + half
        expected = (x[0] + chord * math.cos(direction), x[1] + chord * math.sin(direction))
        assert tuple(mm.ctrv_transition(x, dt_s)[:2]) == expected, omega_t


def test_ctra_matches_paper_eq8_eq9_away_from_zero_turn_rate():
    x = np.array([1.0, 2.0, -0.8, 7.0, 1.5, 0.4])
    dt_s = 1.3
    _, _, th, v, a, w = x
    dx = (
        (v * w + a * w * dt_s) * math.sin(th + w * dt_s)
        + a * math.cos(th + w * dt_s)
        - v * w * math.sin(th)
        - a * math.cos(th)
    ) / w**2
    dy = (
        (-v * w - a * w * dt_s) * math.cos(th + w * dt_s)
        + a * math.sin(th + w * dt_s)
        + v * w * math.cos(th)
        - a * math.sin(th)
    ) / w**2
    np.testing.assert_allclose(
        mm.ctra_transition(x, dt_s), [1 + dx, 2 + dy, th + w * dt_s, v + a * dt_s, a, w]
    )


def test_cca_and_ctrv_agree_when_curvature_matches_turn_rate_without_acceleration():
    rng = np.random.default_rng(5)
    x5 = random_states(mm.CTRV, rng, 200)
    x5[:, 3] = rng.uniform(1.0, 30.0, 200)
    x6 = np.concatenate([x5[:, :4], np.zeros((200, 1)), (x5[:, 4] / x5[:, 3])[:, None]], axis=1)
    np.testing.assert_allclose(
        mm.cca_transition(x6, 0.9)[:, :4], mm.ctrv_transition(x5, 0.9)[:, :4], atol=1e-9
    )


def test_straight_line_limits_agree_across_all_models():
    theta, v, a, dt_s = 0.7, 9.0, 1.2, 1.5
    ctra = mm.ctra_transition(np.array([0, 0, theta, v, a, 0.0]), dt_s)
    cca = mm.cca_transition(np.array([0, 0, theta, v, a, 0.0]), dt_s)
    np.testing.assert_allclose(ctra, cca, atol=1e-12)
    s = v * dt_s + 0.5 * a * dt_s**2
    np.testing.assert_allclose(
        ctra[:2], s * np.array([math.cos(theta), math.sin(theta)]), atol=1e-12
    )
    cv = mm.cv_transition(np.array([0, 0, v * math.cos(theta), v * math.sin(theta)]), dt_s)
    ctrv = mm.ctrv_transition(np.array([0, 0, theta, v, 0.0]), dt_s)
    np.testing.assert_allclose(cv[:2], ctrv[:2], atol=1e-12)


@pytest.mark.parametrize("model", list(mm.MODELS.values()), ids=list(mm.MODELS))
def test_batched_equals_one_by_one_with_per_run_time_steps(model):
    rng = np.random.default_rng(6)
    x = random_states(model, rng, 12).reshape(3, 4, model.n)
    dt = rng.uniform(0.01, 2.0, (3, 4))
    batched, jac = model.transition(x, dt), model.jacobian(x, dt)
    assert batched.shape == x.shape and jac.shape == x.shape + (model.n,)
    for i in range(3):
        for j in range(4):
            np.testing.assert_array_equal(batched[i, j], model.transition(x[i, j], dt[i, j]))
            np.testing.assert_array_equal(jac[i, j], model.jacobian(x[i, j], dt[i, j]))


@pytest.mark.parametrize("model", [mm.CTRV, mm.CTRA, mm.CCA], ids=["CTRV", "CTRA", "CCA"])
def test_heading_wraps_across_plus_minus_pi(model):
    x = np.zeros((2, model.n))
    x[:, 2] = [math.pi - 0.01, -math.pi + 0.01]
    x[:, 3] = 10.0
    x[:, -1] = [0.2, -0.2] if model is not mm.CCA else [0.02, -0.02]
    out = model.transition(x, 0.5)
    assert np.all((out[:, 2] >= -math.pi) & (out[:, 2] < math.pi))
    np.testing.assert_allclose(out[:, 2], [-math.pi + 0.09, math.pi - 0.09], atol=1e-12)
    # the position does not care which representative of the heading came in
    x_shifted = x.copy()
    x_shifted[:, 2] += 2 * math.pi
    np.testing.assert_allclose(model.transition(x_shifted, 0.5), out, atol=1e-9)


@pytest.mark.parametrize("model", list(mm.MODELS.values()), ids=list(mm.MODELS))
def test_noise_augmented_transition(model):
    rng = np.random.default_rng(7)
    x = random_states(model, rng, 50)
    np.testing.assert_array_equal(
        model.transition_with_noise(x, np.zeros((50, 2)), 0.3), model.transition(x, 0.3)
    )
    e = rng.normal(size=(50, 2))
    out = model.transition_with_noise(x, e, 0.3)
    idx = list(model.noise_indices)
    np.testing.assert_allclose(
        out[:, idx], x[:, idx] + e
    )  # the driven quantities take the increment
    np.testing.assert_allclose(model.process_noise_std(0.04), 0.2 * np.array(model.noise_intensity))


def test_cv_noise_ramp_is_exact():
    x = np.array([1.0, 2.0, 3.0, -4.0])
    out = mm.CV.transition_with_noise(x, np.array([0.2, 0.4]), 2.0)
    np.testing.assert_allclose(out, [1 + 2 * 3.1, 2 + 2 * (-3.8), 3.2, -3.6])


def test_a_model_with_scattered_noise_entries_is_refused():
    with pytest.raises(
        EstimationError, match="CTRV: noise_indices \\(2, 4\\) must be 2 consecutive entries"
    ):
        dataclasses.replace(mm.CTRV, noise_indices=(2, 4))


def test_bad_state_shape_and_time_step_are_refused():
    with pytest.raises(EstimationError, match=r"CTRV: the state must have shape \(\.\.\., 5\)"):
        mm.ctrv_transition(np.zeros(6), 0.1)
    with pytest.raises(EstimationError, match="dt_s must be finite and > 0"):
        mm.CTRA.process_noise_std(0.0)


@pytest.mark.parametrize("model", [mm.CTRV, mm.CTRA, mm.CCA], ids=lambda m: m.name)
def test_heading_just_below_minus_pi_wraps_into_the_half_open_range(model):
    """A heading one ulp below -pi must come out in [-pi, pi), never as +pi."""
    x = np.zeros(len(model.state_names))
    x[model.angle_indices[0]] = np.nextafter(-np.pi, -np.inf)
    heading = model.transition(x, 0.1)[model.angle_indices[0]]
    assert -np.pi <= heading < np.pi

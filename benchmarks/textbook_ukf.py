"""A textbook unscented Kalman filter in plain numpy: the reference row of ``filters.py``.

Written as the textbooks give it (Wan and van der Merwe 2000, "The unscented Kalman filter
for nonlinear estimation", scaled sigma points; additive noise), for the CTRV tracking problem
of ``filters.py`` with the heading continuous (the measurements unwrapped), and nothing more:
no checks, no batches, no angle handling. ``filters.py`` checks that it gives our estimates
before timing it.
"""

from __future__ import annotations

import numpy as np


def ctrv_points(X: np.ndarray, dt: float) -> np.ndarray:
    """CTRV (paper 001 eq. 5) of states ``X (N, 5)`` = ``(x_m, y_m, theta_rad, v_m_s,
    omega_rad_s)`` over ``dt`` s, heading continuous (``omega`` never 0 here)."""
    px, py, theta, v, omega = X.T
    theta_new = theta + omega * dt
    r = v / omega
    return np.column_stack(
        [
            px + r * (np.sin(theta_new) - np.sin(theta)),
            py + r * (np.cos(theta) - np.cos(theta_new)),
            theta_new,
            v,
            omega,
        ]
    )


def sigma_weights(n: int, alpha: float, beta: float, kappa: float):
    """Scaled sigma-point weights: ``Wm (2n+1,)``, ``Wc (2n+1,)`` and the spread ``sqrt(n +
    lambda)``, ``lambda = alpha^2 (n + kappa) - n``."""
    lam = alpha**2 * (n + kappa) - n
    Wm = np.full(2 * n + 1, 0.5 / (n + lam))
    Wm[0] = lam / (n + lam)
    Wc = Wm.copy()
    Wc[0] += 1.0 - alpha**2 + beta
    return Wm, Wc, np.sqrt(n + lam)


def sigma_points(x: np.ndarray, P: np.ndarray, spread: float) -> np.ndarray:
    """``(2n+1, n)``: ``x``, then ``x +- spread * (columns of chol(P))``."""
    L = spread * np.linalg.cholesky(P)
    return np.vstack([x, x + L.T, x - L.T])


def textbook_ukf_run(p, z: np.ndarray, initial: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UKF over one run ``z (steps, 3)`` (pose measured, heading unwrapped) from ``initial
    (5,)`` with the constants of ``p`` (a ``filter_peers.Problem``). Returns the means ``(steps,
    5)`` and covariances ``(steps, 5, 5)`` after each update."""
    n = 5
    Wm, Wc, spread = sigma_weights(n, p.alpha, p.beta, p.kappa)
    x, P = initial.copy(), p.P0.copy()
    means, covs = np.empty((len(z), n)), np.empty((len(z), n, n))
    for k, zk in enumerate(z):
        # predict: propagate the sigma points, take their weighted moments
        Y = ctrv_points(sigma_points(x, P, spread), p.dt_s)
        x = Wm @ Y
        dY = Y - x
        P = dY.T @ (Wc[:, None] * dY) + p.Q
        # update: h(x) = x[:3] on fresh sigma points of the prediction
        X = sigma_points(x, P, spread)
        Z = X[:, :3]
        z_hat = Wm @ Z
        dX, dZ = X - x, Z - z_hat
        S = dZ.T @ (Wc[:, None] * dZ) + p.R
        Pxz = dX.T @ (Wc[:, None] * dZ)
        K = np.linalg.solve(S, Pxz.T).T  # K = Pxz S^-1 (S symmetric)
        x = x + K @ (zk - z_hat)
        P = P - K @ S @ K.T
        means[k], covs[k] = x, P
    return means, covs

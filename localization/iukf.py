"""The iterated unscented Kalman filter of paper 000 (Banani and Masnadi-Shirazi).

Statistical linearisation for the prediction, analytical linearisation for the update:

- predict: the unscented transform of the process model (paper 000 eq. 1, 3-5), here with
  any sigma-point scheme (the paper's is :class:`~localization.sigma_points.KappaSigmaPoints`);
- update: Newton iterations of eq. 11 from ``x_0 = x(k+1|k)`` with the analytic Jacobian of
  ``h``, covariance eq. 12 (implemented in :func:`localization.ekf.iterated_update`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from localization.ekf import IterationSettings, iterated_update
from localization.gaussian import Gaussian
from localization.linalg import PDPolicy
from localization.models import MeasurementModel, ProcessModel
from localization.sigma_points import KappaSigmaPoints, SigmaPointScheme
from localization.ukf import UnscentedKalmanFilter


@dataclass(frozen=True)
class IteratedUnscentedKalmanFilter:
    """IUKF settings; ``predict`` and ``update`` are pure steps.

    Attributes:
        points: sigma points of the prediction (paper 000 eq. 1: kappa points).
        iteration: the Newton iteration cap ``L`` and tolerance of the update.
        pd_policy: what to do when a covariance to factorise is not positive definite.
    """

    points: SigmaPointScheme = field(default_factory=KappaSigmaPoints)
    iteration: IterationSettings = field(default_factory=IterationSettings)
    pd_policy: PDPolicy = field(default_factory=PDPolicy)

    def predict(self, belief: Gaussian, model: ProcessModel, *args) -> Gaussian:
        """Unscented prediction, paper 000 eq. 3-5 (see :meth:`UnscentedKalmanFilter.predict`)."""
        return UnscentedKalmanFilter(self.points, self.pd_policy).predict(belief, model, *args)

    def update(self, belief: Gaussian, z: np.ndarray, model: MeasurementModel, *args) -> Gaussian:
        """Newton update, paper 000 eq. 11-12; needs ``model.jacobian``."""
        return iterated_update(belief, z, model, args, self.iteration, "IUKF update")

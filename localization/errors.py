"""Errors raised by the estimators.

:class:`EstimationError` is a precondition that does not hold (a bad setting, a non-finite
input); :class:`NumericalError`, its subclass, a numerical breakdown inside a filter (a
covariance that is not positive definite, a singular system, a state that became
non-finite). Raised under the ``robotsim`` command, on a scenario that passed validation,
either is a defect of the tool, not the user's mistake.
"""


class EstimationError(ValueError):
    """An estimator cannot go on: a bad setting, a non-finite input, a broken covariance.

    The message names the step (``predict``, ``update``...) and the reason.
    """


class NumericalError(EstimationError):
    """A numerical breakdown: a singular matrix, a covariance that cannot be factorised."""

"""Errors raised by the estimators."""


class EstimationError(ValueError):
    """An estimator cannot go on: a bad setting, a non-finite input, a broken covariance.

    The message names the step (``predict``, ``update``...) and the reason.
    """

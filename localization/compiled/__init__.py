"""All of the package's numba code: the per-point kernels and the compiled filter steps.

=====================  ==================================================================
module                 holds
=====================  ==================================================================
``motion``             the motion models of paper 001 per state (the one definition)
``linalg``             scalar linear algebra of one run (Cholesky, gains, angle wrapping)
``glue``               status codes, argument packing and entry calls (Python side)
``ukf``, ``ekf``       the batched filter steps behind ``UnscentedKalmanFilter`` and
                       ``ExtendedKalmanFilter``
``soa``                the UKF's batched steps of the built-in models, runs innermost
``lean``               one filter stepped in place, one call a step or a sequence
``dead_reckoning``     the dead-reckoning filter over a stretch of samples
``mcl``                the Monte Carlo localisation kernels
``samples``            the localiser's odometry samples checked and appended, a block a call
=====================  ==================================================================

numba's disk cache keys an entry on its own file only, while the entries inline kernels from
the other modules here; importing this package first drops the cache when any file of the
folder changed (:mod:`localization.kernel_cache`).
"""

from pathlib import Path

from localization.kernel_cache import drop_stale_kernel_caches

drop_stale_kernel_caches(Path(__file__).parent)

"""References of the compiled estimators, for tests and benchmarks only.

:mod:`localization.reference.dead_reckoning`: the dead reckoning run by the generic filter
classes step by step, the reference of the compiled step of
:mod:`localization.dead_reckoning`; :mod:`localization.reference.per_run_ukf`: the batched UKF
entries of the built-in kernels one run at a time, the reference of the structure-of-arrays
entries of :mod:`localization.compiled.soa`. The production path never imports this package (tested).
"""

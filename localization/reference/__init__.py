"""References of the compiled estimators, for tests and benchmarks only.

:mod:`localization.reference.dead_reckoning`: the dead reckoning run by the generic filter
classes step by step, the reference of the compiled step of
:mod:`localization.dead_reckoning`. The production path never imports this package (tested).
"""

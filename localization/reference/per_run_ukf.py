"""The batched UKF entries of the built-in kernels one run at a time, the reference of the
structure-of-arrays entries of :mod:`localization.compiled.soa`.

Each is the loop of :mod:`localization.compiled.batch` over a per-run function of
:mod:`localization.compiled.ukf` (what a lean filter steps; the batched path's entries until
issue 17), with the signature of the SoA entry it checks: ``per_run_predict`` against
``soa.predict_builtin`` (additive noise), ``per_run_augmented`` against
``soa.noisy_predict_builtin`` and ``per_run_update`` against ``soa.update_leading_entries``.
Tests and benchmarks only: the production path never imports this module.
"""

from __future__ import annotations

from localization.compiled import ukf as compiled_ukf
from localization.compiled.batch import batched_predict, batched_update

per_run_predict = batched_predict(
    compiled_ukf.builtin_predict_run, compiled_ukf.predict_scratch_length
)
per_run_augmented = batched_predict(
    compiled_ukf.builtin_augmented_predict_run, compiled_ukf.predict_scratch_length
)
per_run_update = batched_update(
    compiled_ukf.leading_entries_update_run, compiled_ukf.update_scratch_length
)

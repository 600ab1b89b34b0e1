"""localization: Gaussian beliefs, the Kalman filter family and the motion models of the papers.

Imports none of the other testbed packages; works on numpy arrays with a leading batch axis.
"""

from pathlib import Path

from localization.kernel_cache import drop_stale_kernel_caches

drop_stale_kernel_caches(Path(__file__).parent)

"""Keep numba's disk cache of the compiled filter steps in step with their sources.

numba's ``cache=True`` keys a compiled entry on the source file that defines it (its time
stamp and size) and nothing else. The entries of :mod:`localization.compiled_ukf` and
:mod:`localization.dead_reckoning_kernel` inline kernels from other files
(:mod:`localization.compiled_linalg`, :mod:`localization.motion_models`), so a change to one
of those alone (an edit, or an upgrade of the package that leaves the entry's file as it was)
would let numba load machine code built from the old kernels. :func:`drop_stale_kernel_caches`,
run when the package is imported, prevents that: it keeps a digest of all the kernel sources
next to the cache and removes the package's cache files when the digest changes. It touches
only this package's ``__pycache__`` files, and costs one hash of about 60 kB per import.

When the package folder is read-only numba keeps its cache in its user-wide folder
(``NUMBA_CACHE_DIR`` or ``~/.cache/numba``), which this does not reach; a read-only install is
not edited in place, and an upgrade changes every file's time stamp, so there the file-based
key suffices.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

KERNEL_SOURCES = (
    "compiled_linalg.py",
    "compiled_ukf.py",
    "compiled_ekf.py",
    "motion_models.py",
    "dead_reckoning_kernel.py",
)
"""The files whose compiled code numba's cache entries of this package contain."""

MARKER_NAME = "numba-kernels.sha256"


def sources_digest(package_dir: Path, names: tuple[str, ...] = KERNEL_SOURCES) -> str:
    """SHA-256 of the kernel sources, in order (a missing file counts as empty)."""
    digest = hashlib.sha256()
    for name in names:
        path = package_dir / name
        digest.update(name.encode())
        digest.update(path.read_bytes() if path.is_file() else b"")
    return digest.hexdigest()


def drop_stale_kernel_caches(package_dir: Path, names: tuple[str, ...] = KERNEL_SOURCES) -> bool:
    """Remove ``package_dir/__pycache__/*.nbi, *.nbc`` if the kernel sources changed since last time.

    Returns whether files were removed. Errors of a read-only folder are ignored (see the
    module docstring).
    """
    cache = package_dir / "__pycache__"
    marker = cache / MARKER_NAME
    digest = sources_digest(package_dir, names)
    try:
        if marker.read_text() == digest:
            return False
    except OSError:
        pass
    removed = False
    try:
        for path in (*cache.glob("*.nbi"), *cache.glob("*.nbc")):
            path.unlink()
            removed = True
        cache.mkdir(exist_ok=True)
        marker.write_text(digest)
    except OSError:
        pass
    return removed

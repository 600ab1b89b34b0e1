"""Keep numba's disk cache of the compiled filter steps in step with their sources.

numba's ``cache=True`` keys a compiled entry on the source file that defines it (its time
stamp and size) and nothing else. The entries of :mod:`localization.compiled` inline kernels
from other files of that folder (:mod:`localization.compiled.motion`,
:mod:`localization.compiled.linalg`), so a change to one of those alone (an edit, or an
upgrade of the package that leaves the entry's file as it was) would let numba load machine
code built from the old kernels. :func:`drop_stale_kernel_caches`, run when
:mod:`localization.compiled` is imported, prevents that: it keeps a digest of every Python
file of the folder next to the cache (no hand-kept list: a new module is covered as soon as
it is there) and removes the folder's cache files when the digest changes. It touches only
that folder's ``__pycache__`` numba files, and costs one hash of about 100 kB per import.

When the package folder is read-only numba keeps its cache in its user-wide folder
(``NUMBA_CACHE_DIR`` or ``~/.cache/numba``), which this does not reach; a read-only install is
not edited in place, and an upgrade changes every file's time stamp, so there the file-based
key suffices.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

MARKER_NAME = "numba-kernels.sha256"


def sources_digest(package_dir: Path) -> str:
    """SHA-256 of the folder's Python sources (``*.py``), by name in sorted order."""
    digest = hashlib.sha256()
    for path in sorted(package_dir.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def drop_stale_kernel_caches(package_dir: Path) -> bool:
    """Remove ``package_dir/__pycache__/*.nbi, *.nbc`` if the folder's sources changed since last time.

    Returns whether files were removed. Errors of a read-only folder are ignored (see the
    module docstring).
    """
    cache = package_dir / "__pycache__"
    marker = cache / MARKER_NAME
    digest = sources_digest(package_dir)
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

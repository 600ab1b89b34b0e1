"""numba's cached machine code is dropped when any file of the compiled folder changes, kept otherwise."""

from __future__ import annotations

from pathlib import Path

import localization.compiled
from localization import kernel_cache
from localization.kernel_cache import MARKER_NAME, drop_stale_kernel_caches


def _cache_files(folder: Path) -> list[str]:
    return sorted(p.name for p in (folder / "__pycache__").glob("*.nb?"))


def test_a_changed_dependency_drops_the_cache(tmp_path):
    for name in ("entry.py", "kernels.py"):
        (tmp_path / name).write_text(f"# {name}\n")
    drop_stale_kernel_caches(tmp_path)  # first import: writes the marker
    cache = tmp_path / "__pycache__"
    for name in ("entry.run-10.py311.nbi", "entry.run-10.py311.1.nbc"):
        (cache / name).write_bytes(b"machine code")
    (cache / "entry.cpython-311.pyc").write_bytes(b"bytecode")

    assert not drop_stale_kernel_caches(tmp_path)  # nothing changed: kept
    assert _cache_files(tmp_path) == ["entry.run-10.py311.1.nbc", "entry.run-10.py311.nbi"]

    (tmp_path / "kernels.py").write_text("# kernels.py, edited\n")  # the entry's file is untouched
    assert drop_stale_kernel_caches(tmp_path)
    assert _cache_files(tmp_path) == []
    assert (cache / "entry.cpython-311.pyc").exists()  # only numba's files go
    assert not drop_stale_kernel_caches(tmp_path)

    (tmp_path / "new_kernels.py").write_text("# a module added to the folder\n")  # no list to edit
    (cache / "entry.run-10.py311.nbi").write_bytes(b"machine code")
    assert drop_stale_kernel_caches(tmp_path)
    assert _cache_files(tmp_path) == []


def test_the_compiled_folder_marker_matches_its_sources():
    folder = Path(localization.compiled.__file__).parent
    assert {"motion.py", "ukf.py", "ekf.py", "linalg.py", "lean.py"} <= {
        p.name for p in folder.glob("*.py")
    }
    marker = folder / "__pycache__" / MARKER_NAME
    if marker.exists():  # absent only when the package folder is read-only
        assert marker.read_text() == kernel_cache.sources_digest(folder)

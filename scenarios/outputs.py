"""Atomic output writing: a crash or a user error never leaves a half-written file behind.

Every output of the CLI goes through these helpers: it is written under a temporary name
in the destination folder and moved into place (``os.replace``) only once complete. Outputs
get the usual permissions of a new file (``0o666``) or folder (``0o777``) less the process's
umask, not the private ones of the temporary names.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: Permissions of a new output file and folder, before the umask is applied.
FILE_MODE = 0o666
FOLDER_MODE = 0o777


def _umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_destination(path: str | Path) -> str | None:
    """Why ``path`` cannot receive an output file, or None when it can.

    Refused: an existing folder (or anything not a regular file) at ``path``, and a parent
    that cannot be created (an ancestor that is a file, or not writable).
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        return f"{path} exists and is not a file"
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"cannot create the folder {path.parent}: {ancestor} is not a folder"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"cannot write in {ancestor}"
    return None


def _temporary_file(path: Path) -> Path:
    """A new empty file beside ``path`` (its folder created if needed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    return Path(tmp_name)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` if the block succeeds.

    On any exception the temporary file is removed and ``path`` is left as it was.
    """
    with atomic_paths(path) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(*paths: str | Path) -> Iterator[tuple[Path, ...]]:
    """Yield one temporary path beside each of ``paths``; move them all into place only
    once the whole block has succeeded.

    All or nothing: on an exception in the block every temporary file is removed and no
    destination is touched; if a move fails, the destinations already moved are put back
    as they were (their previous file restored, or removed when there was none).
    """
    destinations = [Path(path) for path in paths]
    if len({path.resolve() for path in destinations}) < len(destinations):
        raise ValueError(f"the same destination given twice: {', '.join(map(str, destinations))}")
    temporaries: list[Path] = []
    try:
        for path in destinations:
            temporaries.append(_temporary_file(path))
        yield tuple(temporaries)
        mode = FILE_MODE & ~_umask()
        for tmp in temporaries:
            os.chmod(tmp, mode)
        _move_all(temporaries, destinations)
    finally:
        for tmp in temporaries:
            tmp.unlink(missing_ok=True)


def _move_all(temporaries: list[Path], destinations: list[Path]) -> None:
    """Move each temporary file onto its destination; on a failure undo the moves made."""
    backups: list[Path | None] = []
    try:
        for tmp, path in zip(temporaries, destinations):
            backup = None
            if path.is_file():  # keep the previous file (a hard link, no copy) to restore it
                backup = _temporary_file(path)
                backup.unlink()
                try:
                    os.link(path, backup)
                except OSError:  # a file system without hard links
                    shutil.copy2(path, backup)
            backups.append(backup)
            try:
                os.replace(tmp, path)
            except OSError as exc:  # name the destination, not the temporary file
                backups.pop()
                if backup is not None:
                    backup.unlink()
                raise OSError(exc.errno, exc.strerror, str(path)) from exc
    except BaseException:
        for path, backup in zip(destinations, backups):
            if backup is None:
                path.unlink(missing_ok=True)
            else:
                os.replace(backup, path)
        raise
    for backup in backups:
        if backup is not None:
            backup.unlink()


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically; non-finite floats are refused."""
    text = json.dumps(obj, indent=2, sort_keys=False, allow_nan=False) + "\n"
    write_text(path, text)


@contextlib.contextmanager
def atomic_directory(path: str | Path) -> Iterator[Path]:
    """Yield a fresh temporary folder beside ``path``; on success it replaces ``path``.

    For outputs made of several files (a reproduction's table and figures): either the
    whole new folder lands, or the old one (if any) stays untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    os.chmod(tmp, FOLDER_MODE & ~_umask())
    old = None
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
        os.replace(path, old / "previous")
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)

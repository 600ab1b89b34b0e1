"""Output writing that never destroys: nothing half-written, nothing of the user's replaced.

Every output of the CLI goes through these helpers:

- a file is written under a temporary name in its destination folder and moved into place
  (``os.replace``) only once complete (:func:`atomic_paths`); a failure names the user's
  path, never the temporary one;
- a folder of outputs (a reproduction) is built beside its destination and swapped in
  whole (:func:`atomic_directory`); it carries a marker file, :data:`MARKER`, and only a
  folder with that marker is ever replaced: an existing file or any other folder is
  refused (:func:`check_folder_destination`);
- no destination may be an input of the run (:func:`check_not_input`);
- temporary names carry the writing process's id (``.<name>.<pid>-<random>.part``): the
  next write to the same destination removes those a killed process (``kill -9``, a power
  cut) left behind, and leaves alone those of a process still running;
- a stop signal (Ctrl-C, SIGTERM, SIGHUP) is held back while a temporary is created and
  recorded for removal, and while the outputs are moved into place (:func:`signals_held`):
  one that arrives then takes effect just after, so that no temporary is left unrecorded
  and no destination is left half swapped.

Outputs get the usual permissions of a new file (``0o666``) or folder (``0o777``) less the
process's umask, not the private ones of the temporary names.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

#: Permissions of a new output file and folder, before the umask is applied.
FILE_MODE = 0o666
FOLDER_MODE = 0o777

#: The file inside every folder ``robotsim reproduce`` writes: only such a folder is replaced.
MARKER = ".robotsim-reproduce"
MARKER_TEXT = "written by robotsim reproduce; robotsim may replace this folder as a whole\n"

#: Suffixes of the temporary names beside a destination (new output; previous folder).
PART_SUFFIX = ".part"
OLD_SUFFIX = ".old"

#: Signals that stop a CLI run as Ctrl-C does (SIGINT raises KeyboardInterrupt by itself):
#: the temporary files are removed and the exit status is 128 + the signal's number.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
#: The signals whose handlers raise in the CLI (Ctrl-C and :data:`STOP_SIGNALS`).
HELD_SIGNALS = (signal.SIGINT, *STOP_SIGNALS)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold back :data:`HELD_SIGNALS` while the block runs: their handlers are swapped for
    one that notes the signal, and a signal noted is raised again once the previous handlers
    are back. (Masking the signal would not do: the kernel hands a process's signal to any
    thread that does not mask it, numpy's among them, and Python runs the handler anyway.)
    Only the main thread runs handlers and may set them: elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {
        signum: signal.signal(signum, lambda n, _: arrived.append(n)) for signum in HELD_SIGNALS
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        for number in dict.fromkeys(arrived):
            signal.raise_signal(number)


def _umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _parent_problem(path: Path) -> str | None:
    """Why the folder of ``path`` cannot be created or written in, or None."""
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"cannot create the folder {path.parent}: {ancestor} is not a folder"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"cannot write in {ancestor}"
    return None


def check_destination(path: str | Path, inputs: Iterable[str | Path] = ()) -> str | None:
    """Why ``path`` cannot receive an output file, or None when it can.

    Refused: an existing folder (or anything not a regular file) at ``path``, a parent that
    cannot be created (an ancestor that is a file, or not writable), and one of ``inputs``.
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        return f"{path} exists and is not a file"
    return check_not_input(path, inputs) or _parent_problem(path)


def check_not_input(path: str | Path, inputs: Iterable[str | Path]) -> str | None:
    """Why ``path`` may not be written: it is one of ``inputs`` (the same file under any
    name, hard links included) or, for a folder, holds one; None otherwise."""
    path = Path(path)
    target = path.resolve()
    for item in inputs:
        source = Path(item)
        if not source.exists():
            continue
        same = os.path.samefile(path, source) if path.exists() else False
        if same or target == source.resolve():
            return f"{path} is an input of this run ({source}): it would be overwritten"
        if source.resolve().is_relative_to(target):
            return f"{path} holds an input of this run ({source}): it would be replaced"
    return None


def check_folder_destination(path: str | Path, inputs: Iterable[str | Path] = ()) -> str | None:
    """Why ``path`` cannot receive a folder of outputs, or None when it can.

    Accepted: a new path, or a folder an earlier reproduction wrote (it holds :data:`MARKER`).
    Refused: anything else that exists (a file, a folder of the user's), the current folder
    or one of its ancestors, a folder that holds an input of the run, an unwritable parent.
    """
    path = Path(path)
    if Path.cwd().resolve().is_relative_to(path.resolve()):
        return f"{path} is the current folder or holds it; give a new folder"
    if path.exists() or path.is_symlink():
        if path.is_symlink() or not path.is_dir():
            return f"{path} exists and is not a folder; give a new folder"
        if not (path / MARKER).is_file():
            return (
                f"{path} exists and was not written by robotsim reproduce (no {MARKER} in it); "
                "give a new folder, or remove this one yourself"
            )
    return check_not_input(path, inputs) or _parent_problem(path)


def _pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one we may not signal counts as existing)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove the temporaries beside ``path`` (``.<name>.<pid>-*.part`` / ``.old``) whose
    writing process is gone; returns what was removed. Those of live processes stay."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        return []
    removed = []
    prefix = f".{path.name}."
    for entry in folder.iterdir():
        name = entry.name
        if not (name.startswith(prefix) and name.endswith((PART_SUFFIX, OLD_SUFFIX))):
            continue
        pid_text = name[len(prefix) :].split("-", 1)[0]
        if not pid_text.isdigit() or _pid_alive(int(pid_text)):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def _temporary_prefix(path: Path) -> str:
    return f".{path.name}.{os.getpid()}-"


def _temporary_file(path: Path) -> Path:
    """A new empty file beside ``path`` (its folder created if needed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    fd, tmp_name = tempfile.mkstemp(
        prefix=_temporary_prefix(path), suffix=PART_SUFFIX, dir=path.parent
    )
    os.close(fd)
    return Path(tmp_name)


def _naming(exc: OSError, temporaries: list[Path], destinations: list[Path]) -> OSError:
    """``exc`` with the user's path in place of a temporary name (or of no name at all).

    ``temporaries`` may be fewer than ``destinations`` (a failure while creating them)."""
    if exc.filename is None:
        if len(destinations) != 1:
            return exc
        path = destinations[0]
    else:
        name = Path(exc.filename).name
        owners = [
            path
            for i, path in enumerate(destinations)
            if name.startswith(_temporary_prefix(path))
            or (i < len(temporaries) and name.startswith(f".{temporaries[i].name}."))
        ]
        if not owners:
            return exc
        path = owners[0]
    renamed = OSError(exc.errno, exc.strerror or str(exc), str(path))
    renamed.__cause__ = exc
    return renamed


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
    as they were (their previous file restored, or removed when there was none). An
    ``OSError`` names the destination it concerns, not its temporary name.
    """
    destinations = [Path(path) for path in paths]
    if len({path.resolve() for path in destinations}) < len(destinations):
        raise ValueError(f"the same destination given twice: {', '.join(map(str, destinations))}")
    temporaries: list[Path] = []
    try:
        try:
            for path in destinations:
                with signals_held():  # a stop here must not leave a temporary unrecorded
                    temporaries.append(_temporary_file(path))
            yield tuple(temporaries)
            mode = FILE_MODE & ~_umask()
            for tmp in temporaries:
                os.chmod(tmp, mode)
        except OSError as exc:
            raise _naming(exc, temporaries, destinations) from exc
        with signals_held():
            _move_all(temporaries, destinations)
    finally:
        for tmp in temporaries:
            tmp.unlink(missing_ok=True)


def _move_all(temporaries: list[Path], destinations: list[Path]) -> None:
    """Move each temporary file onto its destination; on a failure undo the moves made."""
    backups: list[Path | None] = []
    try:
        for tmp, path in zip(temporaries, destinations, strict=True):
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
        for path, backup in zip(destinations, backups, strict=False):
            if backup is None:
                path.unlink(missing_ok=True)
            else:
                os.replace(backup, path)
        raise
    for backup in backups:
        if backup is not None:
            backup.unlink()


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to the file ``path`` (not atomic: for a temporary path); a failure
    (a full disk) raises an ``OSError`` that names ``path``."""
    try:
        with open(path, "wb") as file:
            file.write(data)
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        write_bytes(tmp, text.encode("utf-8"))


def write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically; non-finite floats are refused."""
    text = json.dumps(obj, indent=2, sort_keys=False, allow_nan=False) + "\n"
    write_text(path, text)


@contextlib.contextmanager
def atomic_directory(path: str | Path) -> Iterator[Path]:
    """Yield a fresh temporary folder beside ``path``; on success it replaces ``path``.

    For outputs made of several files (a reproduction's table and figures): either the
    whole new folder lands, or the old one (if any) stays untouched. The new folder holds
    :data:`MARKER`; ``path`` is replaced only when it is such a folder (checked before the
    block and again before the swap), otherwise ``FileExistsError`` is raised and nothing
    is touched.
    """
    path = Path(path)
    reason = check_folder_destination(path)
    if reason is not None:
        raise FileExistsError(reason)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    prefix = _temporary_prefix(path)
    made: list[Path] = []  # the temporary folder, once made
    try:
        with signals_held():  # a stop here must not leave the folder unrecorded
            made.append(Path(tempfile.mkdtemp(prefix=prefix, suffix=PART_SUFFIX, dir=path.parent)))
        tmp = made[0]
        try:
            yield tmp
            write_bytes(tmp / MARKER, MARKER_TEXT.encode("utf-8"))
        except OSError as exc:
            raise _naming(exc, [tmp], [path]) from exc
        reason = check_folder_destination(path)
        if reason is not None:
            raise FileExistsError(reason)
        os.chmod(tmp, FOLDER_MODE & ~_umask())
        with signals_held():
            _swap_folder(tmp, path, prefix)
    except BaseException:
        for folder in made:
            shutil.rmtree(folder, ignore_errors=True)
        raise


def _swap_folder(new: Path, path: Path, prefix: str) -> None:
    """Move the folder ``new`` onto ``path``; the folder there before (if any) is set aside
    first, put back if the move fails, and removed once it succeeded."""
    old = None
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=prefix, suffix=OLD_SUFFIX, dir=path.parent))
        os.replace(path, old / "previous")
    try:
        os.replace(new, path)
    except BaseException:
        if old is not None:
            os.replace(old / "previous", path)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

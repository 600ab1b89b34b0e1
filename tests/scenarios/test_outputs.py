"""The atomic writers: all-or-nothing over several files, usual permissions, refused destinations."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import tempfile

import pytest

from scenarios import outputs
from tests.helpers import small_file_limit


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.fixture
def umask_027():
    previous = os.umask(0o027)
    yield 0o027
    os.umask(previous)


def test_atomic_paths_rolls_back_the_files_moved_when_a_later_move_fails(tmp_path):
    kept = tmp_path / "kept.rrd"
    kept.write_text("previous recording")
    new = tmp_path / "new.json"
    taken = tmp_path / "taken"  # a folder: the last move fails
    taken.mkdir()
    with pytest.raises(OSError) as failure, outputs.atomic_paths(kept, new, taken) as temporaries:
        for tmp, text in zip(temporaries, ("new recording", "summary", "third"), strict=True):
            tmp.write_text(text)
    assert str(taken) in str(failure.value)
    assert kept.read_text() == "previous recording"  # restored
    assert not new.exists()  # removed: there was no file before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.rrd", "taken"]  # no temporary left
    assert not any(taken.iterdir())


def test_atomic_paths_moves_every_file_once_the_block_succeeds(tmp_path):
    first, second = tmp_path / "a" / "one.txt", tmp_path / "two.txt"
    second.write_text("old")
    with outputs.atomic_paths(first, second) as (tmp_first, tmp_second):
        tmp_first.write_text("1")
        tmp_second.write_text("2")
        assert not first.exists() and second.read_text() == "old"  # nothing lands before the end
    assert first.read_text() == "1" and second.read_text() == "2"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "two.txt"]


def test_an_error_in_the_block_touches_no_destination(tmp_path):
    first, second = tmp_path / "one.txt", tmp_path / "two.txt"
    second.write_text("old")
    with (
        pytest.raises(RuntimeError),
        outputs.atomic_paths(first, second) as (tmp_first, _),
    ):
        tmp_first.write_text("1")
        raise RuntimeError("crash")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.txt"] and second.read_text() == "old"


def test_the_same_destination_twice_is_refused(tmp_path):
    with (
        pytest.raises(ValueError, match="twice"),
        outputs.atomic_paths(tmp_path / "x", tmp_path / "." / "x"),
    ):
        pass
    assert not any(tmp_path.iterdir())


def test_outputs_get_the_usual_permissions_less_the_umask(tmp_path, umask_027):
    outputs.write_text(tmp_path / "file.txt", "x")
    assert mode(tmp_path / "file.txt") == 0o666 & ~umask_027
    with outputs.atomic_directory(tmp_path / "folder") as folder:
        outputs.write_json(folder / "table.json", {"a": 1})
    assert mode(tmp_path / "folder") == 0o777 & ~umask_027
    assert mode(tmp_path / "folder" / "table.json") == 0o666 & ~umask_027


def test_check_destination_names_what_is_wrong(tmp_path):
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("")
    assert outputs.check_destination(tmp_path / "new" / "deeper" / "x.rrd") is None
    assert outputs.check_destination(tmp_path / "file") is None  # replaced
    assert "not a file" in outputs.check_destination(tmp_path / "folder")
    assert "not a folder" in outputs.check_destination(tmp_path / "file" / "x.rrd")


# --- issue 12: outputs that never destroy -------------------------------------------------
def tree(folder) -> dict[str, str]:
    """Every file under ``folder`` with its text: what "untouched" is checked against."""
    return {
        str(p.relative_to(folder)): p.read_text() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def test_a_folder_of_outputs_replaces_only_a_folder_it_wrote(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    (tmp_path / "notes.txt").write_text("keep")
    before = tree(tmp_path)
    for taken in (mine, tmp_path / "notes.txt"):
        with pytest.raises(FileExistsError), outputs.atomic_directory(taken) as folder:
            (folder / "table.json").write_text("{}")
    assert tree(tmp_path) == before  # nothing replaced, no temporary left

    out = tmp_path / "out"
    with outputs.atomic_directory(out) as folder:
        (folder / "a.txt").write_text("first")
    assert (out / outputs.MARKER).is_file()
    with outputs.atomic_directory(out) as folder:  # marked: replaced as a whole
        (folder / "b.txt").write_text("second")
    assert sorted(p.name for p in out.iterdir()) == [outputs.MARKER, "b.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "notes.txt", "out"]


def test_check_folder_destination_refuses_the_current_folder_and_its_ancestors(
    tmp_path, monkeypatch
):
    inner = tmp_path / "a" / "b"
    inner.mkdir(parents=True)
    (inner / outputs.MARKER).write_text("")  # even a marked folder: the user works in it
    monkeypatch.chdir(inner)
    for path in (".", inner, tmp_path / "a", "..", inner / ".."):
        assert "current folder" in str(outputs.check_folder_destination(path)), path
    assert outputs.check_folder_destination("new") is None


def test_no_output_may_be_an_input(tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text("[run]\n")
    os.link(scenario, tmp_path / "alias.toml")
    os.symlink(scenario, tmp_path / "link.toml")
    for path in (
        scenario,
        tmp_path / "alias.toml",
        tmp_path / "link.toml",
        tmp_path / "." / "s.toml",
    ):
        assert "is an input" in str(outputs.check_destination(path, [scenario])), path
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / outputs.MARKER).write_text("")
    (tmp_path / "maps" / "room.wkt").write_text("")
    reason = outputs.check_folder_destination(tmp_path / "maps", [tmp_path / "maps" / "room.wkt"])
    assert "holds an input" in str(reason)
    assert outputs.check_destination(tmp_path / "other.json", [scenario]) is None


def dead_pid() -> int:
    """The id of a process that has exited (and been reaped)."""
    child = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    return int(child.stdout)


def test_stale_temporaries_of_a_killed_writer_are_removed_and_live_ones_kept(tmp_path):
    target = tmp_path / "hall.rrd"
    stale_file = tmp_path / f".hall.rrd.{dead_pid()}-abc.part"
    stale_file.write_text("40 MB of a killed run")
    stale_folder = tmp_path / f".hall.rrd.{dead_pid()}-def.part"
    stale_folder.mkdir()
    (stale_folder / "table.json").write_text("{}")
    live = tmp_path / f".hall.rrd.{os.getppid()}-ghi.part"  # our parent is alive
    live.write_text("being written")
    unrelated = tmp_path / ".hall.rrd.notes.part"
    unrelated.write_text("not ours")
    outputs.write_text(target, "new")
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["hall.rrd", live.name, unrelated.name]
    )


def test_a_failed_write_names_the_users_path_not_a_temporary(tmp_path):
    """A full disk (per-file size limit, ``ulimit -f``) while writing JSON: the OSError names
    the destination, and nothing is left beside it."""
    code = (
        "import sys\n"
        "from scenarios import outputs\n"
        "try:\n"
        "    outputs.write_json(sys.argv[1], {'x': 'y' * 100000})\n"
        "except OSError as exc:\n"
        "    print(exc.filename); print(exc.strerror)\n"
    )
    target = tmp_path / "summary.json"
    done = subprocess.run(
        [sys.executable, "-c", code, str(target)],
        preexec_fn=small_file_limit(10_000),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    filename, reason = done.stdout.splitlines()
    assert filename == str(target) and reason == "File too large"
    assert not any(tmp_path.iterdir())


def test_a_truncated_recording_does_not_verify(tmp_path):
    from scenarios.errors import InternalError
    from scenarios.recording import verify_recording, write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("symmetric").with_run(duration_s=2.0)
    result = run_scenario(spec)
    whole = tmp_path / "whole.rrd"
    write_recording(whole, spec, result.log, result.estimation)  # verifies itself
    data = whole.read_bytes()
    recording_id = f"{spec.name}-seed{spec.run.seed}"
    for cut in (len(data) - 1, len(data) - 200, len(data) // 2, 10):
        truncated = tmp_path / f"cut{cut}.rrd"
        truncated.write_bytes(data[:cut])
        with pytest.raises(InternalError, match="does not read back"):
            verify_recording(truncated, recording_id)
    with pytest.raises(InternalError, match="holds"):
        verify_recording(whole, "another-seed1")


def test_a_temporary_that_cannot_be_created_is_reported_under_the_users_path(tmp_path):
    """``/proc`` takes no new file: the error names the destination, not ``.x.<pid>-....part``,
    and the first destination's temporary is gone too."""
    with (
        pytest.raises(OSError) as failure,
        outputs.atomic_paths(tmp_path / "a.rrd", "/proc/x.json"),
    ):
        pass
    assert failure.value.filename == "/proc/x.json"
    assert not any(tmp_path.iterdir())


class Stop(Exception):
    """What the CLI's stop handler raises, here raised by this test's handler."""


@pytest.fixture
def sigterm_raises():
    """SIGTERM raises :class:`Stop` while the test runs (as the CLI's handler does)."""

    def stop(signum, frame):
        raise Stop(signum)

    previous = signal.signal(signal.SIGTERM, stop)
    yield
    signal.signal(signal.SIGTERM, previous)


def signal_self_after(function):
    """``function`` that sends this process SIGTERM once its work is done: the signal
    arrives at the worst moment, with the temporary made and not yet recorded."""

    def signalled(*args, **kwargs):
        made = function(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        return made

    return signalled


@pytest.mark.parametrize("which", [0, 1])
def test_a_stop_while_a_temporary_is_made_leaves_no_temporary(
    tmp_path, monkeypatch, sigterm_raises, which
):
    """Before, a SIGTERM between ``mkstemp`` and the list of temporaries left a .part
    behind (seen in CI: the second destination's). Now it is delivered once recorded."""
    made = []
    real = outputs.tempfile.mkstemp

    def counted(*args, **kwargs):
        made.append(None)
        fd_name = real(*args, **kwargs)
        if len(made) == which + 1:
            os.kill(os.getpid(), signal.SIGTERM)
        return fd_name

    monkeypatch.setattr(outputs.tempfile, "mkstemp", counted)
    first, second = tmp_path / "one.rrd", tmp_path / "two.json"
    second.write_text("previous")
    with pytest.raises(Stop), outputs.atomic_paths(first, second) as temporaries:
        for tmp in temporaries:
            tmp.write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.json"]
    assert second.read_text() == "previous"


def test_a_stop_while_moving_into_place_lands_all_or_nothing(tmp_path, monkeypatch, sigterm_raises):
    """A SIGTERM while the outputs are moved (here after the first move) takes effect once
    every output is in place and the previous file's backup removed: no half swap."""
    monkeypatch.setattr(outputs.os, "replace", signal_self_after(os.replace))
    first, second = tmp_path / "one.rrd", tmp_path / "two.json"
    second.write_text("previous")
    with pytest.raises(Stop), outputs.atomic_paths(first, second) as (tmp_first, tmp_second):
        tmp_first.write_text("1")
        tmp_second.write_text("2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.rrd", "two.json"]
    assert first.read_text() == "1" and second.read_text() == "2"


def test_a_stop_while_a_folder_is_swapped_keeps_a_whole_folder(
    tmp_path, monkeypatch, sigterm_raises
):
    """A SIGTERM just after the previous folder was set aside (before, it stayed in a
    ``.old`` folder that the next write removed, and ``out`` was missing): now the swap
    completes first, and no temporary folder is left."""
    out = tmp_path / "out"
    with outputs.atomic_directory(out) as folder:
        (folder / "a.txt").write_text("first")
    monkeypatch.setattr(outputs.os, "replace", signal_self_after(os.replace))
    with pytest.raises(Stop), outputs.atomic_directory(out) as folder:
        (folder / "b.txt").write_text("second")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert sorted(p.name for p in out.iterdir()) == [outputs.MARKER, "b.txt"]


def test_a_stop_while_a_temporary_folder_is_made_leaves_none(tmp_path, monkeypatch, sigterm_raises):
    monkeypatch.setattr(outputs.tempfile, "mkdtemp", signal_self_after(tempfile.mkdtemp))
    with pytest.raises(Stop), outputs.atomic_directory(tmp_path / "out") as folder:
        (folder / "a.txt").write_text("never")
    assert list(tmp_path.iterdir()) == []

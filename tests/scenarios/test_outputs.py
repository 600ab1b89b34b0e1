"""The atomic writers: all-or-nothing over several files, usual permissions, refused destinations."""

from __future__ import annotations

import os
import stat

import pytest

from scenarios import outputs


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
        for tmp, text in zip(temporaries, ("new recording", "summary", "third")):
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
    with pytest.raises(RuntimeError), outputs.atomic_paths(first, second) as (tmp_first, tmp_second):
        tmp_first.write_text("1")
        raise RuntimeError("crash")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.txt"] and second.read_text() == "old"


def test_the_same_destination_twice_is_refused(tmp_path):
    with pytest.raises(ValueError, match="twice"), outputs.atomic_paths(tmp_path / "x", tmp_path / "." / "x"):
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

"""``robotsim warmup`` and the compile-free timings (issue 17): after the warm-up a run compiles
nothing; warm-ups take turns on their lock; a timing numba compiled into is refused.

The two cold-cache tests run in new interpreters with an empty ``NUMBA_CACHE_DIR``, so that
what earlier tests compiled cannot stand in for the warm-up.
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from scenarios.errors import InternalError
from scenarios.warmup import PARTS, lock_path, no_compilation, turn

ROOT = Path(__file__).resolve().parents[2]

#: Python that prints the qualified names of what numba compiled while ``BODY`` ran.
RECORD_COMPILES = """
import json
from numba.core import event
with event.install_recorder("numba:compile") as recorder:
    BODY
names = sorted({e.data["dispatcher"].py_func.__qualname__ for _, e in recorder.buffer})
print("COMPILED " + json.dumps(names))
"""


def python(code: str, cache: Path, cwd: Path) -> str:
    """Run ``code`` in a new Python on this tree with numba's cache in ``cache``; its stdout."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=environment,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def compiled_by(body: str, cache: Path, cwd: Path) -> list[str]:
    """What numba compiled while ``body`` (one statement) ran in a new Python on ``cache``."""
    out = python(RECORD_COMPILES.replace("BODY", body), cache, cwd)
    return json.loads(out.rsplit("COMPILED ", 1)[1])


@pytest.mark.slow
def test_after_the_warm_up_a_run_compiles_nothing(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    warm = compiled_by("__import__('scenarios.warmup').warmup.warm_up(('run',))", cache, tmp_path)
    assert warm, "the warm-up compiled nothing into an empty cache: the test would prove nothing"
    run = (
        "__import__('scenarios.cli').cli.main(['run', 'hall', '--duration', '3', "
        "'--rrd', 'a.rrd', '--summary', 'a.json'])"
    )
    assert compiled_by(run, cache, tmp_path) == []
    assert json.loads((tmp_path / "a.json").read_text())["containment"] == 1.0
    # the particle filter too: its updates, resampling and recovery over a longer run
    mcl = (
        "__import__('scenarios.runner').runner.run_scenario(__import__('scenarios.spec')"
        ".spec.load_scenario('office').with_estimation(estimator='mcl').with_run(duration_s=8))"
    )
    assert compiled_by(mcl, cache, tmp_path) == []
    # the idle join of a large hall's first set, and the tightening's piece test
    join_and_pieces = (
        "[__import__('scenarios.runner').runner.run_scenario(__import__('scenarios.spec')"
        ".spec.load_scenario(name).with_estimation(tighten_levels=6).with_run(duration_s=2)) "
        "for name in ('big_hall', 'corridor')]"
    )
    assert compiled_by(join_and_pieces, cache, tmp_path) == []


@pytest.mark.slow
def test_the_motion_model_cost_is_timed_after_the_compilation(tmp_path):
    """In an empty cache the filter's first steps compile; :func:`run_filter` must have done
    so before its clock started (``no_compilation`` raises otherwise)."""
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    code = (
        "import numpy as np\n"
        "from localization.motion_models import MODELS\n"
        "from robotsim.vehicle.drives import highway_drive\n"
        "from robotsim.vehicle.sensors import VehicleSensorParams, measure\n"
        "from scenarios.reproduce.motion_models import run_filter\n"
        "drive = highway_drive(np.random.default_rng(0), 20.0)\n"
        "meas = measure(drive, VehicleSensorParams(), np.random.default_rng(1), runs=2)\n"
        "draws = np.random.default_rng(2).standard_normal((2, 6))\n"
        "result = run_filter(MODELS['CTRV'], drive, meas, draws)\n"
        "print('SECONDS', result.seconds)\n"
    )
    compiled = compiled_by(f"exec({code!r})", cache, tmp_path)
    assert compiled, "nothing compiled into an empty cache: the test would prove nothing"


def test_a_timing_numba_compiled_into_is_refused():
    @numba.njit
    def twice(x):
        return 2.0 * x

    refused = pytest.raises(InternalError, match=r"a figure: numba compiled .*twice while timed")
    with refused, no_compilation("a figure"):
        twice(1.0)
    with no_compilation("a figure"):  # compiled now: timing it is fine
        assert twice(2.0) == 4.0


def test_warm_ups_take_turns_on_the_lock(tmp_path):
    """While one process holds the lock another cannot take it; once released it can."""
    lock = tmp_path / "warmup.lock"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys\nfrom pathlib import Path\nfrom scenarios.warmup import turn\n"
            f"with turn(Path({str(lock)!r})):\n    print('held', flush=True)\n    sys.stdin.readline()\n",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert holder.stdout is not None and holder.stdin is not None
        assert holder.stdout.readline().strip() == "held"
        with open(lock, "a") as handle:
            with pytest.raises(BlockingIOError):
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            holder.stdin.write("done\n")
            holder.stdin.flush()
            assert holder.wait(timeout=60) == 0
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)  # free now
            fcntl.flock(handle, fcntl.LOCK_UN)
    finally:
        holder.kill()
        holder.wait()
    with turn(lock):  # and the context manager takes it too
        pass


def test_one_lock_per_install_and_cache(monkeypatch):
    first = lock_path()
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/somewhere/else")
    assert lock_path() != first and lock_path().parent == first.parent


@pytest.mark.slow  # compiles the filter steps if no earlier test has
def test_the_command_runs_the_parts_it_is_asked_for(capsys):
    from scenarios.cli import main

    assert set(PARTS) == {"run", "filters"}
    assert main(["warmup", "--only", "filters"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("robotsim warmup: filters ") and "run" not in line.split(";")[0]
    with pytest.raises(SystemExit) as refused:
        main(["warmup", "--only", "nonsense"])
    assert refused.value.code == 2

"""``robotsim warmup``: compile the numba kernels of the built-in paths into numba's disk cache.

numba compiles a kernel at its first call and, with ``cache=True``, keeps the machine code on
disk (beside the installed package, in ``__pycache__``, or under ``NUMBA_CACHE_DIR``); a later
process loads it in milliseconds. A fresh install has no cache, so without this the first
``robotsim run`` pays the compilation (BENCHMARKS.md, "First run"). Run it once after an
install (``.ci/run`` does); it takes each built-in path a few steps:

- ``run``: the default scenario for :data:`RUN_S` with each dead-reckoning filter, the IMAGESP
  tracker, the ray test and the tightening pass (:data:`RUN_VARIANTS`), and for
  :data:`MCL_RUN_S` with the particle filter: the dead-reckoning step, the sonar box tests,
  the in-room test, the ray kernels, the tightening's piece test and the MCL kernels
  (``localization.compiled.mcl``, the expected ranges of ``scenarios.mcl_ranges``); and
  :data:`JOIN_MAP` for :data:`RUN_S`, whose large first set makes SIVIA join boxes back
  across their idle axes (``intervals.sivia``), which the default room's never does;
- ``filters``: one predict and one update of the UKF (additive and augmented noise) and of
  the EKF for every motion model of :data:`localization.motion_models.MODELS`, with the GPS
  and the pose measurement models: the compiled filter steps.

A second warm-up loads what the first compiled and so takes a few seconds. Warm-ups started
side by side (CI jobs, a campaign's parent and a user's run) take turns on a lock file
(:func:`turn`), so that no two of them compile the same entries into one cache at once.

A timing that a table reports runs inside :func:`no_compilation`, which refuses a figure that
counted numba compiling: the code that times warms its path first, untimed.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from scenarios.errors import InternalError

#: Simulated seconds of each short run of the ``run`` part (an interval epoch at 0 s and 1 s).
RUN_S = 1.0
#: The ``[estimation]`` settings the ``run`` part runs the default scenario with: each
#: selects compiled kernels the others do not.
RUN_VARIANTS: tuple[dict[str, object], ...] = (
    {},
    {"filter": "iukf"},
    {"filter": "ekf"},
    {"filter": "iekf"},
    {"tracker": "imagesp"},
    {"ray_test": True},
    {"tighten_levels": 3},
)
#: The built-in scenario whose first epoch takes the idle join (a large open hall).
JOIN_MAP = "big_hall"
#: Simulated seconds of the default scenario's run with the particle filter: long enough for
#: the robot to move past ``update_min_d``, so that the motion model is sampled (1 s is not).
MCL_RUN_S = 3.0


def warm_runs() -> None:
    """The default scenario for :data:`RUN_S` with each of :data:`RUN_VARIANTS`, and for
    :data:`MCL_RUN_S` with the particle filter; :data:`JOIN_MAP` for :data:`RUN_S`."""
    from scenarios.catalog import DEFAULT_MAP
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario(DEFAULT_MAP).with_run(duration_s=RUN_S)
    for variant in RUN_VARIANTS:
        run_scenario(spec.with_estimation(**variant))
    run_scenario(spec.with_estimation(estimator="mcl").with_run(duration_s=MCL_RUN_S))
    run_scenario(load_scenario(JOIN_MAP).with_run(duration_s=RUN_S))


def warm_filters() -> None:
    """A UKF step (additive and augmented process noise) and an EKF step of every motion
    model, each a prediction then a GPS and a pose update, on a batch of two runs; and the
    same filters' lean entries, a step and a sequence, on one run."""
    import numpy as np

    from localization.compiled.lean import LeanEKF, LeanUKF
    from localization.ekf import ExtendedKalmanFilter
    from localization.gaussian import Gaussian
    from localization.models import ProcessNoise
    from localization.motion_models import MODELS, gps_model, pose_model
    from localization.ukf import UnscentedKalmanFilter

    dt_s = 0.01
    gps, pose = gps_model(np.eye(2)), pose_model(np.eye(3))
    for model in MODELS.values():
        start = Gaussian(
            np.full((2, model.n), 0.1),
            np.broadcast_to(np.eye(model.n), (2, model.n, model.n)),
            model.angle_indices,
        )
        steps = (
            (UnscentedKalmanFilter(), model.process_model(0.01 * np.eye(model.n))),
            (
                UnscentedKalmanFilter(),
                model.process_model(
                    np.diag(model.process_noise_std(dt_s) ** 2), noise=ProcessNoise.AUGMENTED
                ),
            ),
            (ExtendedKalmanFilter(), model.process_model(0.01 * np.eye(model.n))),
        )
        for kalman, process in steps:
            belief = kalman.predict(start, process, dt_s)
            belief = kalman.update(belief, np.zeros((2, 2)), gps)
            if 2 in model.angle_indices:  # the pose model reads the heading as entry 2
                kalman.update(belief, np.zeros((2, 3)), pose)
        # the lean entries (localization.compiled.lean): a step and a sequence of each
        one = Gaussian(np.full(model.n, 0.1), np.eye(model.n), model.angle_indices)
        for measurement in (gps, pose) if 2 in model.angle_indices else (gps,):
            z = np.zeros((1, measurement.R.shape[0]))
            for kalman, process in steps:
                lean = (
                    LeanEKF(process, measurement, one, dt_s)
                    if isinstance(kalman, ExtendedKalmanFilter)
                    else LeanUKF(kalman, process, measurement, one, dt_s)
                )
                lean.step(z[0])
                lean.run(z)


#: The parts of the warm-up, in the order they run.
PARTS: dict[str, Callable[[], None]] = {"run": warm_runs, "filters": warm_filters}


def lock_path() -> Path:
    """The lock file of this installation's cache: one per (package folder, ``NUMBA_CACHE_DIR``,
    user), in the temporary folder (always writable, unlike an installed package; per user,
    since another user's lock file could not be opened, and a shared read-only install
    leaves each user a cache of their own)."""
    package = Path(__file__).resolve().parent.parent
    key = f"{package}\0{os.environ.get('NUMBA_CACHE_DIR', '')}\0{os.getuid()}".encode()
    return (
        Path(tempfile.gettempdir()) / f"robotsim-warmup-{hashlib.sha256(key).hexdigest()[:16]}.lock"
    )


@contextlib.contextmanager
def turn(path: Path | None = None) -> Iterator[None]:
    """Hold the warm-up lock (``path``, default :func:`lock_path`) while the block runs: a
    second process waits here until the first is done, then loads what it compiled."""
    path = path or lock_path()
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def warm_up(parts: tuple[str, ...] = tuple(PARTS)) -> dict[str, float]:
    """Run the warm-up ``parts`` (names of :data:`PARTS`) under the lock; their wall times, s."""
    seconds = {}
    with turn():
        for name in parts:
            start = time.perf_counter()
            PARTS[name]()
            seconds[name] = time.perf_counter() - start
    return seconds


@contextlib.contextmanager
def no_compilation(what: str) -> Iterator[None]:
    """Run the block, a timed one, and raise :class:`InternalError` if numba compiled anything
    meanwhile (its ``numba:compile`` events): ``what``'s figure would count compile time as
    run time. Loading an entry from the disk cache is not a compilation (milliseconds)."""
    from numba.core import event

    with event.install_recorder("numba:compile") as recorder:
        yield
    compiled = sorted({item.data["dispatcher"].py_func.__qualname__ for _, item in recorder.buffer})
    if compiled:
        raise InternalError(
            f"{what}: numba compiled {', '.join(compiled)} while timed (warm the path up first)"
        )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim warmup``."""
    parser.add_argument(
        "--only",
        choices=tuple(PARTS),
        action="append",
        help="warm up only this part (repeatable; default: all of them)",
    )


def main(args: argparse.Namespace) -> int:
    """``robotsim warmup``: one line with each part's wall time."""
    seconds = warm_up(tuple(args.only or PARTS))
    done = ", ".join(f"{name} {s:.1f} s" for name, s in seconds.items())
    print(f"robotsim warmup: {done}; numba's disk cache now holds the built-in kernels")
    sys.stdout.flush()
    return 0

"""Benchmark of the default pipeline on every built-in floor plan, one subprocess per plan.

    python benchmarks/buildings.py [PLAN ...] [--duration S] [--timeout S] [--memory-gib G]
                                   [--compare DIR] [--set KEY=VALUE ...] [--write]

Runs what ``robotsim run`` runs (simulation, dead reckoning, interval epochs, fusion,
summary, rerun recording to a temporary file) on each built-in scenario (default: all of
them, plus ``big_hall`` with ``lost_echo_prob = 0.5``), ``--duration`` simulated seconds
each (default 60). A plan may be named as a variant of a built-in one, ``"PLAN[, lost_echo_prob
P][, seed N]"`` (``"corridor, lost_echo_prob 0.5, seed 1"``: ``corridor`` with ``[sensors.sonar]
lost_echo_prob = 0.5`` and ``[run] seed = 1``; ``_common.variant_parts``). Each run is a
child process, so its peak memory is its own (the ``ru_maxrss`` of ``os.wait4``); its address
space is capped with ``RLIMIT_AS`` (``--memory-gib``, default 4) so that a run asking for too
much fails with a
``MemoryError`` (reported ``memory > cap``, with the size asked and where) instead of
exhausting the machine, and it is killed after ``--timeout`` wall seconds (reported
``timeout``). Before its plan, each child runs 3 s of ``hall`` untimed and records it, so
that loading the compiled kernels is not counted in the first epoch, nor the recording's
first-use imports in the recording.

Reported per plan, from the run's summary (``scenarios.runner.RunResult.summary_with_timing``)
and its epoch log: the real-time factor of the whole run, the interval epoch's median and
95th percentile (all epochs), the 95th percentile of the tracking epochs alone, the global
localisation time (the first epoch, always a global one), the peak memory, the mean (x, y)
area of the outer set, the epochs without a set, and the status (with the containment
when below 1). The targets of issue 13: at least 100x real time, tracking epoch p95 at
most 10 ms, global localisation at most 1 s on ``office_floor``, peak memory at most
1 GiB everywhere.

``--compare DIR`` runs each plan a second time with another source tree's code (a
checkout of another commit; the scenario files are always this checkout's), for figures
side by side; the ``code`` column names each row's commit. ``--set KEY=VALUE`` (repeatable)
replaces a key of every scenario's ``[estimation]`` table (the value read as JSON:
``--set tighten_levels=12``), in both trees. ``--write`` puts the default pipeline's table
(no ``--set``) in the ``Buildings`` section of ``BENCHMARKS.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _common import (
    add_set_argument,
    code_label,
    load_variant,
    machine_line,
    markdown_table,
    parsed_settings,
    settings_arguments,
    variant_parts,
    write_section,
)

#: Variants benchmarked by default besides the built-in scenarios (``_common.variant_parts``).
VARIANTS = ("big_hall, lost_echo_prob 0.5",)

#: The source tree this script belongs to, and its built-in scenario files.
REPOSITORY = Path(__file__).resolve().parent.parent
SCENARIO_FOLDER = REPOSITORY / "scenarios" / "builtin"

#: Simulated seconds of ``hall`` a child runs before its plan (one-time costs out of the figures).
WARM_UP_S = 3.0

#: Exit status of a child whose run raised ``MemoryError`` (the address-space cap).
MEMORY_EXIT = 3

SECTION = "Buildings: the default pipeline on every built-in floor plan"


# The child: one run -------------------------------------------------------------------


def progress_path(out: Path) -> Path:
    """Where a child keeps the share of its run done (read when it is killed)."""
    return out.with_suffix(".progress")


class ProgressFile:
    """A ``run_scenario`` progress callback writing the share done (percent) to a file,
    once per percent."""

    def __init__(self, path: Path):
        self._path = path
        self._percent = -1

    def __call__(self, fraction: float) -> None:
        percent = int(100 * fraction)
        if percent != self._percent:
            self._percent = percent
            self._path.write_text(str(percent), encoding="ascii")


def child(name: str, duration_s: float, out: Path, changes: dict | None = None) -> int:
    """Run one plan (a built-in name or a variant, ``_common.load_variant``); write its figures
    to ``out``. ``changes``: keys of ``[estimation]`` replaced in the plan's scenario (``--set``)."""
    from scenarios.epochs import GLOBAL, TRACKING
    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    # the scenario files of this checkout, so that another code tree (--compare) runs them too
    spec = load_variant(name, SCENARIO_FOLDER).with_run(duration_s=duration_s)
    spec = spec.with_estimation(**(changes or {}))
    try:
        # warm-up, not timed: loads the compiled kernels (numba's cache) and the lazy imports,
        # which would otherwise land in the first epoch, the global localisation, and in the
        # first recording (rerun imports pyarrow.compute there: about 0.13 s once a process)
        # (with the same --set keys, so that their kernels are loaded too)
        warm = load_scenario(str(SCENARIO_FOLDER / "hall.toml")).with_run(duration_s=WARM_UP_S)
        warm = warm.with_estimation(**(changes or {}))
        warm_result = run_scenario(warm)
        with tempfile.TemporaryDirectory() as folder:
            write_recording(
                Path(folder) / "warm.rrd", warm, warm_result.log, warm_result.estimation
            )
        start = time.perf_counter()
        result = run_scenario(spec, progress=ProgressFile(progress_path(out)))
        with tempfile.TemporaryDirectory() as folder:
            clock = time.perf_counter()
            write_recording(Path(folder) / "run.rrd", spec, result.log, result.estimation)
            recording_s = time.perf_counter() - clock
        summary = result.summary_with_timing(
            recording_s=recording_s, wall_s=time.perf_counter() - start
        )
    except MemoryError as error:
        # one line for the parent's table: the allocation refused and where it was asked for
        where = traceback.extract_tb(error.__traceback__)[-1]
        place = f"{Path(where.filename).name}:{where.lineno} {where.name}"
        print(f"MemoryError at {place}: {error}", file=sys.stderr)
        return MEMORY_EXIT
    epochs = result.estimation.epochs
    is_global = epochs.status == GLOBAL
    summary["global_localisation_ms"] = (
        1e3 * float(epochs.elapsed_s[is_global][0]) if is_global.any() else None
    )
    tracking_ms = 1e3 * epochs.elapsed_s[epochs.status == TRACKING]
    summary["tracking_epoch_ms_p95"] = (
        float(np.percentile(tracking_ms, 95)) if tracking_ms.size else None
    )
    summary["segments"] = len(spec.map.segments)
    out.write_text(json.dumps(summary), encoding="utf-8")
    return 0


# The parent: one subprocess per plan --------------------------------------------------


@dataclass
class Outcome:
    """What one child gave: its status, its peak memory and (when it finished) its summary."""

    name: str
    status: str
    wall_s: float
    peak_mib: float
    summary: dict | None


def _cap_memory(limit_bytes: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))


def run_child(
    name: str,
    duration_s: float,
    timeout_s: float,
    memory_gib: float,
    code: Path,
    changes: dict | None = None,
) -> Outcome:
    """One plan in a child process importing the code tree ``code`` (its ``PYTHONPATH``),
    capped at ``memory_gib`` GiB of address space and ``timeout_s`` wall seconds, with the
    ``[estimation]`` keys ``changes`` replaced."""
    limit = int(memory_gib * 2**30)
    environment = {**os.environ, "PYTHONPATH": str(code)}
    with tempfile.TemporaryDirectory() as folder:
        out, err = Path(folder) / "summary.json", Path(folder) / "stderr.txt"
        command = [sys.executable, __file__, "--child", name, "--duration", str(duration_s)]
        command += ["--out", str(out), *settings_arguments(changes or {})]
        start = time.perf_counter()
        with open(err, "wb") as stderr:
            # preexec_fn runs between fork and exec: it only sets the limit
            child_process = subprocess.Popen(
                command,
                stdout=subprocess.DEVNULL,
                stderr=stderr,
                env=environment,
                preexec_fn=lambda: _cap_memory(limit),
            )
        status_word, usage, timed_out = 0, None, False
        try:
            while True:
                pid, status_word, usage = os.wait4(child_process.pid, os.WNOHANG)
                if pid:
                    break
                if time.perf_counter() - start > timeout_s:
                    os.kill(child_process.pid, signal.SIGKILL)
                    _, status_word, usage = os.wait4(child_process.pid, 0)
                    timed_out = True
                    break
                time.sleep(0.1)
        except BaseException:  # Ctrl-C or any error here: never leave the child running
            os.kill(child_process.pid, signal.SIGKILL)
            os.wait4(child_process.pid, 0)
            raise
        child_process.returncode = os.waitstatus_to_exitcode(status_word)
        wall_s = time.perf_counter() - start
        peak_mib = usage.ru_maxrss / 1024.0 if usage else float("nan")  # KiB on Linux
        code = child_process.returncode
        message = err.read_text(encoding="utf-8", errors="replace").strip().splitlines()
        if timed_out:
            status = f"timeout (> {timeout_s:g} s{_progress_note(progress_path(out))})"
        elif code == MEMORY_EXIT or any("MemoryError" in line for line in message[-3:]):
            status = f"memory > {memory_gib:g} GiB ({_refused(message)})"
        elif code != 0:
            status = f"failed (exit {code}: {message[-1] if message else 'no message'})"
        else:
            status = "ok"
        summary = json.loads(out.read_text(encoding="utf-8")) if out.is_file() else None
    return Outcome(name, status, wall_s, peak_mib, summary)


def _progress_note(path: Path) -> str:
    """How far a killed child got: the share of its interval epochs done (the progress
    callback's fraction past the simulation's share, ``scenarios.runner``)."""
    from scenarios.runner import SIMULATION_PROGRESS

    if not path.is_file():
        return ""
    fraction = int(path.read_text(encoding="ascii")) / 100.0
    if fraction < SIMULATION_PROGRESS:
        return ", in the simulation"
    epochs = (fraction - SIMULATION_PROGRESS) / (1.0 - SIMULATION_PROGRESS)
    return f", {epochs:.0%} of the epochs done"


def _refused(message: list[str]) -> str:
    """What the child's ``MemoryError`` line says, shortened: the size asked and where."""
    line = next((line for line in reversed(message) if "MemoryError" in line), "")
    size = re.search(r"allocate ([0-9]+(?:\.[0-9]+)?)\.? ([KMGTP]?i?B)", line)
    place = re.search(r"at (\S+:\d+ \w+)", line)
    parts = [
        f"asked {size.group(1)} {size.group(2)}" if size else "",
        place.group(1) if place else "",
    ]
    return ", ".join(part for part in parts if part) or "MemoryError"


def _figure(value, pattern: str) -> str:
    return "-" if value is None else pattern.format(value)


def table_row(outcome: Outcome) -> list[str]:
    """A markdown row: plan, segments, real-time factor, epoch median/p95, global
    localisation, peak memory, mean set area, containment, status."""
    s = outcome.summary or {}
    timing = s.get("timing", {})
    box = s.get("box") or {}
    status = outcome.status
    if s and s.get("containment") is not None and s["containment"] < 1.0:
        status += f", containment {s['containment']:.3f}"
    return [
        outcome.name,
        _figure(s.get("segments"), "{}"),
        _figure(timing.get("realtime_factor"), "{:.1f}x"),
        _figure(timing.get("ia_epoch_ms_median"), "{:.1f}")
        + " / "
        + _figure(timing.get("ia_epoch_ms_p95"), "{:.1f}"),
        _figure(s.get("tracking_epoch_ms_p95"), "{:.1f}"),
        _figure(s.get("global_localisation_ms"), "{:.0f}"),
        f"{outcome.peak_mib:.0f}",
        _figure(box.get("mean_area_m2"), "{:.3f}"),
        _figure(s.get("empty_epochs"), "{}"),
        status,
    ]


HEADER = [
    "plan",
    "code",
    "segments",
    "real-time factor",
    "epoch median / p95 (ms)",
    "tracking epoch p95 (ms)",
    "global localisation (ms)",
    "peak memory (MiB)",
    "mean set area (m²)",
    "empty epochs",
    "status",
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plans", nargs="*", help="built-in scenarios or variants (default: all)")
    parser.add_argument(
        "--duration", type=float, default=60.0, help="simulated seconds (default: %(default)s)"
    )
    parser.add_argument(
        "--timeout", type=float, default=300.0, help="wall seconds per plan (default: %(default)s)"
    )
    parser.add_argument(
        "--memory-gib",
        type=float,
        default=4.0,
        help="address-space cap per plan, GiB (default: %(default)s)",
    )
    parser.add_argument(
        "--compare",
        type=Path,
        metavar="DIR",
        help="another source tree (a checkout) to run each plan with too, side by side",
    )
    add_set_argument(parser)
    parser.add_argument("--write", action="store_true", help="update BENCHMARKS.md")
    parser.add_argument("--child", metavar="PLAN", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    changes = parsed_settings(parser, args.set)
    if args.child:
        return child(args.child, args.duration, args.out, changes)
    if changes and args.write:
        parser.error("--write keeps the default pipeline's table: not with --set")

    from scenarios.mcl_pipeline import Estimator
    from scenarios.spec import builtin_names, load_scenario

    # the interval stage's benchmark: the particle filter's scenarios are benchmarks/mcl.py's
    interval_plans = [
        name
        for name in builtin_names()
        if load_scenario(name).estimation.estimator == Estimator.INTERVALS
    ]
    plans = args.plans or [*interval_plans, *VARIANTS]
    for plan in plans:
        try:
            base = variant_parts(plan)[0]
        except ValueError as error:
            parser.error(str(error))
        if base not in interval_plans:
            parser.error(f"unknown plan {base!r}; choose from {', '.join(interval_plans)}")
    if not (args.duration > 0 and args.timeout > 0 and args.memory_gib > 0):
        parser.error("--duration, --timeout and --memory-gib must be > 0")
    trees = [REPOSITORY]
    if args.compare:
        if not (args.compare / "scenarios" / "runner.py").is_file():
            parser.error(f"--compare {args.compare}: not a source tree (no scenarios/runner.py)")
        trees.append(args.compare.resolve())
    labels = {tree: code_label(tree) for tree in trees}  # once: the trees may change meanwhile
    # a polite kill (SIGTERM) unwinds like Ctrl-C, so the running child is killed too
    signal.signal(signal.SIGTERM, signal.default_int_handler)

    load_before = os.getloadavg()
    rows = []
    for plan in plans:
        for tree in trees:
            outcome = run_child(plan, args.duration, args.timeout, args.memory_gib, tree, changes)
            rows.append([table_row(outcome)[0], labels[tree], *table_row(outcome)[1:]])
            print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    load_after = os.getloadavg()
    settings = (
        "the scenario's own settings (the default pipeline, as `robotsim run`, recording included)"
        if not changes
        else "the scenario's settings with "
        + ", ".join(f"`{k} = {v!r}`" for k, v in changes.items())
        + " (as `robotsim run`, recording included)"
    )
    body = "\n".join(
        [
            f"`python benchmarks/buildings.py --duration {args.duration:g} --timeout "
            f"{args.timeout:g} --memory-gib {args.memory_gib:g}"
            f"{''.join(' ' + a for a in settings_arguments(changes))}`: {args.duration:g} s "
            f"simulated per plan with {settings}, one child process per plan capped at "
            f"{args.memory_gib:g} GiB of address space and {args.timeout:g} s of wall time. "
            "Epoch median / p95: all epochs; tracking p95: the tracking epochs alone; global "
            "localisation: the first epoch. Issue 13's targets: >= 100x real time, tracking "
            "p95 <= 10 ms, global localisation <= 1 s on office_floor, peak memory <= 1 GiB.",
            "",
            markdown_table(HEADER, rows),
            "",
            f"Machine: {machine_line('numba', 'shapely')}; 1-minute load "
            f"{load_before[0]:.1f} before, {load_after[0]:.1f} after.",
        ]
    )
    print(body)
    if args.write:
        write_section(SECTION, body)
    return 0


if __name__ == "__main__":
    sys.exit(main())

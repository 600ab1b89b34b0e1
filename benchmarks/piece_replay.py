"""Benchmark: the tightening's piece test against another tree's on recorded calls, CPU time.

    python benchmarks/piece_replay.py record DIR [PLAN ...] [--duration S] [--set KEY=VALUE]
    python benchmarks/piece_replay.py compare DIR --base TREE [--repeat R]

``record``: steps the tracker over ``--duration`` simulated seconds of each plan (default
hall, office, apartment, corridor; 20 s) as ``benchmarks/tracking_epochs.py`` does, with the
``[estimation]`` changes of ``--set`` (default ``tighten_levels=9``,
``tighten_max_tested=10000000``), and pickles the arguments of every call of
:func:`intervals.sonar.pieces.piece_rejections_into` into ``DIR/PLAN.pkl``. ``compare``:
replays every call through this checkout's kernel and through ``TREE``'s (one child process
per tree, the trees alternating round by round; a tree whose kernel takes no ``enough``
argument computes complete rows), reports whether the verdicts agree (each piece rejected by
at least ``enough`` sensors in both, and the same row where fewer) and per plan the minimum
over ``--repeat`` rounds of the process CPU time of all calls, in us a piece. Both trees are
handed the recorded ``params`` array: record with the tree whose kernel reads the longer one
(since session 28 the piece kernel reads an eighth tolerance, the decision slack).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import record_calls

REPOSITORY = Path(__file__).resolve().parent.parent
PLANS = ("hall", "office", "apartment", "corridor")
ENOUGH_ARGUMENT = 18  # position of ``enough`` among piece_rejections_into's arguments


def record(folder: Path, plans: list[str], duration_s: float, changes: dict) -> None:
    import tracking_epochs

    from intervals.sonar import pieces

    calls = record_calls(pieces, "piece_rejections_into")
    folder.mkdir(parents=True, exist_ok=True)
    for plan in plans:
        calls.clear()
        tracking_epochs.child(plan, duration_s, 1, folder / f"{plan}.json", changes)
        (folder / f"{plan}.pkl").write_bytes(pickle.dumps(calls))
        print(f"{plan}: {len(calls)} calls, {sum(c[0].shape[0] for c in calls)} pieces")


def child(path: Path, rounds: int, out: Path) -> None:
    """Replay ``path``'s calls ``rounds`` times with the code on ``sys.path``: CPU seconds of
    each round and the outputs, into ``out``."""
    from intervals.sonar import pieces

    kernel = pieces.piece_rejections_into
    takes_enough = "enough" in inspect.signature(kernel.py_func).parameters
    calls = pickle.loads(path.read_bytes())
    if not takes_enough:
        calls = [c[:ENOUGH_ARGUMENT] + c[ENOUGH_ARGUMENT + 1 :] for c in calls]
    outputs = [np.empty_like(c[-1]) for c in calls]
    kernel(*calls[0][:-1], outputs[0])  # loads the compiled kernel, not timed
    seconds = []
    for _ in range(rounds):
        start = time.process_time()
        for call, reject in zip(calls, outputs, strict=True):
            kernel(*call[:-1], reject)
        seconds.append(time.process_time() - start)
    out.write_bytes(pickle.dumps((seconds, outputs)))


def _run(tree: Path, path: Path, rounds: int) -> tuple[list[float], list[np.ndarray]]:
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "out.pkl"
        command = [sys.executable, __file__, "child", str(path), str(rounds), str(out)]
        subprocess.run(command, env={**os.environ, "PYTHONPATH": str(tree)}, check=True)
        return pickle.loads(out.read_bytes())


def compare(folder: Path, base: Path, repeat: int) -> None:
    for path in sorted(folder.glob("*.pkl")):
        calls = pickle.loads(path.read_bytes())
        pieces_count = sum(c[0].shape[0] for c in calls)
        times: dict[str, list[float]] = {"base": [], "new": []}
        outputs = {}
        for _ in range(repeat):  # the trees alternate, a few rounds each
            for name, tree in (("base", base), ("new", REPOSITORY)):
                seconds, outputs[name] = _run(tree, path, 2)
                times[name] += seconds
        same = True
        for call, old, new in zip(calls, outputs["base"], outputs["new"], strict=True):
            enough = call[ENOUGH_ARGUMENT]
            full, left = old.sum(axis=1) >= enough, new.sum(axis=1) >= enough
            same &= np.array_equal(full, left) and np.array_equal(old[~left], new[~left])
        t_old, t_new = min(times["base"]), min(times["new"])
        print(f"{path.stem:10s} {len(calls)} calls, {pieces_count} pieces: verdicts same {same}; "
              f"CPU base {t_old * 1e3:7.1f} ms ({t_old * 1e6 / pieces_count:.2f} us a piece), "
              f"new {t_new * 1e3:7.1f} ms ({t_new * 1e6 / pieces_count:.2f} us), "
              f"ratio {t_old / t_new:.2f}")  # fmt: skip
    print(f"1-minute load {os.getloadavg()[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    rec = commands.add_parser("record")
    rec.add_argument("folder", type=Path)
    rec.add_argument("plans", nargs="*", default=list(PLANS))
    rec.add_argument("--duration", type=float, default=20.0)
    rec.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    cmp = commands.add_parser("compare")
    cmp.add_argument("folder", type=Path)
    cmp.add_argument("--base", type=Path, required=True)
    cmp.add_argument("--repeat", type=int, default=3)
    run = commands.add_parser("child")
    run.add_argument("path", type=Path)
    run.add_argument("rounds", type=int)
    run.add_argument("out", type=Path)
    args = parser.parse_args()
    if args.command == "record":
        changes = {"tighten_levels": 9, "tighten_max_tested": 10000000}
        for item in args.set:
            key, _, value = item.partition("=")
            changes[key] = json.loads(value)
        record(args.folder, args.plans, args.duration, changes)
    elif args.command == "compare":
        compare(args.folder, args.base, args.repeat)
    else:
        child(args.path, args.rounds, args.out)


if __name__ == "__main__":
    main()

"""Benchmark: the compiled cone kernel against another tree's on recorded calls, CPU time.

    python benchmarks/cone_kernel_replay.py record DIR [PLAN ...] [--duration S]
    python benchmarks/cone_kernel_replay.py compare DIR --base TREE [--repeat R]

``record``: runs ``robotsim run PLAN --duration S`` (default corridor, office_floor, apartment,
big_hall; 30 s) in this process with :func:`intervals.sonar.cone_kernel.sensor_verdicts_into`
wrapped, and pickles the arguments of up to 300 of its calls per plan (a seeded sample) into
``DIR/PLAN.pkl``. ``compare``: replays every recorded call through this checkout's kernel and
through ``TREE/intervals/sonar/cone_kernel.py`` (e.g. ``git archive`` of main, imported in the
same process), as recorded and with ``inner`` flipped: reports whether ``reject`` and
``certain`` are bit-identical (and their digests), and per plan the minimum over ``--repeat``
rounds of the process CPU time of all recorded calls, the two kernels interleaved.
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import record_calls

PLANS = ("corridor", "office_floor", "apartment", "big_hall")
KEPT_CALLS = 300
INNER_ARGUMENT = 21  # position of ``inner`` among sensor_verdicts_into's arguments


def record(folder: Path, plans: list[str], duration_s: float) -> None:
    from intervals.sonar import cone_kernel
    from scenarios.cli import main

    calls = record_calls(cone_kernel, "sensor_verdicts_into")
    folder.mkdir(parents=True, exist_ok=True)
    for plan in plans:
        calls.clear()
        out = folder / plan
        main(["run", plan, "--duration", str(duration_s)]
             + ["--summary", f"{out}.json", "--rrd", f"{out}.rrd"])  # fmt: skip
        kept = calls if len(calls) <= KEPT_CALLS else random.Random(0).sample(calls, KEPT_CALLS)
        (folder / f"{plan}.pkl").write_bytes(pickle.dumps(kept))
        print(f"{plan}: {len(calls)} calls, kept {len(kept)}")


def _replay(module, calls: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
    outputs = []
    for call in calls:
        reject, certain = np.empty_like(call[-2]), np.empty_like(call[-1])
        module.sensor_verdicts_into(*call[:-2], reject, certain)
        outputs.append((reject, certain))
    return outputs


def _digest(outputs: list[tuple[np.ndarray, np.ndarray]]) -> str:
    h = hashlib.sha256()
    for reject, certain in outputs:
        h.update(reject.tobytes())
        h.update(certain.tobytes())
    return h.hexdigest()[:16]


def compare(folder: Path, base: Path, repeat: int) -> None:
    from intervals.sonar import cone_kernel as new

    module_folder = Path(tempfile.mkdtemp(prefix="cone_kernel_base_"))
    shutil.copy(base / "intervals" / "sonar" / "cone_kernel.py", module_folder / "base_kernel.py")
    sys.path.insert(0, str(module_folder))
    import base_kernel as old  # type: ignore[import-not-found]

    for path in sorted(folder.glob("*.pkl")):
        calls = pickle.loads(path.read_bytes())
        flipped = [
            c[:INNER_ARGUMENT] + (not c[INNER_ARGUMENT],) + c[INNER_ARGUMENT + 1 :] for c in calls
        ]
        for label, replayed in (("recorded", calls), ("inner flipped", flipped)):
            a, b = _replay(old, replayed), _replay(new, replayed)
            same = all(
                np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1])
                for x, y in zip(a, b, strict=True)
            )
            print(f"{path.stem:13s} {label:14s} {len(replayed)} calls: identical {same}, "
                  f"digest base {_digest(a)} new {_digest(b)}")  # fmt: skip
        times: dict[str, list[float]] = {"base": [], "new": []}
        for _ in range(repeat):
            for name, module in (("base", old), ("new", new)):
                start = time.process_time()
                _replay(module, calls)
                times[name].append(time.process_time() - start)
        t_old, t_new = min(times["base"]), min(times["new"])
        print(f"{path.stem:13s} CPU base {t_old * 1e3:7.2f} ms new {t_new * 1e3:7.2f} ms "
              f"({(t_new / t_old - 1) * 100:+.1f} %)")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    rec = commands.add_parser("record")
    rec.add_argument("folder", type=Path)
    rec.add_argument("plans", nargs="*", default=list(PLANS))
    rec.add_argument("--duration", type=float, default=30.0)
    cmp = commands.add_parser("compare")
    cmp.add_argument("folder", type=Path)
    cmp.add_argument("--base", type=Path, required=True)
    cmp.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    if args.command == "record":
        record(args.folder, args.plans, args.duration)
    else:
        compare(args.folder, args.base, args.repeat)


if __name__ == "__main__":
    main()

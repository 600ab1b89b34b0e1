"""Hostile input, generated (issue 12): the README's promise holds for every case.

Hypothesis writes scenario files (the built-in hall's keys mutated, random keys, types,
values, nesting, extreme numbers, unicode; raw bytes too) and ``robotsim`` command lines.
For every case:

- the exit status is 0 or 2, or 3 with a crash file whose path the message gives;
- stderr holds no traceback and at most one line;
- no output file exists unless the exit status is 0;
- the inputs (the scenario file, the map file it names) are byte for byte as before.

The bulk runs in this process: the spec loader alone (thousands of files), then the CLI's
``main(argv)`` (outputs and the current folder in a temporary folder; a run that passes
validation is simulated for a few samples). A few cases run the installed console script
as real subprocesses. ``-m slow`` runs ten times more of each.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from scenarios.errors import ScenarioError
from scenarios.spec import load_scenario

pytestmark = pytest.mark.slow  # generated cases by the thousand, subprocesses among them

ROBOTSIM = str(Path(sys.executable).with_name("robotsim"))

#: The scenario every generated file starts from (then mutated).
BASE = tomllib.loads(
    (Path(__file__).parents[2] / "scenarios" / "builtin" / "hall.toml").read_text()
)
BASE["run"]["duration_s"] = 1.0

#: Keys of the schema the mutations aim at (dotted), beside random ones.
SCHEMA_KEYS = (
    "description",
    "run.duration_s",
    "run.seed",
    "run.rate_hz",
    "run.dt_s",
    "map.builtin",
    "map.segments",
    "map.file",
    "robot.start_xy_m",
    "robot.start_heading_deg",
    "robot.radius_m",
    "robot.wheel_radius_m",
    "robot.true_wheel_radius_left_m",
    "robot.wheel_base_m",
    "robot.ticks_per_rev",
    "robot.mass_kg",
    "robot.v_max_m_s",
    "robot.omega_max_rad_s",
    "robot.a_max_m_s2",
    "route.waypoints_m",
    "route.cruise_speed_m_s",
    "route.lookahead_m",
    "route.loop",
    "route.profile",
    "sensors.encoders.slip_std",
    "sensors.gyro.noise_density_rad_s_sqrt_hz",
    "sensors.gyro.turn_on_bias_std_rad_s",
    "sensors.accelerometer.turn_on_bias_std_m_s2",
    "sensors.accelerometer.bias_random_walk_m_s2_sqrt_s",
    "sensors.sonar.count",
    "sensors.sonar.mount_xy",
    "sensors.sonar.mount_angle_rad",
    "sensors.sonar.mount_angle_deg",
    "sensors.sonar.half_aperture_deg",
    "sensors.sonar.d_max_m",
    "sensors.sonar.error_abs_bound_m",
    "sensors.sonar.rate_hz",
    "sensors.sonar.outlier_prob",
    "sensors.sonar.lost_echo_prob",
    "estimation.filter",
    "estimation.tracker",
    "estimation.fusion",
    "estimation.eps_m",
    "estimation.q_max",
    "estimation.interval_rate_hz",
    "estimation.imagesp_pitch_m",
    "estimation.free_space",
)

#: Numbers at the edges: overflow, underflow, signed zero, int64 limits, non-finite.
EXTREME_NUMBERS = st.sampled_from(
    [
        0,
        -0.0,
        1,
        -1,
        2**62,
        2**63 - 1,
        -(2**63),
        1e-300,
        5e-324,
        1e300,
        -1e300,
        1.7976931348623157e308,
        math.inf,
        -math.inf,
        math.nan,
        0.1,
        1e10,
        3,
        16,
    ]
)

SCALARS = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    EXTREME_NUMBERS,
    st.text(max_size=12),
    st.sampled_from(
        ["hall", "ukf", "sivia", "imagesp", "clamp", "map.wkt", "../x", "", "é☃\u202e"]
    ),
)

#: Any TOML value: scalars, arrays (of mixed depth), tables.
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=4),
    ),
    max_leaves=12,
)

#: Arrays shaped like the schema's (points, segments), with extreme coordinates.
COORDINATE = st.one_of(st.floats(-20.0, 20.0), EXTREME_NUMBERS)
SHAPED = st.one_of(
    st.lists(COORDINATE, min_size=0, max_size=3),
    st.lists(st.lists(COORDINATE, min_size=2, max_size=2), min_size=0, max_size=6),
    st.lists(
        st.lists(st.lists(COORDINATE, min_size=2, max_size=2), min_size=2, max_size=2),
        min_size=0,
        max_size=5,
    ),
)

KEYS = st.one_of(
    st.sampled_from(SCHEMA_KEYS),
    st.lists(st.text(min_size=1, max_size=8), min_size=1, max_size=3).map(".".join),
)

#: One mutation: set a key (to any value, or a schema-shaped array) or delete it.
MUTATION = st.tuples(KEYS, st.one_of(VALUES, SHAPED, st.just(DELETE := object())))


def mutated(mutations: list[tuple[str, Any]]) -> dict[str, Any]:
    """The base scenario with ``mutations`` applied (intermediate tables created)."""
    doc = copy.deepcopy(BASE)
    for dotted, value in mutations:
        *parents, last = dotted.split(".")
        table = doc
        for name in parents:
            if not isinstance(table.get(name), dict):
                table[name] = {}
            table = table[name]
        if value is DELETE:
            table.pop(last, None)
        else:
            table[last] = value
    return doc


def toml_text(doc: dict[str, Any]) -> str:
    """``doc`` as TOML: every table a header, every key quoted, values inline."""
    lines: list[str] = []
    _table(doc, [], lines)
    return "\n".join(lines) + "\n"


def _table(table: dict[str, Any], path: list[str], lines: list[str]) -> None:
    scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in table.items() if isinstance(v, dict)}
    if path and (scalars or not tables):
        lines.append("[" + ".".join(map(_key, path)) + "]")
    lines += [f"{_key(k)} = {_value(v)}" for k, v in scalars.items()]
    for key, sub in tables.items():
        _table(sub, [*path, key], lines)


def _key(key: str) -> str:
    return json.dumps(key, ensure_ascii=False)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(map(_value, value)) + "]"
    return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"


#: Map files a scenario may name (``map.file``), written beside it.
MAP_FILES = {
    "map.wkt": "POLYGON ((0 0, 10 0, 10 8, 0 8, 0 0), (4 4, 6 4, 6 6, 4 6, 4 4))\n",
    "bad.wkt": "POLYGON ((0 0, 1",
    "line.geojson": '{"type": "LineString", "coordinates": [[0, 0], [5, 0]]}',
}


def prefix_files(mutations: list[tuple[str, Any]]) -> list[bytes]:
    """The files of every prefix of ``mutations``: several cases for one generated draw
    (drawing is the costly part)."""
    return [toml_text(mutated(mutations[: n + 1])).encode() for n in range(len(mutations))]


#: Batches of scenario files for the loader: mutation prefixes (three draws in five, about
#: 4.5 files each), raw bytes, raw text.
LOADER_FILES = st.one_of(
    st.lists(MUTATION, min_size=1, max_size=8).map(prefix_files),
    st.lists(MUTATION, min_size=1, max_size=8).map(prefix_files),
    st.lists(MUTATION, min_size=1, max_size=8).map(prefix_files),
    st.binary(max_size=200).map(lambda b: [b]),
    st.text(max_size=200).map(lambda t: [t.encode("utf-8", "surrogatepass")]),
)

SCENARIO_FILES = st.one_of(
    st.lists(MUTATION, min_size=1, max_size=5).map(lambda m: toml_text(mutated(m)).encode()),
    st.binary(max_size=200),
    st.text(max_size=200).map(lambda t: t.encode("utf-8", "surrogatepass")),
)


#: Where the cases' folders go: a memory file system when there is one (creating a file on
#: this disk costs milliseconds, and the bulk creates tens of thousands).
FUZZ_ROOT = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None


@contextlib.contextmanager
def case_folder(scenario: bytes) -> Any:
    """A fresh folder, made current, holding ``s.toml`` and the map files."""
    with tempfile.TemporaryDirectory(dir=FUZZ_ROOT) as name, contextlib.chdir(name):
        folder = Path(name)
        (folder / "s.toml").write_bytes(scenario)
        for map_name, text in MAP_FILES.items():
            (folder / map_name).write_text(text)
        yield folder


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def named_outputs(argv: list[str]) -> set[str]:
    """The files a command line names as outputs (which a successful run may replace)."""
    return {argv[i + 1] for i, arg in enumerate(argv[:-1]) if arg in ("--rrd", "--summary")}


def check_outcome(
    status: int,
    err: str,
    folder: Path,
    before: dict[str, bytes],
    outputs: frozenset[str] | set[str] = frozenset(),
) -> None:
    """The promise, for one case run in ``folder`` whose files were ``before``; a file named
    as an output (and not an input of the run, which the CLI refuses) may change on exit 0."""
    event(f"exit {status}")
    if status == 0:
        before = {k: v for k, v in before.items() if k not in outputs}
    assert "Traceback" not in err, err
    assert len(err.splitlines()) <= 1, err
    crash = None
    if status == 3:
        assert "a defect of robotsim" in err and "traceback in " in err, err
        crash = Path(err.rstrip("\n").rsplit("traceback in ", 1)[1])
        assert crash.is_file() and crash.parent == folder, err
    else:
        assert status in (0, 2), (status, err)
    now = snapshot(folder)
    assert {k: now[k] for k in before} == before  # inputs untouched
    made = {p for p in folder.rglob("*") if p.is_file() and p.name not in before and p != crash}
    if status != 0:
        assert made == set(), (status, err, made)


def run_main(argv: list[str]) -> tuple[int, str]:
    """``robotsim ARGV`` in this process: exit status and stderr (stdout discarded)."""
    from scenarios.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code if isinstance(exit_.code, int) else 2
    return status, err.getvalue()


@contextlib.contextmanager
def crash_files_in(folder: Path) -> Any:
    """Crash files go to ``folder`` (the system's temporary folder otherwise)."""
    previous = tempfile.tempdir
    tempfile.tempdir = str(folder)
    try:
        yield
    finally:
        tempfile.tempdir = previous


BULK = settings(
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def fuzz(max_examples: int, *strategies: Any) -> Any:
    """``body`` run on ``max_examples`` cases drawn from ``strategies``."""

    def wrap(body: Any) -> Any:
        return settings(BULK, max_examples=max_examples)(given(*strategies)(body))

    return wrap


#: One folder for every loader case (the loader writes nothing: only ``s.toml`` changes).
LOADER_FOLDER = tempfile.TemporaryDirectory(prefix="robotsim-fuzz-", dir=FUZZ_ROOT)
for _name, _text in MAP_FILES.items():
    (Path(LOADER_FOLDER.name) / _name).write_text(_text)


def loader_case(scenarios: list[bytes]) -> None:
    """The spec loader on each file: a spec, or a ScenarioError naming the file; nothing else."""
    folder = Path(LOADER_FOLDER.name)
    for scenario in scenarios:
        (folder / "s.toml").write_bytes(scenario)
        before = snapshot(folder)
        with contextlib.chdir(folder):
            try:
                load_scenario(folder / "s.toml")
                event("accepted")
            except ScenarioError as exc:
                event("refused")
                assert str(exc).startswith(str(folder / "s.toml")), str(exc)
        assert snapshot(folder) == before


OPTION_VALUES = st.one_of(
    st.sampled_from(["0", "-1", "0.02", "1e400", "nan", "inf", "-inf", "", "x", "2e9", str(2**70)]),
    st.text(max_size=6),
)
OUTPUT_PATHS = st.sampled_from(
    [
        "out/x.rrd",
        "out/x.json",
        "s.toml",
        "map.wkt",
        ".",
        "out",
        "/",
        "out/é☃.rrd",
        "a\nb.json",
        "/proc/x.json",
        "/dev/full",
        "s.toml/x.rrd",
        "x" * 300,
    ]
)


@st.composite
def command_lines(draw) -> list[str]:
    """A ``robotsim`` command line: a sub-command, options with hostile values, junk."""
    command = draw(st.sampled_from(["run", "run", "run", "scenarios", "reproduce", "junk"]))
    if command == "junk":
        return draw(st.lists(st.text(max_size=8), max_size=4))
    if command == "scenarios":
        return ["scenarios", *draw(st.lists(st.sampled_from(["--debug", "x"]), max_size=1))]
    if command == "reproduce":
        name = draw(
            st.sampled_from(["iukf-examples", "mukf-example", "motion-models", "ia-fusion", "nope"])
        )
        argv = ["reproduce", name]
        for option in draw(
            st.lists(st.sampled_from(["--runs", "--steps", "--seed", "--duration"]), max_size=3)
        ):
            argv += [option, draw(st.sampled_from(["-1", "0", "nan", str(10**12), "x", "1e9"]))]
        # a reproduction that would run is kept out of the bulk: its --out is always refused
        return [*argv, "--out", draw(st.sampled_from(["s.toml", ".", "mine"]))]
    argv = ["run", draw(st.sampled_from(["s.toml", "hall", "symmetric", "nope", ".", "map.wkt"]))]
    if draw(st.booleans()):
        argv += ["--rrd", draw(OUTPUT_PATHS)]
    if draw(st.booleans()):
        argv += ["--summary", draw(OUTPUT_PATHS)]
    if draw(st.booleans()):
        argv += ["--seed", draw(OPTION_VALUES)]
    # keep what runs short: a tiny duration unless the option itself is under test
    argv += ["--duration", draw(st.one_of(st.just("0.05"), OPTION_VALUES))]
    return argv + draw(st.lists(st.sampled_from(["--debug", "--bogus", "extra"]), max_size=1))


#: The most samples a run in the bulk may simulate (a generated ``rate_hz`` of 1e8 would
#: make even 0.05 s a run of millions of samples: valid, but not what the bulk is for).
BULK_SAMPLES = 200


def affordable(argv: list[str], folder: Path) -> list[str]:
    """``argv`` with its ``--duration`` shortened to at most :data:`BULK_SAMPLES` samples of
    the scenario it runs (when that scenario loads and the duration is a number)."""
    if "--duration" not in argv or argv[0] != "run":
        return argv
    at = argv.index("--duration") + 1
    try:
        duration_s = float(argv[at])
        spec = load_scenario(folder / argv[1] if argv[1] == "s.toml" else argv[1])
    except (ValueError, IndexError, ScenarioError):
        return argv
    if math.isfinite(duration_s) and duration_s * spec.run.rate_hz > BULK_SAMPLES:
        return [*argv[:at], repr(BULK_SAMPLES / spec.run.rate_hz), *argv[at + 1 :]]
    return argv


def command_line_case(argv: list[str], scenario: bytes) -> None:
    """``main(argv)`` in a folder holding a generated scenario file."""
    with case_folder(scenario) as folder, crash_files_in(folder):
        (folder / "mine").mkdir()
        before = snapshot(folder)
        argv = affordable(argv, folder)
        status, err = run_main(argv)
        inputs = {"s.toml", *MAP_FILES} if argv[:2] == ["run", "s.toml"] else set()
        check_outcome(status, err, folder, before, named_outputs(argv) - inputs)


def scenario_case(mutations: list[tuple[str, Any]]) -> None:
    """``robotsim run`` in this process on a mutated scenario (a few samples when valid)."""
    scenario = toml_text(mutated(mutations)).encode()
    with case_folder(scenario) as folder, crash_files_in(folder):
        before = snapshot(folder)
        argv = [
            "run",
            "s.toml",
            "--rrd",
            "out/x.rrd",
            "--summary",
            "out/x.json",
            "--duration",
            "0.05",
        ]
        status, err = run_main(affordable(argv, folder))
        check_outcome(status, err, folder, before)
        if status == 0:
            assert sorted(p.name for p in (folder / "out").iterdir()) == ["x.json", "x.rrd"]


def console_script_case(mutations: list[tuple[str, Any]], duration: str) -> None:
    """The installed ``robotsim`` as a real subprocess on a mutated scenario."""
    scenario = toml_text(mutated(mutations)).encode()
    with case_folder(scenario) as folder:
        before = snapshot(folder)
        env = {**os.environ, "TMPDIR": str(folder)}
        argv = ["run", "s.toml", "--rrd", "out/x.rrd", "--summary", "out/x.json"]
        done = subprocess.run(
            [ROBOTSIM, *affordable([*argv, "--duration", duration], folder)],
            cwd=folder,
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        check_outcome(done.returncode, done.stderr, folder, before)


#: Each property, its strategies and its number of cases in the default run.
PROPERTIES = {
    "loader": (loader_case, (LOADER_FILES,), 700),
    "command lines": (command_line_case, (command_lines(), SCENARIO_FILES), 300),
    "scenarios": (scenario_case, (st.lists(MUTATION, min_size=1, max_size=4),), 150),
    "console script": (
        console_script_case,
        (st.lists(MUTATION, min_size=1, max_size=3), st.sampled_from(["0.05", "nan", "-1", "x"])),
        3,
    ),
}

test_the_loader_refuses_every_bad_file_with_its_name = fuzz(
    PROPERTIES["loader"][2], *PROPERTIES["loader"][1]
)(loader_case)
test_the_cli_keeps_its_promise_for_hostile_command_lines = fuzz(
    PROPERTIES["command lines"][2], *PROPERTIES["command lines"][1]
)(command_line_case)
test_the_cli_keeps_its_promise_for_mutated_scenarios = fuzz(
    PROPERTIES["scenarios"][2], *PROPERTIES["scenarios"][1]
)(scenario_case)
test_the_console_script_keeps_its_promise = fuzz(
    PROPERTIES["console script"][2], *PROPERTIES["console script"][1]
)(console_script_case)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(PROPERTIES))
def test_ten_times_more_cases(request, name):
    """Each property over ten times as many cases; only when ``-m`` asks for ``slow``."""
    if "slow" not in (request.config.getoption("markexpr") or ""):
        pytest.skip("ten times more cases: run with -m slow")
    body, strategies, examples = PROPERTIES[name]
    fuzz(10 * examples, *strategies)(body)()

"""The scenario documentation (docs/scenario-format.md): its example parses and runs, and its
key tables list every parameter with the default the code really uses."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from intervals.tracker import TrackerSettings
from localization.mcl import MclSettings
from robotsim.control import Route
from robotsim.robot import RobotParams
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.imu import AccelerometerParams, GyroParams
from robotsim.sensors.sonar import SonarBeltParams
from scenarios.runner import run_scenario
from scenarios.spec import EstimationSpec, RunSpec, load_scenario, parse_scenario

FORMAT_DOC = Path(__file__).resolve().parents[2] / "docs" / "scenario-format.md"


def format_section() -> str:
    text = FORMAT_DOC.read_text(encoding="utf-8")
    start = text.index("## Scenario file format")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def key_tables() -> dict[str, dict[str, str]]:
    """``{"[table]": {key: default as written}}`` from the section's markdown tables."""
    tables: dict[str, dict[str, str]] = {}
    current = None
    for line in format_section().splitlines():
        heading = re.match(r"^`(\[[a-z.]+\])`", line)
        if heading:
            current = tables.setdefault(heading.group(1), {})
        row = re.match(r"^\| `([a-z0-9_]+)` \|\s*([^|]*?)\s*\|", line)
        if row and current is not None:
            current[row.group(1)] = row.group(2).strip().strip("`")
    return tables


def _block(language: str, text: str) -> str:
    """The first fenced code block of ``language`` in ``text``."""
    found = re.search(rf"```{language}\n(.*?)```", text, re.S)
    assert found, f"no {language} block"
    return found.group(1)


def test_the_example_parses_and_runs():
    example = _block("toml", format_section())
    spec = parse_scenario(example, source="docs/scenario-format.md")
    assert spec.run.seed == 7 and spec.sensors.sonar.outlier_prob == 0.02
    assert spec.map.boundary is not None  # the inline outer wall was recognised
    assert isinstance(spec.plan, Route) and spec.plan.loop
    result = run_scenario(spec.with_run(duration_s=10.0))
    assert result.summary["walls"]["contact_samples"] == 0
    assert result.summary["distance_m"] > 2.0


def _key_tree(value):
    """The nested keys of a summary, values dropped (lists of records by their first)."""
    if isinstance(value, dict):
        return {key: _key_tree(item) for key, item in value.items()}
    if isinstance(value, list) and value and isinstance(value[0], dict):
        return [_key_tree(value[0])]
    return None


def test_the_summary_example_has_the_keys_a_run_writes():
    text = FORMAT_DOC.read_text(encoding="utf-8")
    example = json.loads(_block("json", text[text.index("numbers rounded to 4 digits") :]))
    summary = run_scenario(load_scenario("hall").with_run(duration_s=5.0)).summary
    written = {key: value for key, value in summary.items() if key not in {"nees", "nis"}}
    del example["timing"]  # added by the command line, not by run_scenario
    assert _key_tree(example) == _key_tree(written)


ROBOT = RobotParams()
DOCUMENTED: dict[str, Any] = {
    "[run]": RunSpec(),
    "[robot]": ROBOT,
    "[route]": Route(waypoints_m=np.zeros((1, 2))),
    "[sensors.encoders]": EncoderParams(),
    "[sensors.gyro]": GyroParams(),
    "[sensors.accelerometer]": AccelerometerParams(),
    "[sensors.sonar]": SonarBeltParams.default_belt(robot_radius_m=RobotParams().radius_m),
    "[estimation]": EstimationSpec(
        intervals=TrackerSettings(ROBOT.v_max_m_s, ROBOT.omega_max_rad_s)
    ),
    "[estimation.mcl]": MclSettings(),
}


def documented_keys(defaults) -> dict:
    """The keys a table takes and their defaults: the record's fields, or for ``[estimation]``
    the keys of the records it holds."""
    if isinstance(defaults, EstimationSpec):
        return defaults.as_keys()
    return {f.name: getattr(defaults, f.name) for f in dataclasses.fields(defaults)}


@pytest.mark.parametrize("table", sorted(DOCUMENTED))
def test_every_parameter_is_documented_with_its_true_default(table):
    rows = key_tables()[table]
    defaults = documented_keys(DOCUMENTED[table])
    fields = set(defaults)
    assert fields <= set(rows), f"undocumented in {table}: {fields - set(rows)}"
    checked = 0
    for key, written in rows.items():
        if not written or written.startswith("*") or key not in defaults:
            continue
        value = defaults[key]
        if isinstance(value, bool):
            assert written == str(value).lower(), key
        elif isinstance(value, np.ndarray):
            continue
        elif isinstance(value, str):
            assert written == f'"{value}"', key
        else:
            assert float(written) == pytest.approx(value, rel=1e-3), key
        checked += 1
    assert checked >= len(fields) // 2


# ---------------------------------------------------------------------------------------
# The README and the docs/ pages as a whole
# ---------------------------------------------------------------------------------------
ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
CODE_PACKAGES = ("robotsim", "localization", "intervals", "scenarios", "benchmarks")


def test_the_readme_is_short_and_keeps_the_commands_ci_runs():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    # .ci/run installs and tests exactly as these blocks say
    assert "```sh\npip install .\nrobotsim run\n```" in text
    assert '```sh\npip install -e ".[test]"\nrobotsim warmup\npytest\n```' in text
    assert 'pip install -e ".[dev]"' in text and "pre-commit install" in text


def _anchor(heading: str) -> str:
    """The anchor GitHub gives a markdown heading (lower case, punctuation dropped)."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_relative_link_of_the_pages_resolves():
    checked = 0
    for page in PAGES:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if target.startswith(("http://", "https://")):
                continue
            path_part, _, anchor = target.partition("#")
            linked = (page.parent / path_part).resolve() if path_part else page
            assert linked.is_file(), f"{page.name}: broken link {target}"
            if anchor and linked.suffix == ".md":
                headings = re.findall(r"^#+ (.+)$", linked.read_text(encoding="utf-8"), re.M)
                assert anchor in {_anchor(h) for h in headings}, f"{page.name}: no #{anchor}"
            checked += 1
    assert checked > 20


def _code_text() -> str:
    files = [p for package in CODE_PACKAGES for p in (ROOT / package).rglob("*.py")]
    return "\n".join(p.read_text(encoding="utf-8") for p in files)


def test_every_paper_the_code_cites_is_named_in_the_references():
    cited = set(re.findall(r"[Pp]aper (00\d)", _code_text()))
    assert {"000", "001", "002", "004"} <= cited
    references = (ROOT / "docs" / "references.md").read_text(encoding="utf-8")
    for number in cited:
        row = re.search(rf"^\| \*\*paper {number}\*\* \| ([^|]+) \|", references, re.M)
        assert row, f"paper {number} is cited in the code but not named in docs/references.md"
        assert '"' in row.group(1) and re.search(r"\b(19|20)\d\d\b", row.group(1)), row.group(1)


def test_every_models_section_the_code_cites_exists():
    text = _code_text()
    sections = {int(n) for n in re.findall(r"docs/models\.md sections? (\d)", text)}
    sections |= {int(b) for _, b in re.findall(r"docs/models\.md sections (\d)-(\d)", text)}
    assert sections
    models = (ROOT / "docs" / "models.md").read_text(encoding="utf-8")
    for n in sorted(sections):
        assert re.search(rf"^## {n}\. ", models, re.M), (
            f"docs/models.md section {n} is not in docs/models.md"
        )


def test_the_interval_example_runs_and_holds_the_truth():
    text = (ROOT / "docs" / "guarantee.md").read_text(encoding="utf-8")
    section = text[text.index("## 8. Using the package") :]
    code = _block("python", section)
    namespace: dict = {}
    exec(compile(code.replace("print(", "_ = ("), "docs/guarantee.md", "exec"), namespace)
    paving, truth = namespace["paving"], namespace["truth"]
    assert paving.contains(truth[None]).all()
    assert 0.0 < paving.area_xy() < 0.1  # one scan narrows the whole hall to a small set

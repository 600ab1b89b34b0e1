"""``[[events]]``: a kidnapping declared in the scenario file, validated like every key; the
summary gives the time the estimate takes to recover."""

from __future__ import annotations

import numpy as np
import pytest

from scenarios.errors import ScenarioError
from scenarios.pipeline import FUSED, RECOVERY_DISTANCE_M, RECOVERY_HOLD_S
from scenarios.runner import run_scenario
from scenarios.spec import BUILTIN_FOLDER, parse_scenario

KIDNAP = """
[[events]]
kind = "kidnap"
t_s = 20.0
xy_m = [9.0, 5.0]
heading_deg = 90
"""


def hall_with(extra: str, duration_s: float = 60.0) -> str:
    text = (BUILTIN_FOLDER / "hall.toml").read_text()
    return text.replace("duration_s = 600.0", f"duration_s = {duration_s}") + extra


def direct_recovery_s(error_m: np.ndarray, start: int, rate_hz: float) -> float | None:
    """The first sample from ``start`` after which the error stays within the distance for
    the hold time, one candidate at a time."""
    hold = round(RECOVERY_HOLD_S * rate_hz)
    for k in range(start, len(error_m) - hold + 1):
        if np.all(error_m[k : k + hold] <= RECOVERY_DISTANCE_M):
            return (k - start) / rate_hz
    return None


@pytest.mark.slow
@pytest.mark.parametrize("fusion", ["clamp", "clamp_heading"])
def test_a_kidnapping_is_detected_and_the_recovery_time_reported(fusion):
    spec = parse_scenario(
        hall_with(KIDNAP + f'\n[estimation]\nfusion = "{fusion}"\n'), source="k.toml"
    )
    run = run_scenario(spec)
    log, summary = run.log, run.summary
    np.testing.assert_array_equal(log.kidnap_t_s, [20.0])
    np.testing.assert_allclose(log.pose[2000], [9.0, 5.0, np.pi / 2], atol=1e-9)
    assert summary["epoch_status"]["inconsistent"] >= 1  # the scans contradict the set
    assert summary["containment"] == 1.0  # never clamped to an empty or wrong set
    error = np.linalg.norm(run.estimation.pose[FUSED, :, :2] - log.pose[:, :2], axis=1)
    assert error[2000] > 1.0  # the kidnapping moved the robot away from its estimate
    (kidnap,) = summary["kidnaps"]
    assert kidnap["t_s"] == 20.0
    assert kidnap["recovery_s"] == direct_recovery_s(error, 2000, log.rate_hz)
    if fusion == "clamp_heading":  # relocalised at the next epochs, heading included
        assert kidnap["recovery_s"] is not None and kidnap["recovery_s"] <= 5.0


def test_a_run_without_events_has_no_kidnap():
    spec = parse_scenario(hall_with("", duration_s=5.0), source="plain.toml")
    assert spec.kidnaps == ()
    assert run_scenario(spec).summary["kidnaps"] == []


BAD_EVENTS = {
    "unknown kind": (
        'kind = "teleport"\nt_s = 1.0\nxy_m = [9, 5]\n',
        "events[0].kind",
        "one of 'kidnap'",
    ),
    "time beyond the run": (
        'kind = "kidnap"\nt_s = 61.0\nxy_m = [9, 5]\n',
        "events[0].t_s",
        "<= 60",
    ),
    "time at the start": ('kind = "kidnap"\nt_s = 0.0\nxy_m = [9, 5]\n', "events[0].t_s", "> 0"),
    "no pose": ('kind = "kidnap"\nt_s = 1.0\n', "events[0].xy_m", ""),
    "pose outside the hall": ('kind = "kidnap"\nt_s = 1.0\nxy_m = [20, 5]\n', "events[0].xy_m", ""),
    "unknown key": (
        'kind = "kidnap"\nt_s = 1.0\nxy_m = [9, 5]\nsonar = 3\n',
        "events[0].sonar",
        "unknown key",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_EVENTS))
def test_bad_events_are_refused_naming_file_and_key(case):
    body, key, reason = BAD_EVENTS[case]
    with pytest.raises(ScenarioError) as info:
        parse_scenario(hall_with("\n[[events]]\n" + body), source="k.toml")
    assert info.value.source == "k.toml" and info.value.key == key
    assert reason in info.value.reason


def test_two_kidnaps_on_one_sample_are_refused():
    twice = KIDNAP + KIDNAP.replace("t_s = 20.0", "t_s = 19.995")  # both on sample 2000
    with pytest.raises(ScenarioError) as info:
        parse_scenario(hall_with(twice), source="k.toml")
    assert info.value.key == "events[1].t_s" and "same sample" in info.value.reason

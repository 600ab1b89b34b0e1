"""``robotsim reproduce mukf-example`` end to end (few runs): files, structure, robust orderings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenarios.cli import main


@pytest.mark.slow
def test_mukf_example_writes_its_table_and_figures(tmp_path):
    out = tmp_path / "mukf"
    assert (
        main(
            [
                "reproduce",
                "mukf-example",
                "--runs",
                "10",
                "--steps",
                "100",
                "--seed",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    table = json.loads((out / "table.json").read_text())
    for name in ("fig1_x3_case_a.png", "fig2_x3_case_b.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "true initial state" in (out / "table.md").read_text()
    for case in ("case_a", "case_b"):
        mse = {f: np.array([v["x1"], v["x2"], v["x3"]]) for f, v in table[case]["mse"].items()}
        assert set(mse) == {"EKF", "MEKF", "UKF", "MUKF"}
        # The modification helps the parameter x3 (paper 004's main claim), for both bases...
        assert mse["MUKF"][2] < mse["UKF"][2]
        assert mse["MEKF"][2] < mse["EKF"][2]
        # ... and costs a little on the linear states (paper: "EKF best for x1 and x2").
        assert mse["EKF"][0] < mse["MEKF"][0]
        assert mse["UKF"][0] < mse["MUKF"][0]
        assert table[case]["covariance_repairs"]["UKF"] == 0
    assert table["case_a"]["mse"]["MUKF"]["x3"] < table["case_b"]["mse"]["MUKF"]["x3"]

"""The filter example of docs/models.md (section 6) runs as written and does what it says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

MODELS_DOC = Path(__file__).resolve().parents[2] / "docs" / "models.md"


def test_the_filter_example_runs():
    text = MODELS_DOC.read_text(encoding="utf-8")
    section = text[text.index("## 6. The Kalman filter family") :]
    found = re.search(r"```python\n(.*?)```", section, re.S)
    assert found, "no python block in section 6 of docs/models.md"
    code = found.group(1)
    namespace: dict = {}
    exec(compile(code, "docs/models.md", "exec"), namespace)
    belief = namespace["belief"]
    assert belief.mean.shape == (1000, 5) and belief.cov.shape == (1000, 5, 5)
    # the GPS update on a linear measurement is the Kalman update of the predicted belief
    start = namespace["Gaussian"](np.zeros(5), np.eye(5), angle_indices=(2,))
    predicted = namespace["ukf"].predict(start, namespace["process"], 0.01).cov
    h = np.eye(5)[:2]
    gain = predicted @ h.T @ np.linalg.inv(h @ predicted @ h.T + 2.25 * np.eye(2))
    np.testing.assert_allclose(belief.cov[0], predicted - gain @ h @ predicted, atol=1e-12)
    assert belief.cov[0, 0, 0] < min(predicted[0, 0], 2.25)
    # the user's own numpy model (`mine`) and the compiled `gps` model give the same update
    ukf, z = namespace["ukf"], np.array([0.3, -0.2])
    compiled = ukf.update(start, z, namespace["gps"])
    numpy_path = ukf.update(start, z, namespace["mine"])
    np.testing.assert_allclose(compiled.mean, numpy_path.mean, atol=1e-12)
    np.testing.assert_allclose(compiled.cov, numpy_path.cov, atol=1e-12)

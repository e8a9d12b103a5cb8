"""The README's Python examples run as written."""

import math
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def run_example(heading: str) -> dict:
    """Execute the first ``python`` block after ``heading``; return its namespace."""
    text = README.read_text()
    section = text[text.index(heading):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    return namespace


def test_python_api_example_runs():
    sol = run_example("## Python API")["sol"]
    assert sol.stats["failed_steps"] == 0
    assert "tip_force" in sol.observables


def test_gradient_example_runs():
    grad = run_example("### Gradients through whole trajectories")["grads"]
    assert set(grad) == {"E", "e", "velocity"}
    assert all(math.isfinite(float(g)) for g in grad.values())
    assert float(grad["velocity"]) != 0.0 and float(grad["E"]) != 0.0

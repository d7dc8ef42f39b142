"""Every example runs headless and prints what it promises."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parent.parent / "examples").glob("[0-9][0-9]_*.py"))


def test_examples_exist():
    assert len(EXAMPLES) >= 6


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs_headless(path):
    env = {**os.environ, "MUJOCO_GL": "egl"}
    r = subprocess.run([sys.executable, str(path), "--headless"], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip(), "an example must report what it did"
    if "pick_and_place" in path.stem or "swap_controller" in path.stem:
        assert "success=True" in r.stdout, r.stdout

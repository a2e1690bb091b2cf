"""Golden recording: the scripted run of tools/make_viz_reference.py must reproduce
``data/reference/viz/scripted-run.rrd`` exactly (``rerun rrd compare --unordered``: the same
chunks, rows and values; log time is off and batching does not depend on timing).

When the recording layout changes on purpose, regenerate the reference with
``uv run python tools/make_viz_reference.py`` and commit it.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
from tool_modules import load_tool

from slam.viz.stream import rerun_executable, viewer_env

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "data" / "reference" / "viz" / "scripted-run.rrd"


def _compare(a: Path, b: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        # --unordered: chunks are compared as sets (rerun writes them in no fixed order)
        [*rerun_executable(), "rrd", "compare", "--unordered", str(a), str(b)],
        env=viewer_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_reference_is_small_and_verifies():
    assert REFERENCE.is_file(), "run: uv run python tools/make_viz_reference.py"
    assert REFERENCE.stat().st_size < 300_000
    verify = subprocess.run(
        [*rerun_executable(), "rrd", "verify", str(REFERENCE)],
        env=viewer_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert verify.returncode == 0, verify.stderr


def test_scripted_run_matches_the_golden_recording(tmp_path):
    fresh = load_tool("make_viz_reference").write_reference(tmp_path / "fresh.rrd")
    result = _compare(REFERENCE, fresh)
    assert result.returncode == 0, (
        f"recording differs from {REFERENCE.name} (regenerate with "
        f"tools/make_viz_reference.py if intended):\n{result.stdout[-2000:]}{result.stderr[-2000:]}"
    )


def test_compare_catches_a_changed_pose(tmp_path, monkeypatch):
    tool = load_tool("make_viz_reference")
    original = tool.scripted_poses

    def shifted(steps: int = tool.STEPS) -> np.ndarray:
        poses = original(steps)
        poses[17, 0] += 0.01
        return poses

    monkeypatch.setattr(tool, "scripted_poses", shifted)
    changed = tool.write_reference(tmp_path / "changed.rrd")
    assert _compare(REFERENCE, changed).returncode != 0

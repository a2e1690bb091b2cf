"""``tools/perturb_odometry.py``: a CARMEN log with its odometry's distances and turns rescaled."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest
from tool_modules import load_tool

LOG = """# a tiny CARMEN log
ODOM 0.000000 0.000000 0.000000 0.0 0.0 0.0 1.0 host 1.0
FLASER 3 1.0 2.0 3.0 0.1 0.0 0.0 0.0 0.0 0.0 1.05 host 1.05
ODOM 1.000000 0.000000 0.000000 0.0 0.0 0.0 2.0 host 2.0
FLASER 3 1.5 2.5 3.5 1.1 0.0 0.0 1.0 0.0 0.0 2.05 host 2.05
ODOM 1.000000 1.000000 1.5707963 0.0 0.0 0.0 3.0 host 3.0
FLASER 3 4.0 5.0 6.0 1.0 1.1 1.5707963 1.0 1.0 1.5707963 3.05 host 3.05
"""


def _poses(text: str, kind: str) -> list[list[float]]:
    out = []
    for line in text.splitlines():
        f = line.split()
        if f and f[0] == kind == "ODOM":
            out.append([float(v) for v in f[1:4]])
        elif f and f[0] == kind == "FLASER":
            n = int(f[1])
            out.append([float(v) for v in f[n + 2 : n + 8]] + [float(v) for v in f[2 : n + 2]])
    return out


def test_distances_and_turns_are_rescaled_and_the_laser_keeps_its_offset(tmp_path):
    tool = load_tool("perturb_odometry")
    log, out = tmp_path / "a.clf", tmp_path / "b.clf.gz"
    log.write_text(LOG)
    assert tool.main([str(log), str(out), "--distance-scale", "2"]) == 0
    text = gzip.decompress(out.read_bytes()).decode()
    odom = _poses(text, "ODOM")
    assert np.allclose(odom, [[0, 0, 0], [2, 0, 0], [2, 2, math.pi / 2]], atol=1e-6)
    laser = _poses(text, "FLASER")
    # laser pose (x y theta), odometry pose, then the ranges as they were
    assert np.allclose(laser[1], [2.1, 0, 0, 2, 0, 0, 1.5, 2.5, 3.5], atol=1e-6)
    assert np.allclose(laser[2], [2, 2.1, math.pi / 2, 2, 2, math.pi / 2, 4, 5, 6], atol=1e-6)
    assert text.splitlines()[0] == "# a tiny CARMEN log"

    half = tmp_path / "c.clf"
    assert tool.main([str(log), str(half), "--turn-scale", "0.5"]) == 0
    odom = _poses(half.read_text(), "ODOM")
    assert np.allclose(odom, [[0, 0, 0], [1, 0, 0], [1, 1, math.pi / 4]], atol=1e-6)


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("ROBOTLASER1 0 -1.57 3.14 0.01 30 0.01 0 0", "line 8: ROBOTLASER1 lines carry poses"),
        ("ODOM 1.0 x 0.0 0 0 0 4.0 host 4.0", "line 8: expected a pose (three numbers)"),
        ("FLASER 3 1.0 2.0", "line 8: expected 11 fields or more for 3 readings, found 4"),
    ],
)
def test_bad_lines_are_named_and_nothing_is_written(tmp_path, capsys, line, says):
    tool = load_tool("perturb_odometry")
    log, out = tmp_path / "a.clf", tmp_path / "b.clf"
    log.write_text(LOG + line + "\n")
    assert tool.main([str(log), str(out), "--distance-scale", "1.05"]) == 2
    err = capsys.readouterr().err
    assert str(log) in err and says in err and err.count("\n") == 1
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["a.clf"]


def test_an_existing_output_is_never_replaced_and_factors_are_bounded(tmp_path, capsys):
    tool = load_tool("perturb_odometry")
    log, out = tmp_path / "a.clf", tmp_path / "b.clf"
    log.write_text(LOG)
    out.write_text("mine")
    assert tool.main([str(log), str(out)]) == 2
    assert "exists; the output is never replaced" in capsys.readouterr().err
    assert out.read_text() == "mine"
    assert tool.main([str(log), str(tmp_path / "c.clf"), "--turn-scale", "3"]) == 2
    assert "--turn-scale: expected a factor from 0.5 to 2, found 3.0" in capsys.readouterr().err
    assert tool.main([str(tmp_path / "none.clf"), str(tmp_path / "d.clf")]) == 2
    assert "none.clf: cannot read" in capsys.readouterr().err
    bare = tmp_path / "bare.clf"
    bare.write_text("# no odometry here\nPARAM robot_width 0.5\n")
    assert tool.main([str(bare), str(tmp_path / "e.clf")]) == 2
    assert "bare.clf: no ODOM or FLASER lines" in capsys.readouterr().err
    bare.unlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.clf", "b.clf"]

"""``tools/perturb_ranges.py``: a CARMEN log with Gaussian noise added to its laser readings."""

from __future__ import annotations

import gzip

import numpy as np
from tool_modules import load_tool

LOG = """# a tiny CARMEN log
ODOM 0.000000 0.000000 0.000000 0.0 0.0 0.0 1.0 host 1.0
FLASER 4 1.0 2.0 81.91 0.0 0.1 0.0 0.0 0.0 0.0 0.0 1.05 host 1.05
FLASER 4 3.0 10.0 4.0 81.91 1.1 0.0 0.0 1.0 0.0 0.0 2.05 host 2.05
"""


def _readings(text: str) -> list[list[float]]:
    out = []
    for line in text.splitlines():
        f = line.split()
        if f and f[0] == "FLASER":
            out.append([float(v) for v in f[2 : int(f[1]) + 2]])
    return out


def _tail(text: str) -> list[list[str]]:
    """Every line but the readings of its FLASER lines."""
    out = []
    for line in text.splitlines():
        f = line.split()
        out.append(f[:2] + f[int(f[1]) + 2 :] if f and f[0] == "FLASER" else f)
    return out


def test_readings_get_seeded_noise_and_nothing_else_changes(tmp_path):
    tool = load_tool("perturb_ranges")
    log = tmp_path / "a.clf"
    log.write_text(LOG)
    a, b, c = tmp_path / "b.clf.gz", tmp_path / "c.clf", tmp_path / "d.clf"
    assert tool.main([str(log), str(a), "--sigma-m", "0.05", "--sigma-rel", "0.01"]) == 0
    assert tool.main([str(log), str(b), "--sigma-m", "0.05", "--sigma-rel", "0.01"]) == 0
    assert tool.main([str(log), str(c), "--sigma-m", "0.05", "--seed", "1"]) == 0
    text = gzip.decompress(a.read_bytes()).decode()
    assert text == b.read_text()  # the same arguments, the same file
    assert text != c.read_text()  # another seed, other noise
    assert _tail(text) == _tail(LOG)  # poses, times, every other line as they were
    before, after = np.array(_readings(LOG)), np.array(_readings(text))
    assert after[0, 2] == after[1, 3] == 81.91  # the log's largest value: no return, kept
    assert after[0, 3] == 0.0  # a zero reading too
    moved = before != after
    assert moved.sum() == 5 and np.all(np.abs(after - before)[moved] < 5 * 0.15)
    assert np.all((after >= 0) & (after < 81.91 + 1e-9))


def test_the_noise_has_the_asked_spread(tmp_path):
    tool = load_tool("perturb_ranges")
    rng = np.random.default_rng(5)
    rows = [
        "FLASER 90 " + " ".join(f"{v:.3f}" for v in rng.uniform(1, 9, 90)) + " 0 0 0 0 0 0 1 h 1"
        for _ in range(200)
    ]
    rows.append("FLASER 1 30.0 0 0 0 0 0 0 2 h 2")  # the log's largest reading
    log, out = tmp_path / "a.clf", tmp_path / "b.clf"
    log.write_text("\n".join(rows) + "\n")
    assert tool.main([str(log), str(out), "--sigma-m", "0.02", "--sigma-rel", "0.01"]) == 0
    before = np.concatenate(_readings(log.read_text())[:-1])
    after = np.concatenate(_readings(out.read_text())[:-1])
    z = (after - before) / (0.02 + 0.01 * before)
    assert abs(z.mean()) < 0.05 and 0.95 < z.std() < 1.05  # 18,000 readings: within 5 %


BAD = [  # (line added to the log, arguments, what the one-line message says)
    ("", ["--sigma-m", "2"], "--sigma-m: expected a value from 0 to 1, found 2.0"),
    ("", ["--sigma-rel", "-0.1"], "--sigma-rel: expected a value from 0 to 0.2, found -0.1"),
    ("", ["--sigma-m", "nan"], "--sigma-m: expected a value from 0 to 1, found nan"),
    ("", ["--seed", "-1"], "--seed: expected a whole number 0 or above, found -1"),
    ("FLASER 3 1.0 2.0", [], "a.clf, line 5: expected 11 fields or more for 3 readings, found 4"),
    ("FLASER 2 1.0 x 0 0 0 0 0 0 3 h 3", [], "a.clf, line 5: expected 2 numbers as readings"),
    ("FLASER 2 1.0 -2 0 0 0 0 0 0 3 h 3", [], "a.clf, line 5: a reading is negative or not"),
    ("FLASER x 1.0", [], "a.clf, line 5: expected FLASER num_readings ..., found ['FLASER', 'x']"),
]


def test_bad_input_is_one_line_naming_what_and_where_and_nothing_is_written(tmp_path, capsys):
    tool = load_tool("perturb_ranges")
    log = tmp_path / "a.clf"
    for k, (line, args, says) in enumerate(BAD):
        log.write_text(LOG + line + "\n")
        out = tmp_path / f"out{k}.clf"
        assert tool.main([str(log), str(out), "--sigma-m", "0.01", *args]) == 2, says
        err = capsys.readouterr().err
        assert err.startswith("perturb_ranges: error: ") and says in err, err
        assert err.count("\n") == 1 and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.clf"]


def test_an_existing_output_is_never_replaced_and_a_log_needs_scans(tmp_path, capsys):
    tool = load_tool("perturb_ranges")
    log, out = tmp_path / "a.clf", tmp_path / "b.clf"
    log.write_text(LOG)
    out.write_text("mine")
    assert tool.main([str(log), str(out), "--sigma-m", "0.01"]) == 2
    assert "exists; the output is never replaced" in capsys.readouterr().err
    assert out.read_text() == "mine"
    bare = tmp_path / "bare.clf"
    bare.write_text("ODOM 0 0 0 0 0 0 1 h 1\n")
    assert tool.main([str(bare), str(tmp_path / "c.clf")]) == 2
    assert "bare.clf: no FLASER lines" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.clf", "b.clf", "bare.clf"]

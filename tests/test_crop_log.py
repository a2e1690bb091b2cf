"""``tools/crop_log.py``: a CARMEN log without its first records, as a run started elsewhere."""

from __future__ import annotations

import gzip
import os

from test_perturb_odometry import LOG as BASE
from tool_modules import load_tool

LINES = BASE.splitlines(keepends=True)
LOG = "".join([*LINES[:4], "# a comment in the middle\n", *LINES[4:]])
"""The perturbation tool's tiny log (three ODOM and three FLASER records at 1, 1.05, 2, 2.05, 3,
3.05 s) with a comment between its third and fourth records."""


def test_the_first_records_are_dropped_and_the_comments_kept():
    tool = load_tool("crop_log")
    lines = LOG.splitlines()
    assert tool.crop_lines(lines, 0.0) == lines
    half = tool.crop_lines(lines, 0.5)  # 6 records: from the 4th (ODOM 1.0 ...'s FLASER) on
    assert half[0] == "# a tiny CARMEN log"
    assert [line.split()[0] for line in half[1:]] == ["#", "FLASER", "ODOM", "FLASER"]
    assert half[2].split()[-1] == "2.05"
    last = tool.crop_lines(lines, 0.99)
    assert [line.split()[-1] for line in last if not line.startswith("#")] == ["3.05"]


def test_the_copy_is_written_compressed_and_never_over_a_file(tmp_path, capsys):
    tool = load_tool("crop_log")
    src = tmp_path / "log.clf.gz"
    src.write_bytes(gzip.compress(LOG.encode()))  # read as gzip by its content
    (tmp_path / "cut").mkdir()
    out = tmp_path / "cut" / "log.clf.gz"
    assert tool.main([str(src), str(out), "--from", "0.5"]) == 0
    text = gzip.decompress(out.read_bytes()).decode()
    assert text.count("FLASER") == 2 and text.count("ODOM") == 1
    assert text.splitlines() == tool.crop_lines(LOG.splitlines(), 0.5)
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask  # as a plain open() makes it
    before = out.read_bytes()
    assert tool.main([str(src), str(out), "--from", "0.1"]) == 2
    assert "log.clf.gz: exists; the output is never replaced" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert tool.main([str(src), str(tmp_path / "x.clf"), "--from", "1.0"]) == 2
    assert "--from: expected a fraction in [0, 1), found 1.0" in capsys.readouterr().err
    assert tool.main([str(src), str(tmp_path / "x.clf"), "--from", "nan"]) == 2
    assert "--from: expected a fraction in [0, 1), found nan" in capsys.readouterr().err
    empty = tmp_path / "empty.clf"
    empty.write_text("# nothing\n")
    assert tool.main([str(empty), str(tmp_path / "y.clf"), "--from", "0.5"]) == 2
    assert "empty.clf: expected CARMEN records, found none" in capsys.readouterr().err
    assert tool.main([str(src), str(tmp_path / "no" / "z.clf"), "--from", "0.5"]) == 2
    assert "no: no such folder for the output" in capsys.readouterr().err
    broken = tmp_path / "broken.clf.gz"
    broken.write_bytes(gzip.compress(LOG.encode())[:20])
    assert tool.main([str(broken), str(tmp_path / "w.clf"), "--from", "0.5"]) == 2
    assert "broken.clf.gz: a gzip file that does not decompress" in capsys.readouterr().err
    assert not any((tmp_path / n).exists() for n in ("x.clf", "y.clf", "w.clf", "no"))
    assert sorted(p.name for p in out.parent.iterdir()) == ["log.clf.gz"]  # no partial file

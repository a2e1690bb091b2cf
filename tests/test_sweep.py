"""``slam sweep`` and ``slam tune`` (issue 17): the spec, the sweep folder's safety, resume after
Ctrl-C, a crashing cell, the Ray executor with a worker killed mid-sweep, tuning on a simulated
log, and (with the real logs) cell-for-cell equality with separate ``slam run`` commands.

Runs use a 12 s simulated log (``slam sim small``) and few scans, so the whole module stays
within a couple of minutes; the real-log comparison is marked ``data`` and ``slow``.
"""

from __future__ import annotations

import contextlib
import ipaddress
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from argparse import Namespace
from pathlib import Path

import pytest
from cli_process import cli_env as env
from cli_process import sigint_as_a_terminal_gives_it, slam_cmd

from slam.cli import main
from slam.errors import UsageError
from slam.sweep.cell import sha256_of
from slam.sweep.spec import build_spec, parse_seeds, split_values

SCANS = "40"
RUN_OPTIONS = ["--particles", "10", "--max-scans", SCANS, "--no-record", "--no-texture"]


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """A 12 s simulated log (ECE276A format) with ground truth."""
    folder = tmp_path_factory.mktemp("sweep") / "small"
    args = ["sim", "small", "--out", str(folder), "--duration", "12", "--no-rgbd", "--quiet"]
    assert main(args) == 0
    return folder


@pytest.fixture(scope="module")
def local_hashes(small, tmp_path_factory) -> dict[str, str]:
    """Trajectory hashes of the 4-cell sweep (seeds 0-3) of the local executor."""
    out = tmp_path_factory.mktemp("local") / "sw"
    assert (
        main(["sweep", "--logs", str(small), "--seeds", "0-3", "--out", str(out), *RUN_OPTIONS])
        == 0
    )
    return {name: row["trajectory_sha256"] for name, row in results(out).items()}


def results(folder: Path) -> dict[str, dict]:
    """``results.json`` cells by name."""
    return {c["cell"]: c for c in json.loads((folder / "results.json").read_text())["cells"]}


def no_args(**values) -> Namespace:
    base = dict.fromkeys(
        ("logs", "seeds", "out", "workers", "executor", "address", "method", "particles", "every",
         "max_scans", "config"))  # fmt: skip
    base.update(no_texture=False, no_record=False, set=[])
    base.update(values)
    return Namespace(**base)


# --- the spec ---------------------------------------------------------------------------------


def test_seeds_values_and_the_grid_of_the_command_line():
    assert parse_seeds("0-3", "--seeds") == (0, 1, 2, 3)
    assert parse_seeds("0,2,5-6", "--seeds") == (0, 2, 5, 6)
    assert parse_seeds([4, 1], "x") == (4, 1)
    with pytest.raises(UsageError, match="--seeds: expected seeds like 0-3"):
        parse_seeds("3-1", "--seeds")
    assert split_values('10,20.5,[1,2],"a,b"') == ["10", "20.5", "[1,2]", '"a,b"']

    spec = build_spec(
        None,
        no_args(logs="intel,aces", seeds="0-1", set=["rbpf.temperature=10,20,40",
                "filter.particles=15", "loops.enabled=true,false"], max_scans=50),
    )  # fmt: skip
    cells = spec.cells()
    assert len(cells) == 2 * 2 * 3 * 2
    first = cells[0]
    assert first.name == "intel-seed0-temperature=10,enabled=true"
    # an ordinary slam run argument list: options first, the seed, then the setting
    assert first.argv == ("intel", "--max-scans", "50", "--set", "filter.particles=15", "--seed",
                          "0", "--set", "rbpf.temperature=10", "--set", "loops.enabled=true")  # fmt: skip
    assert len({c.name for c in cells}) == len(cells)


@pytest.mark.parametrize(
    "value, message",
    [
        # the bug: a list of 10**11 seeds was built (MemoryError, a traceback)
        ("0-99999999999", "--seeds: at most 10000 seeds, found 100000000000 in '0-99999999999'"),
        ("0-5000,6000-11000", "--seeds: at most 10000 seeds, found 10002 in"),
        # the bug: reported as `slam run --seed` errors, without the spec's key
        ([True], "spec.toml: [sweep] seeds: expected seeds like 0-3, 0,2,5 or a list of integers"),
        ([-1], "spec.toml: [sweep] seeds: expected seeds like 0-3"),
        (-1, "spec.toml: [sweep] seeds: expected seeds like 0-3"),
        ([0, 2**63], "spec.toml: [sweep] seeds: expected seeds like 0-3"),
        ("0,,2", "spec.toml: [sweep] seeds: expected seeds like 0-3"),
    ],
)
def test_bad_seeds_are_one_error_naming_where(value, message):
    where = "--seeds" if message.startswith("--seeds") else "spec.toml: [sweep] seeds"
    with pytest.raises(UsageError) as caught:
        parse_seeds(value, where)
    assert str(caught.value).startswith(message)


@pytest.mark.parametrize(
    "address, message",
    [
        # the bug: a ValueError traceback from ray.init, the sweep folder left behind
        ("notanaddress", "--address: expected HOST:PORT of a Ray cluster (e.g. 127.0.0.1:6379"),
        ("127.0.0.1:0", "--address: expected HOST:PORT"),
        ("ray://[::1]:99999", "--address: expected HOST:PORT"),
        # the bug: ray.init retried for minutes, the sweep folder made
        ("127.0.0.1:1", "--address 127.0.0.1:1: no Ray cluster answers there"),
    ],
)
def test_a_bad_ray_address_is_refused_before_the_sweep_folder(tmp_path, capsys, address, message):
    from slam.cli import main

    out = tmp_path / "sweep"
    argv = ["sweep", "--logs", "demo", "--seeds", "0", "--method", "odometry", "--max-scans", "3",
            "--out", str(out), "--executor", "ray", "--address", address]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"slam: error: {message}") and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_a_ray_address_is_blamed_where_it_was_given(tmp_path, capsys):
    """The review's find: a bad --address was blamed on the spec file, a spec file's address on
    --address; an address that is no string crashed."""
    from slam.cli import main

    spec = tmp_path / "s.toml"
    out = tmp_path / "sweep"
    base = ["--seeds", "0", "--method", "odometry", "--max-scans", "3", "--out", str(out)]
    spec.write_text('[sweep]\nlogs = ["demo"]\nexecutor = "ray"\n')
    assert main(["sweep", str(spec), *base, "--address", "bad addr"]) == 2
    assert capsys.readouterr().err.startswith("slam: error: --address: expected HOST:PORT")
    spec.write_text('[sweep]\nlogs = ["demo"]\nexecutor = "ray"\naddress = "127.0.0.1:1"\n')
    assert main(["sweep", str(spec), *base]) == 2
    assert capsys.readouterr().err.startswith(
        f"slam: error: {spec}: [sweep] address 127.0.0.1:1: no Ray cluster answers there"
    )
    spec.write_text('[sweep]\nlogs = ["demo"]\nexecutor = "ray"\naddress = 6379\n')
    assert main(["sweep", str(spec), *base]) == 2
    assert (
        capsys.readouterr().err
        == f"slam: error: {spec}: [sweep] address: expected str, found 6379\n"
    )
    assert not out.exists()


def test_a_finished_sweep_is_written_again_without_its_cluster(tmp_path, capsys):
    """The review's find: the probe refused a finished sweep whose Ray cluster has gone, though
    nothing is left to run (its results are written again, as before the probe)."""
    pytest.importorskip("ray")
    from slam.cli import main

    out = tmp_path / "sweep"
    argv = ["sweep", "--logs", "demo", "--seeds", "0", "--method", "odometry", "--max-scans", "3",
            "--no-record", "--no-texture", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    capsys.readouterr()
    assert main([*argv, "--executor", "ray", "--address", "127.0.0.1:1"]) == 0
    assert "(1 done, 0 to run); ray: 127.0.0.1:1" in capsys.readouterr().err


def test_ray_addresses_that_parse():
    from slam.sweep.executors import ray_endpoint

    assert ray_endpoint("10.0.0.2:6379", "x") == ("10.0.0.2", 6379)
    assert ray_endpoint("ray://head.local:10001", "x") == ("head.local", 10001)
    assert ray_endpoint("[::1]:6379", "x") == ("::1", 6379)
    assert ray_endpoint("auto", "x") is None and ray_endpoint("local", "x") is None


def test_a_tune_grid_too_large_is_refused_before_it_is_built():
    """The bug: two ranges of 100,000 steps built 10**10 grid points (MemoryError) before the
    check against ``trials``; now the size is counted first, and ``steps`` has a ceiling."""
    from slam.sweep.tune import parse_tune, trial_settings

    def table(steps: int) -> dict:
        return {"tune": {"search": "grid", "trials": 5, "ranges": {
            "rbpf.temperature": {"min": 1.0, "max": 2.0, "steps": steps},
            "rbpf.dmax": {"min": 0.1, "max": 0.5, "steps": steps},
        }}}  # fmt: skip

    with pytest.raises(UsageError, match=r"steps: expected an integer in \[1, 10000\], found"):
        parse_tune(table(100_000), "t.toml")
    with pytest.raises(UsageError) as caught:
        trial_settings(parse_tune(table(10_000), "t.toml"))
    assert str(caught.value) == (  # no advice to raise trials past their ceiling
        "[tune]: the grid has 100000000 points but trials = 5 (one is the default): lower the steps"
    )
    # the review's find: the message said to raise trials to 100000001, which then built it
    big = table(10_000)
    big["tune"]["trials"] = 100_000_001
    with pytest.raises(UsageError, match=r"trials: expected an integer in \[2, 10000\] \(the"):
        parse_tune(big, "t.toml")


def test_spec_file_explicit_settings_and_per_setting_seeds(tmp_path):
    spec_file = tmp_path / "s.toml"
    spec_file.write_text(
        '[sweep]\nlogs = ["intel"]\nseeds = "0-3"\n[run]\nno_record = true\n'
        '[[setting]]\nname = "odometry"\nset = { "filter.method" = "odometry" }\nseeds = [0]\n'
        '[[setting]]\nname = "rbpf"\n'
    )
    spec = build_spec(spec_file, no_args())
    names = [c.name for c in spec.cells()]
    assert names == ["intel-seed0-odometry"] + [f"intel-seed{s}-rbpf" for s in range(4)]
    assert spec.cells()[0].argv == ("intel", "--no-record", "--seed", "0", "--set",
                                    'filter.method="odometry"')  # fmt: skip


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[sweep]\nlogs = ['intel']\n[run]\nparticle = 3\n", "s.toml: [run] unknown key 'particle'"),
        ("[sweep]\nlogs = ['intel']\n[run]\nparticles = 0\n", "s.toml: [run] particles: expected an integer in [1, 100000], found 0"),
        ("[sweep]\nlogs = ['intel']\n[run]\nevery = 0\n", "s.toml: [run] every: expected an integer in [1, 1000000], found 0"),
        ("[sweep]\nlogs = ['intel']\n[run]\nmethod = 'fast'\n", "s.toml: [run] method: expected one of odometry, classic, rbpf, found 'fast'"),
        ("[sweep]\nlogs = ['intel']\nseeds = 'x'\n", "s.toml: [sweep] seeds: expected seeds"),
        ("[sweep]\nlogs = ['intel']\n[grid]\n'rbpf.temperature' = []\n", "[grid]: rbpf.temperature: expected a non-empty list"),
        ("[sweep]\nlogs = ['intel']\n[grid]\n'rbpf.nosuch' = [1, 2]\n", "s.toml: [grid] rbpf.nosuch: unknown key"),
        ("[sweep]\nlogs = ['nosuch-log']\n", "s.toml: [sweep] logs: 'nosuch-log' is not"),
        ("[sweep\n", "s.toml: not valid TOML"),
    ],
)  # fmt: skip
def test_bad_spec_is_one_line_exit_2_before_any_work(tmp_path, capsys, text, message):
    spec_file = tmp_path / "s.toml"
    spec_file.write_text(text)
    out = tmp_path / "out"
    assert main(["sweep", str(spec_file), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not out.exists()


GRID = "[sweep]\nlogs = ['intel']\n[grid]\n"
EVALUATION = "[sweep]\nlogs = ['intel', 'mit-killian', 'demo']\n[sweep.evaluation]\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GRID + "'rbpf.temperatur' = [1, 2]\n", "[grid] rbpf.temperatur: unknown key; expected one of coarse_stride, "),
        (GRID + "'rbpf.temperature' = ['x', 2]\n", "[grid] rbpf.temperature: expected a number, found 'x'\n"),
        (GRID + "'rbpf.temperature' = [10, -1]\n", "[grid] rbpf.temperature: expected a finite number in [0.001, 1e+06], found -1.0\n"),
        (GRID + "'loop.enabled' = [true, false]\n", "[grid] loop.enabled: unknown section [loop]; expected one of backend, "),
        (GRID + "'rbpf.sigmas' = [['x'], [1.0]]\n", "[grid] rbpf.sigmas[0]: expected a number, found 'x'\n"),
        ("[sweep]\nlogs = ['intel']\n[[setting]]\nname = 'a'\n[[setting]]\nname = 'b'\nset = { 'rbpf.temperatur' = 3 }\n",
         "[[setting]] #2 set rbpf.temperatur: unknown key; expected one of "),
        ("[sweep]\nlogs = ['intel']\n[run]\nset = ['map.resolution=-1']\n",
         "[run] set map.resolution: expected a finite number in [0.001, 10], found -1.0\n"),
        ("[sweep]\nlogs = ['intel']\n[run]\nset = ['resolution=1']\n",
         "[run] set: expected 'section.key=value' strings (e.g. 'map.resolution=0.05'), found 'resolution=1'\n"),
        ("[sweep]\nlogs = ['intl']\n", "[sweep] logs: 'intl' is not 'demo', a registry dataset ("),
        (EVALUATION + "mit-kilian = 'quality'\n", "[sweep.evaluation] mit-kilian: not a log of the sweep; expected one of its logs (intel, mit-killian, demo), found 'mit-kilian'; did you mean 'mit-killian'?\n"),
        (EVALUATION + "intel = 'ate'\n", "[sweep.evaluation] intel: 'ate' needs a ground-truth trajectory, which intel does not have; expected one of auto, quality\n"),
        (EVALUATION + "intel = 'relations'\n", "[sweep.evaluation] intel: 'relations' needs a relations file, which intel does not have ({data}/carmen/relations/intel.relations is missing); expected one of auto, quality\n"),
        (EVALUATION + "demo = 'relations'\n", "[sweep.evaluation] demo: 'relations' needs a relations file, which demo does not have; expected one of auto, ate, quality\n"),
    ],
)  # fmt: skip
def test_a_bad_spec_value_names_the_spec_file_and_key_before_any_cell(
    tmp_path, capsys, text, message
):
    """A typo in a [grid] key or value, a log, or an evaluation: one line naming the spec file
    and the key (not a --set the user never typed), exit 2, no sweep folder, no cell run."""
    spec_file, out, data = tmp_path / "s.toml", tmp_path / "out", tmp_path / "data"
    spec_file.write_text(text)
    argv = ["sweep", str(spec_file), "--out", str(out), "--data-dir", str(data), *RUN_OPTIONS]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"slam: error: {spec_file}: {message.format(data=data)}"), err
    assert err.count("\n") == 1, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("spec", "options", "message"),
    [
        (None, ["--logs", "intl"], "--logs: 'intl' is not 'demo', a registry dataset ("),
        (None, ["--logs", "intel", "--set", "rbpf.temperatur=1,2"], "--set rbpf.temperatur: unknown key; expected one of "),
        (None, ["--logs", "intel", "--set", "rbpf.temperatur=1"], "--set rbpf.temperatur=1: rbpf.temperatur: unknown key; "),
        # the file's axis keeps its name beside an axis of the command line
        (GRID + "'rbpf.temperature' = [10, -1]\n", ["--set", "filter.particles=10,20"],
         "{spec}: [grid] rbpf.temperature: expected a finite number in [0.001, 1e+06], found -1.0\n"),
        (GRID + "'rbpf.temperature' = [10, 20]\n", ["--set", "rbpf.temperature=10,-1"],
         "--set rbpf.temperature: expected a finite number in [0.001, 1e+06], found -1.0\n"),
        # one value for every cell and an axis of the same key: each cell's axis value would win
        (GRID + "'rbpf.temperature' = [10, 20]\n", ["--set", "rbpf.temperature=-5"],
         "--set rbpf.temperature=-5: rbpf.temperature is also an axis of the sweep's settings"),
        (GRID + "'rbpf.temperature' = [10, 20]\n[run]\nset = ['rbpf.temperature=-3']\n", [],
         "{spec}: [run] set rbpf.temperature: rbpf.temperature is also an axis of the sweep's "),
        # a spec without logs: its evaluation is checked against those of --logs
        ("[sweep.evaluation]\nmit-kilian = 'quality'\n", ["--logs", "intel"],
         "{spec}: [sweep.evaluation] mit-kilian: not a log of the sweep; expected one of its logs (intel), found 'mit-kilian'\n"),
    ],
)  # fmt: skip
def test_a_bad_command_line_value_names_the_option(tmp_path, capsys, spec, options, message):
    spec_file, out = tmp_path / "s.toml", tmp_path / "out"
    argv = ["sweep", "--out", str(out), *RUN_OPTIONS, *options]
    if spec is not None:
        spec_file.write_text(spec)
        argv.insert(1, str(spec_file))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"slam: error: {message.format(spec=spec_file)}"), err
    assert err.count("\n") == 1, err
    assert not out.exists()


def test_a_spec_without_logs_keeps_the_evaluation_of_logs_another_run_names(tmp_path):
    """A spec without [sweep] logs, run for one log at a time (as tools/bench.py runs its spec):
    the evaluation of the other logs stays, and only a name that is no dataset is refused."""
    spec_file = tmp_path / "s.toml"
    spec_file.write_text("[sweep.evaluation]\nmit-killian = 'quality'\nintel = 'relations'\n")
    spec = build_spec(spec_file, no_args(logs="intel", seeds="0"))
    assert spec.logs == ("intel",) and dict(spec.evaluation)["mit-killian"] == "quality"
    spec_file.write_text("[sweep.evaluation]\nmit-kilian = 'quality'\n")
    with pytest.raises(UsageError, match=r"\[sweep.evaluation\] mit-kilian: not a log of the"):
        build_spec(spec_file, no_args(logs="intel", seeds="0"))


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("'loop.enabled' = { values = [true, false] }", "loop.enabled: unknown section [loop]; expected "),
        ("'filter.particle' = { min = 1, max = 3 }", "filter.particle: unknown key; expected one of every, "),
        # an end outside the key's bounds is named as written, not as a value drawn from it
        ("'filter.particles' = { min = 0, max = 60, int = true }", "filter.particles: min: expected an integer in [1, 100000], found 0\n"),
        ("'filter.particles' = { min = 10, max = 200000, int = true }", "filter.particles: max: expected an integer in [1, 100000], found 200000\n"),
        ("'rbpf.temperature' = { min = -5.0, max = 80.0 }", "rbpf.temperature: min: expected a finite number in [0.001, 1e+06], found -5.0\n"),
        ("'filter.method' = { values = ['rbpf', 'fast'] }", "filter.method: values[1]: expected one of odometry, classic, rbpf, found 'fast'\n"),
        ("'filter.particles' = { values = [10, 'x'] }", "filter.particles: values[1]: expected an integer, found 'x'\n"),
        ("'filter.particles' = { min = 0.6, max = 2, int = true }", "filter.particles: min: expected a whole number with int = true, found 0.6\n"),
        ("'filter.particles' = { min = 10, max = 60 }", "filter.particles: an integer key: add int = true (draws whole numbers)\n"),
    ],
)  # fmt: skip
def test_a_bad_tune_range_names_the_spec_file_and_key(tmp_path, capsys, item, message):
    spec_file, out = tmp_path / "t.toml", tmp_path / "out"
    spec_file.write_text(f"[sweep]\nlogs = ['intel']\n[tune]\ntrials = 3\n[tune.ranges]\n{item}\n")
    assert main(["tune", str(spec_file), "--out", str(out), *RUN_OPTIONS]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"slam: error: {spec_file}: [tune.ranges] {message}"), err
    assert err.count("\n") == 1, err
    assert not out.exists()


def test_a_folder_not_made_by_slam_sweep_is_left_alone(small, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    assert main(["sweep", "--logs", str(small), "--out", str(out), *RUN_OPTIONS]) == 2
    assert "is not a sweep folder of slam" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


# --- resume, crash ----------------------------------------------------------------------------


def _signal_state(pid: int) -> str:
    """The signal lines and thread count of ``/proc/PID/status`` (Linux), or why there are none."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError as exc:
        return f"no /proc status ({exc.strerror})"
    keep = ("Sig", "ShdPnd", "Threads", "State")
    return "; ".join(line for line in status.splitlines() if line.startswith(keep))


def test_sigint_then_rerun_finishes_only_the_missing_cells(small, local_hashes, tmp_path):
    """Ctrl-C during a 4-cell sweep (one worker), sent when the first cell has finished: exit
    130, no partial folder left, the finished cells in results.json; the same command again runs
    only the missing cells."""
    out = tmp_path / "sw"
    cmd = slam_cmd("sweep", "--logs", str(small), "--seeds", "0-3", "--workers", "1", "--out",
                   str(out), *RUN_OPTIONS)  # fmt: skip
    proc = subprocess.Popen(
        cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=sigint_as_a_terminal_gives_it,
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while not list(out.glob("*/eval.json")) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)
    state = _signal_state(proc.pid)  # for the message below, should the signal be lost
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (
        f"exit {proc.returncode}; 0.3 s after SIGINT: {state}\nstdout:\n{stdout}\nstderr:\n{stderr}"
    )
    assert "rerun the same command to finish them" in stderr
    done = {c for c, r in results(out).items() if r["status"] == "ok"}
    assert 1 <= len(done) < 4, (stdout, stderr)
    assert not [p for p in out.rglob("*.partial")]
    assert all((out / c / ".slam-run").is_file() for c in done)
    before = {c: os.stat(out / c / "trajectory.tum").st_ino for c in done}

    again = subprocess.run(cmd, env=env(), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"({4 - len(done)} run, {len(done)} already done, 0 failed)" in again.stdout
    assert {c: os.stat(out / c / "trajectory.tum").st_ino for c in done} == before
    final = results(out)
    assert len(final) == 4 and all(r["status"] == "ok" for r in final.values())
    assert all(r["metric"] == "ate" and 0 <= r["error"] < 0.5 for r in final.values())
    # one worker (NUMBA_NUM_THREADS = the cores) gives the trajectories of the default pool
    assert {c: final[c]["trajectory_sha256"] for c in local_hashes} == local_hashes
    # a finished sweep is not run again
    third = subprocess.run(cmd, env=env(), capture_output=True, text=True, timeout=120)
    assert "(0 run, 4 already done, 0 failed)" in third.stdout


def test_a_crashing_cell_is_recorded_and_the_sweep_goes_on(small, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(small, broken)
    (broken / "Hokuyo20.npz").write_bytes(b"PK\x03\x04 not a zip file")
    out = tmp_path / "sw"
    code = main(["sweep", "--logs", f"{small},{broken}", "--out", str(out), *RUN_OPTIONS])
    assert code == 1
    captured = capsys.readouterr()
    rows = results(out)
    assert rows["small-seed0"]["status"] == "ok"
    assert rows["broken-seed0"]["status"] == "error"
    assert "Hokuyo20.npz" in rows["broken-seed0"]["message"]
    assert "cell broken-seed0 failed" in captured.err
    assert not (out / "broken-seed0").exists()
    csv_lines = (out / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 3 and csv_lines[0].startswith("cell,log,seed,setting,status")


# --- tune -------------------------------------------------------------------------------------


def test_tune_finds_a_setting_at_least_as_good_as_the_default_and_writes_it(
    small, tmp_path, capsys
):
    """Budget: 4 trials (the default and 3 random draws of rbpf.temperature), 1 seed, the whole
    log (480 scans: the robot drives, so the ATE is not ~0 as over the first scans)."""
    spec_file = tmp_path / "tune.toml"
    spec_file.write_text(
        f'[sweep]\nlogs = ["{small}"]\nseeds = [0]\n[run]\nparticles = 10\n'
        "no_record = true\nno_texture = true\n"
        '[tune]\ntrials = 4\nseed = 1\n[tune.ranges]\n"rbpf.temperature" = { min = 2.0, max = 60.0, log = true }\n'
    )
    out = tmp_path / "tune"
    assert main(["tune", str(spec_file), "--out", str(out)]) == 0
    report = json.loads((out / "tune.json").read_text())
    assert len(report["trials"]) == 4
    best, default = report["best"], report["default"]
    assert 0.001 < best["error_mean"] <= default["error_mean"] < 0.5
    assert any(t["pareto"] for t in report["trials"])
    config = out / "config.toml"
    assert "[rbpf]" in config.read_text() or best["trial"] == "trial000-default"
    # the written configuration reproduces the best trial
    run = tmp_path / "again"
    assert main(["run", str(small), "--config", str(config), "--seed", "0",
                 "--no-record", "--no-texture", "--quiet", "--out", str(run)]) == 0  # fmt: skip
    ate = json.loads((run / "metrics.json").read_text())["ate_rmse"]
    assert ate == pytest.approx(best["error_mean"], rel=1e-9)
    assert "best trial" in capsys.readouterr().out


# --- Ray --------------------------------------------------------------------------------------


CLUSTER = """
import signal, sys
from ray.cluster_utils import Cluster
cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                        "node_ip_address": "127.0.0.1"})
cluster.add_node(num_cpus=1, node_ip_address="127.0.0.1")
cluster.wait_for_nodes()
print("ADDRESS", cluster.address, flush=True)
signal.sigwait({signal.SIGTERM, signal.SIGINT})
cluster.shutdown()
"""
"""A two-node Ray cluster on this machine (Ray's own test cluster, ``ray.cluster_utils``): the
head and one extra worker node, one CPU each, every address 127.0.0.1; stops on SIGTERM."""


def _loopback(ip: str) -> bool:
    address = ipaddress.ip_address(ip)
    mapped = getattr(address, "ipv4_mapped", None)
    return (mapped or address).is_loopback


def _descendants(psutil, pid: int) -> list:
    with contextlib.suppress(psutil.Error):
        return psutil.Process(pid).children(recursive=True)
    return []


def test_ray_cluster_survives_a_killed_worker(small, local_hashes, tmp_path):
    """A local Ray cluster started by the test: a head node and one extra worker node (one CPU
    each, every address on 127.0.0.1, dashboard off). A Ray worker process of the extra node
    running a cell is killed mid-sweep; Ray re-runs the cell and every cell's trajectory equals
    that of the local executor."""
    pytest.importorskip("ray", reason="Ray is not installed (uv sync --extra ray)")
    psutil = pytest.importorskip("psutil")
    temp = Path("/tmp") / f"slam-ray-{os.getpid()}"  # short: Ray's socket paths are limited
    temp.mkdir(exist_ok=True)
    ray_env = env(
        RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="0",  # every Ray address on 127.0.0.1
        RAY_USAGE_STATS_ENABLED="0",
        RAY_TMPDIR=str(temp),
        RAY_worker_register_timeout_seconds="300",  # a loaded 2-core machine starts workers slowly
        RAY_ENABLE_UV_RUN_RUNTIME_ENV="0",
    )
    starter = subprocess.Popen(
        [sys.executable, "-c", CLUSTER], env=ray_env, start_new_session=True,
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    out = tmp_path / "ray"
    sweep = ["sweep", "--logs", str(small), "--seeds", "0-3", *RUN_OPTIONS]
    driver = None
    try:
        line = starter.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith("ADDRESS 127.0.0.1:"), f"the Ray cluster did not start: {line!r}"
        address = line.split()[1]
        raylets = sorted(
            (p for p in _descendants(psutil, starter.pid) if p.name() == "raylet"),
            key=lambda p: p.create_time(),
        )
        assert len(raylets) == 2, raylets  # the head's and the extra node's
        extra = raylets[1]
        listening = {
            c.laddr.ip
            for p in [psutil.Process(starter.pid), *_descendants(psutil, starter.pid)]
            for c in p.net_connections("inet")
            if c.status == psutil.CONN_LISTEN
        }
        assert listening and all(_loopback(ip) for ip in listening), listening
        driver = subprocess.Popen(
            slam_cmd(*sweep, "--out", str(out), "--executor", "ray", "--address", address),
            env=ray_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        killed = None
        deadline = time.monotonic() + 180
        while killed is None and time.monotonic() < deadline and driver.poll() is None:
            for proc in _descendants(psutil, extra.pid):
                with contextlib.suppress(psutil.Error):
                    if proc.name() == "ray::ray_cell" or proc.cmdline()[:1] == ["ray::ray_cell"]:
                        time.sleep(1.0)  # let it get into the run
                        proc.kill()
                        killed = proc.pid
                        break
            time.sleep(0.2)
        stdout, stderr = driver.communicate(timeout=600)
        assert killed is not None, "no Ray worker of the extra node running a cell was found"
        assert driver.returncode == 0, stderr
        assert "(4 run, 0 already done, 0 failed)" in stdout
    finally:
        if driver is not None and driver.poll() is None:
            driver.kill()
            driver.wait()
        pids = {p.pid for p in _descendants(psutil, starter.pid)}
        starter.terminate()  # the cluster shuts its nodes down
        with contextlib.suppress(subprocess.TimeoutExpired):
            starter.wait(timeout=60)
        for proc in psutil.process_iter(["pid", "cmdline"]):
            if proc.info["pid"] != os.getpid() and str(temp) in " ".join(
                proc.info["cmdline"] or []
            ):
                pids.add(proc.info["pid"])
        left = [pid for pid in pids if psutil.pid_exists(pid)]
        for pid in [starter.pid, *left]:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        starter.wait(timeout=60)  # reaped, so no "subprocess is still running" warning
        starter.stdout.close()  # type: ignore[union-attr]
        shutil.rmtree(temp, ignore_errors=True)
    ray_rows = results(out)
    assert len(ray_rows) == 4
    for name, row in ray_rows.items():
        assert row["status"] == "ok"
        assert row["trajectory_sha256"] == local_hashes[name], name
        assert sha256_of(out / name / "trajectory.tum") == row["trajectory_sha256"]
        assert (out / name / ".slam-run").is_file() and (out / name / "eval.json").is_file()


# --- real logs: a sweep is the same as separate runs ------------------------------------------


@pytest.mark.data
@pytest.mark.slow
def test_sweep_cells_equal_separate_slam_runs(carmen_dir, data_dir, tmp_path):
    """intel, aces, fr079 × seeds 0-1 × 2 settings (12 cells, 250 scans of 5 particles each: the
    first relations of intel end at scan 243, of aces at 134, of fr079 at 25): every cell's
    trajectory.tum is byte-identical to that of the equivalent separate ``slam run`` (run here in
    this process, with numba's default thread count; the sweep's workers use one thread). Two
    seeds are enough to show that the seed reaches the cell; four doubled the suite's longest
    test (148 s on a slow host)."""
    options = [
        "--max-scans",
        "250",
        "--particles",
        "5",
        "--no-record",
        "--no-texture",
        "--set",
        "quality.enabled=false",
    ]
    out = tmp_path / "sw"
    code = main(["sweep", "--logs", "intel,aces,fr079", "--seeds", "0-1", "--set",
                 "rbpf.temperature=10,40", "--out", str(out), "--data-dir", str(data_dir), *options])  # fmt: skip
    assert code == 0
    rows = results(out)
    assert len(rows) == 12
    assert {row["seed"] for row in rows.values()} == {0, 1}
    for name, row in rows.items():
        assert row["metric"] == "relations"
        separate = tmp_path / "runs" / name
        temperature = name.rsplit("=", 1)[1]
        argv = ["run", row["log"], "--seed", str(row["seed"]), *options, "--set",
                f"rbpf.temperature={temperature}", "--out", str(separate), "--quiet",
                "--data-dir", str(data_dir)]  # fmt: skip
        assert main(argv) == 0
        assert sha256_of(separate / "trajectory.tum") == row["trajectory_sha256"], name
        assert sha256_of(out / name / "trajectory.tum") == row["trajectory_sha256"], name
        assert (separate / "config.toml").read_text() == (out / name / "config.toml").read_text()


@pytest.mark.parametrize(
    "address, message",
    [
        (None, "--executor ray: cannot start a local Ray instance (no resources)"),
        ("10.0.0.2:6379", "--address 10.0.0.2:6379: cannot reach a Ray cluster (no resources)"),
    ],
)
def test_a_failed_ray_init_names_what_was_asked(tmp_path, monkeypatch, address, message):
    """A local Ray instance that fails to start is not called an address "None" that cannot be
    reached; a cluster that cannot be joined names its address."""
    pytest.importorskip("ray")
    from types import SimpleNamespace

    from slam.sweep.executors import LOOPBACK_ONLY, NO_UV_RUN_HOOK, RayExecutor

    for name in (LOOPBACK_ONLY, NO_UV_RUN_HOOK):  # the executor sets them: restored afterwards
        monkeypatch.setenv(name, os.environ.get(name, "0"))

    executor = RayExecutor(1, tmp_path, address)

    def init(**options):
        raise RuntimeError("no resources\nmore detail")

    executor.ray = SimpleNamespace(init=init)
    with pytest.raises(UsageError) as caught:
        executor._init()
    assert str(caught.value) == message

"""Output safety, signals and the environment (issue 11, items 1-3, 10-12).

Each test names the item of issue 11 it shows and fails on the code before the fix (checked
against ``main`` at 19f712c), except the guard that bugs keep their traceback. Runs use a small simulated log (``slam sim small``,
12 s, no Kinect) and ``--max-scans`` so that each test takes a few seconds.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_process import cli_env, finished_run, slam_cmd

from slam import cli
from slam.cli import main
from slam.errors import Terminated, UsageError
from slam.io import atomic
from slam.io.atomic import atomic_dir

OWNER_FILE = ".slam-partial"
"""The owner record of a partial folder (:data:`slam.io.runfolder.OWNER_FILE`)."""

SCANS = "20"


def refuse_inside(
    monkeypatch: pytest.MonkeyPatch, function: str, folder: Path, error: type[OSError], code: int
) -> None:
    """Patch ``os.<function>`` to raise ``error(code)`` for every path inside ``folder`` (a
    condition a test cannot create for real, e.g. as root)."""
    real = getattr(os, function)

    def refuse(path, *args, **kwargs):
        if str(path).startswith(str(folder) + os.sep):
            raise error(code, os.strerror(code), str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(os, function, refuse)


def partials(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.name.endswith(".partial"))


def one_line(err: str) -> str:
    """``err`` is exactly one line, without traceback or rerun log lines."""
    assert err.count("\n") == 1, err
    assert "Traceback" not in err and "ERROR" not in err and "\x1b[" not in err, err
    return err


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """A 12 s simulated log (ECE276A format) with ground truth."""
    folder = tmp_path_factory.mktemp("safety") / "small"
    assert (
        main(["sim", "small", "--out", str(folder), "--duration", "12", "--no-rgbd", "--quiet"])
        == 0
    )
    return folder


def make_run(small: Path, out: Path, *extra: str) -> Path:
    """A finished run folder of ``slam run`` at ``out`` (20 scans)."""
    return finished_run(small, out, "--max-scans", SCANS, "--particles", "10", "--quiet", *extra)


def wait_for_partial(parent: Path, process: subprocess.Popen, timeout_s: float = 60.0) -> Path:
    """The partial folder a CLI subprocess is assembling in ``parent``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = partials(parent) if parent.is_dir() else []
        if found:
            return found[0]
        assert process.poll() is None, process.communicate()
        time.sleep(0.02)
    raise AssertionError(f"no partial folder appeared in {parent}")


# --- item 1: --force replaces only our own run folders --------------------------------------


def test_force_never_replaces_an_input_folder_or_a_folder_that_is_not_a_run_folder(
    small, tmp_path, capsys
):
    """Item 1 (fails on main: ``--force`` wiped the folder, the input log with it). The folder
    holding the log, a folder of the user's, a folder that only looks like a run folder (no
    marker) and a plain file are all refused with one line; nothing is touched."""
    data = tmp_path / "d"
    shutil.copytree(small, data / "small")
    before = sorted(p.name for p in (data / "small").iterdir())
    assert main(["run", str(data / "small"), "--out", str(data), "--force", "--quiet"]) == 2
    err = one_line(capsys.readouterr().err)
    assert f"{data}: --out holds an input of this command ({data / 'small'})" in err
    assert sorted(p.name for p in (data / "small").iterdir()) == before

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    (mine / "metrics.json").write_text("{}")
    (mine / "config.toml").write_text("")  # looks like a run folder, but has no marker
    assert main(["run", str(small), "--out", str(mine), "--force", "--quiet"]) == 2
    err = one_line(capsys.readouterr().err)
    assert "--force replaces only a run folder written by `slam run`" in err
    assert ".slam-run" in err and "left alone" in err
    assert (mine / "thesis.tex").read_text() == "years of work"

    plain = tmp_path / "notes.txt"
    plain.write_text("keep")
    assert main(["run", str(small), "--out", str(plain), "--force", "--quiet"]) == 2
    assert "--out expected a folder to create, found a file" in one_line(capsys.readouterr().err)
    assert plain.read_text() == "keep"
    assert not partials(tmp_path)


def test_force_replaces_our_own_run_folder_but_never_through_a_symlink(small, tmp_path, capsys):
    """Item 1 (fails on main: with --force a symlinked --out was renamed to ``.link.old-PID``
    and replaced by a new folder; run folders had no marker). A run folder of ``slam run``
    (marker ``.slam-run`` + metrics.json + config.toml) is replaced with --force; the same
    folder reached through a symbolic link, or holding the --config file, is not."""
    run = make_run(small, tmp_path / "run")
    link = tmp_path / "link"
    link.symlink_to(run)
    stamp = (run / "metrics.json").read_bytes()
    for force in ((), ("--force",)):
        assert main(["run", str(small), "--out", str(link), "--quiet", *force]) == 2
        assert "--out is a symbolic link" in one_line(capsys.readouterr().err)
    assert (run / "metrics.json").read_bytes() == stamp and link.is_symlink()

    assert main(["run", str(small), "--out", str(run), "--config", str(run / "config.toml"),
                 "--force", "--quiet"]) == 2  # fmt: skip
    assert "holds an input of this command" in one_line(capsys.readouterr().err)
    assert (run / ".slam-run").is_file() and not (run / OWNER_FILE).exists()

    inode = run.stat().st_ino
    make_run(small, run, "--force", "--seed", "3")
    assert json.loads((run / "metrics.json").read_text())["seed"] == 3
    assert run.stat().st_ino != inode  # a new folder, renamed into place
    assert not partials(tmp_path) and not (run / OWNER_FILE).exists()


def test_sim_force_replaces_only_a_simulated_dataset(tmp_path, capsys):
    """Item 1 for ``slam sim --out`` (fails on main: --force replaced any folder). A run
    folder of ``slam run`` is not a dataset of ``slam sim`` either."""
    fake = tmp_path / "fake"
    fake.mkdir()
    for name in ("metrics.json", "config.toml", ".slam-run"):
        (fake / name).write_text("x")
    args = ["sim", "small", "--duration", "1", "--no-rgbd", "--quiet", "--force", "--out"]
    assert main([*args, str(fake)]) == 2
    assert "--force replaces only a simulated dataset written by `slam sim`" in one_line(
        capsys.readouterr().err
    )
    assert sorted(p.name for p in fake.iterdir()) == [".slam-run", "config.toml", "metrics.json"]


# --- item 2: the final rename never replaces a folder that appeared meanwhile ---------------


@pytest.mark.parametrize("renameat2", [True, False], ids=["renameat2", "mkdir-fallback"])
def test_final_rename_never_replaces_a_folder_that_appeared_meanwhile(
    tmp_path, monkeypatch, renameat2
):
    """Item 2 (fails on main: the folder that appeared was moved aside and deleted). Both with
    ``renameat2(RENAME_NOREPLACE)`` and with the mkdir-claim fallback, an empty or a non-empty
    folder created at the destination while the output is assembled survives, and the command
    fails with a clear error leaving no partial folder."""
    if not renameat2:
        monkeypatch.setattr(atomic, "_renameat2", lambda src, dst, flags: False)
    for content in ((), ("other.txt",)):
        out = tmp_path / f"out{len(content)}"
        appeared = pytest.raises(UsageError, match="another process created this folder")
        with appeared, atomic_dir(out) as tmp:
            (tmp / "metrics.json").write_text("{}")
            (tmp / "config.toml").write_text("")
            out.mkdir()
            for name in content:
                (out / name).write_text("theirs")
        assert out.is_dir() and sorted(p.name for p in out.iterdir()) == list(content)
        kept = tmp_path / f"{out.name}-2"  # the finished result, not lost: named in the error
        assert str(kept) in str(appeared.excinfo.value)
        assert sorted(p.name for p in kept.iterdir()) == [
            ".slam-run",
            "config.toml",
            "metrics.json",
        ]
    assert not partials(tmp_path)


@pytest.mark.parametrize("exchange", [True, False], ids=["rename-exchange", "move-aside"])
def test_force_replacement_is_race_safe(tmp_path, monkeypatch, exchange):
    """Item 2 with --force (fails on main: whatever sat at the destination at the end was
    deleted). If our run folder is replaced by another folder while the new one is assembled,
    that folder is kept and the command fails; otherwise the old run folder is replaced."""
    if not exchange:
        real = atomic._renameat2
        monkeypatch.setattr(
            atomic,
            "_renameat2",
            lambda s, d, f: False if f == atomic._RENAME_EXCHANGE else real(s, d, f),
        )

    def write_run(folder: Path, seed: int) -> None:
        (folder / "metrics.json").write_text(json.dumps({"seed": seed}))
        (folder / "config.toml").write_text("")

    out = tmp_path / "out"
    with atomic_dir(out) as tmp:
        write_run(tmp, 1)
    with atomic_dir(out, overwrite=True) as tmp:
        write_run(tmp, 2)
    assert json.loads((out / "metrics.json").read_text()) == {"seed": 2}

    changed = pytest.raises(UsageError, match="the folder changed while this command was running")
    with changed, atomic_dir(out, overwrite=True) as tmp:
        write_run(tmp, 3)
        shutil.rmtree(out)
        out.mkdir()
        (out / "theirs.txt").write_text("theirs")
    assert sorted(p.name for p in out.iterdir()) == ["theirs.txt"]
    assert not partials(tmp_path)


def test_two_concurrent_runs_into_one_out_give_one_result_and_one_exit_2(small, tmp_path):
    """Item 2 (fails on main: both exited 0 and one result silently replaced the other). Two
    identical ``slam run --out X`` started 1 s apart: one exit 0 with a complete run folder, one
    exit 2 with one clear line, and no partial folder left."""
    out = tmp_path / "X"
    cmd = slam_cmd("run", str(small), "--out", str(out), "--particles", "60", "--quiet")
    first = subprocess.Popen(
        cmd, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    time.sleep(1.0)
    second = subprocess.Popen(
        cmd, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    results = [(p.wait(timeout=300), *p.communicate()) for p in (first, second)]
    codes = sorted(code for code, _, _ in results)
    assert codes == [0, 2], results
    (loser_err,) = [err for code, _, err in results if code == 2]
    one_line(loser_err)
    assert (
        "another slam process" in loser_err
        or "another process created this folder" in loser_err
        or "output folder exists and is not empty" in loser_err
    ), loser_err
    assert (out / "metrics.json").is_file() and (out / ".slam-run").is_file()
    assert not partials(tmp_path)


# --- item 3: SIGTERM, SIGKILL and stale partial folders -------------------------------------


def test_a_sigterm_whose_exception_a_callback_swallowed_still_ends_the_command(tmp_path):
    """Python swallows an exception raised in some callbacks (a weakref's, the import system's
    lock release: "Exception ignored in ..."); a SIGTERM arriving there must still end the
    command: no output committed, Terminated, and no stale signal for the next command."""
    with cli._termination_as_interrupt():
        with contextlib.suppress(Terminated):  # what Python does with it in such a callback
            cli._raise_terminated(signal.SIGTERM, None)
        with pytest.raises(Terminated) as caught, atomic_dir(tmp_path / "out") as folder:
            (folder / "trajectory.tum").write_text("0 0 0 0 0 0 0 1\n")
    assert caught.value.signum == signal.SIGTERM
    assert list(tmp_path.iterdir()) == []
    with cli._termination_as_interrupt(), atomic_dir(tmp_path / "next") as folder:
        (folder / "trajectory.tum").write_text("0 0 0 0 0 0 0 1\n")
    assert (tmp_path / "next" / "trajectory.tum").is_file()


def test_sigterm_exits_143_and_sigkill_leftovers_go_with_the_next_run(small, tmp_path, capsys):
    """Item 3 (fails on main: SIGTERM and SIGKILL both left ``.X.<rand>.partial`` folders that
    nothing removed). SIGTERM is handled like Ctrl-C: exit 143, one line, nothing left. After
    SIGKILL the partial folder carries the owner's pid; the next run into the same parent folder
    removes it (its process is gone)."""
    parent = tmp_path / "runs"
    cmd = slam_cmd("run", str(small), "--out", str(parent / "a"), "--quiet")
    process = subprocess.Popen(
        cmd, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    wait_for_partial(parent, process)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 143, err
    assert one_line(err) == "slam: terminated by SIGTERM\n"
    assert list(parent.iterdir()) == []

    process = subprocess.Popen(
        cmd, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    left = wait_for_partial(parent, process)
    from slam.io.runfolder import read_owner

    deadline = time.monotonic() + 60  # the owner record follows the folder's creation
    while read_owner(left) is None and time.monotonic() < deadline:
        time.sleep(0.05)
    process.kill()
    process.communicate(timeout=60)

    assert process.returncode == -signal.SIGKILL
    assert left.is_dir() and read_owner(left)["pid"] == process.pid
    assert read_owner(left)["target"] == "a"

    make_run(small, parent / "b")
    assert "removed 1 stale partial folder(s) of interrupted runs" in capsys.readouterr().err
    assert sorted(p.name for p in parent.iterdir()) == ["b"]


def _dead_pid_partial(parent: Path, target: str) -> Path:
    """A partial folder made by a process that was then SIGKILLed."""
    from slam.io.runfolder import read_owner

    code = (
        "import os, sys; from pathlib import Path; from slam.io.runfolder import make_partial; "
        f"p = make_partial(Path({str(parent)!r}), {target!r}); (p / 'map.npz').write_bytes(b'x' * 4096); "
        "os.kill(os.getpid(), 9)"
    )
    subprocess.run([sys.executable, "-c", code], env=cli_env(), check=False, timeout=60)
    (found,) = [p for p in partials(parent) if read_owner(p)["target"] == target]
    return found


def test_runs_clean_removes_only_stale_partial_folders(tmp_path, capsys):
    """Item 3 (fails on main: there is no ``slam runs clean``). It removes partial folders whose
    process is gone, keeps a live one, and leaves alone a ``.partial`` folder without our owner
    record and every other folder."""
    from slam.io.runfolder import make_partial

    stale = _dead_pid_partial(tmp_path, "old")
    live = make_partial(tmp_path, "current")  # ours: this test process is alive
    foreign = tmp_path / ".photos.partial"
    foreign.mkdir()
    (foreign / "img.jpg").write_text("x")
    (tmp_path / "run").mkdir()
    assert main(["runs", "clean", str(tmp_path), "--dry-run"]) == 0
    assert stale.is_dir()
    assert "would remove 1 stale partial folder(s)" in capsys.readouterr().out
    assert main(["runs", "clean", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"removed {stale}" in out and "gone" in out
    assert f"kept {live}" in out and "still running" in out
    assert f"left {foreign}" in out
    assert out.splitlines()[-1] == "removed 1 stale partial folder(s) (0.0 MB); kept 2"
    assert not stale.exists() and live.is_dir() and (foreign / "img.jpg").is_file()
    assert main(["runs", "clean", str(tmp_path / "nowhere")]) == 2
    assert (
        "nowhere: expected a folder holding run folders, found nothing" in capsys.readouterr().err
    )
    assert main(["runs", "clean", str(foreign / "img.jpg")]) == 2
    assert "img.jpg: expected a folder holding run folders, found a file" in capsys.readouterr().err
    # a folder given twice is looked at once
    twice = tmp_path / "twice"
    twice.mkdir()
    again = _dead_pid_partial(twice, "again")
    assert main(["runs", "clean", str(twice), str(twice) + "/", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.count(f"would remove {again}") == 1 and ", started " in out


def test_runs_clean_without_a_runs_folder_has_nothing_to_do(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["runs", "clean"]) == 0
    assert capsys.readouterr().out == "no runs folder here: nothing to clean\n"


def test_a_reused_pid_is_not_a_live_owner(tmp_path):
    """Item 3: the owner record holds the process's start time, so a partial folder whose pid
    now belongs to another process (same pid, other start time) counts as stale."""
    from slam.io.runfolder import find_partials, make_partial, owner_record, owner_state

    record = owner_record("x")
    assert owner_state(record) == "live"
    if record["process_start"] is None:
        pytest.skip("no /proc/<pid>/stat: process start times unavailable")
    assert owner_state({**record, "process_start": record["process_start"] + 1}) == "gone"
    assert owner_state({**record, "host": record["host"] + "-elsewhere"}) == "unknown"
    folder = make_partial(tmp_path, "x")
    (folder / OWNER_FILE).write_text(json.dumps({**record, "process_start": 0}))
    (state,) = [p.state for p in find_partials(tmp_path)]
    assert state == "gone"


# --- item 10: the environment gives one line and the right exit code ------------------------


def test_out_is_a_file_under_a_file_or_ends_in_dotdot(small, tmp_path, monkeypatch, capsys):
    """Item 10 (fails on main: a NotADirectoryError traceback for a file; '[Errno 17] File
    exists' for a path under a file; ``b/..`` with --force ran the whole log, then died with
    an EBUSY traceback)."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert main(["run", str(small), "--out", str(afile), "--quiet"]) == 2
    assert "--out expected a folder to create, found a file" in one_line(capsys.readouterr().err)
    assert main(["run", str(small), "--out", str(afile / "x"), "--quiet"]) == 2
    assert f"--out cannot be created: {afile} is a file" in one_line(capsys.readouterr().err)
    monkeypatch.chdir(tmp_path)
    Path("b").mkdir()
    assert main(["run", str(small), "--out", "b/..", "--force", "--quiet"]) == 2
    assert "--out expected a path ending in a new folder's name, found '..'" in one_line(
        capsys.readouterr().err
    )
    assert afile.read_text() == "x" and Path("b").is_dir() and not partials(tmp_path)


def test_out_on_a_mount_point_is_one_line(small, capsys):
    """Item 10 (fails on main: with --force the whole run ran, then ``os.replace`` of the mount
    point died with an EBUSY traceback). ``/proc`` is a mount point on every Linux system."""
    if not os.path.ismount("/proc"):
        pytest.skip("/proc is not a mount point here")
    assert main(["run", str(small), "--out", "/proc", "--force", "--quiet"]) == 2
    assert "/proc: --out is a mount point" in one_line(capsys.readouterr().err)


def test_out_on_a_file_system_that_refuses_writes_is_one_line(small, tmp_path, monkeypatch, capsys):
    """Item 10 (fails on main: an EPERM/EROFS traceback from ``mkdtemp``). ``/sys`` refuses new
    folders (EPERM as root, EACCES otherwise), a real condition; EROFS is simulated."""
    if Path("/sys").is_dir():
        assert main(["run", str(small), "--out", "/sys/slam-test-run", "--quiet"]) == 2
        err = one_line(capsys.readouterr().err)
        assert err.startswith("slam: error: --out /sys/slam-test-run: cannot write in /sys (")
        assert "Operation not permitted" in err or "Permission denied" in err
    readonly = tmp_path / "ro"
    readonly.mkdir()
    refuse_inside(monkeypatch, "mkdir", readonly, OSError, errno.EROFS)
    assert main(["run", str(small), "--out", str(readonly / "out"), "--quiet"]) == 2
    err = one_line(capsys.readouterr().err)
    assert f"{readonly}/" in err and "Read-only file system" in err


def test_a_full_disk_is_one_line_and_leaves_nothing(small, tmp_path, monkeypatch, capsys):
    """Item 10 (fails on main: three chained ENOSPC tracebacks). The writer fails with ENOSPC
    without naming a file (as ``np.savez`` and rerun's file writer do); the error names the
    run folder and the partial folder is gone."""
    import slam.pipeline

    def full(path, text):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(slam.pipeline, "write_text", full)
    out = tmp_path / "out"
    assert main(["run", str(small), "--out", str(out), "--max-scans", SCANS, "--quiet"]) == 2
    err = one_line(capsys.readouterr().err)
    assert err == f"slam: error: {out}: No space left on device; nothing was written\n"
    assert list(tmp_path.iterdir()) == []


def _mount_tmpfs(folder: Path, size: str) -> bool:
    folder.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
        capture_output=True,
        check=False,
    )
    return done.returncode == 0


def test_a_failed_run_closes_its_recording_before_its_folder_goes(small, tmp_path, monkeypatch,
                                                                 capsys):  # fmt: skip
    """A run that fails after its recorder started (here: writing its outputs) disconnects the
    recording while its partial folder still exists, once; a run that succeeds never aborts.
    Before, rerun's threads kept the file open until the interpreter's exit and flushed into a
    removed folder or a full disk then: an ERROR line, or a process that never exited."""
    import slam.pipeline
    from slam.viz.recorder import RunRecorder

    seen: list[bool] = []
    real_abort = RunRecorder.abort

    def abort(self) -> None:
        seen.append(self.path.parent.is_dir())  # the partial folder is still there
        real_abort(self)

    monkeypatch.setattr(RunRecorder, "abort", abort)
    good = tmp_path / "good"
    assert main(["run", str(small), "--out", str(good), "--max-scans", SCANS, "--quiet"]) == 0
    assert seen == [] and (good / "recording.rrd").is_file()

    def full(path, text):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(slam.pipeline, "write_text", full)
    out = tmp_path / "out"
    assert main(["run", str(small), "--out", str(out), "--max-scans", SCANS, "--quiet"]) == 2
    assert seen == [True]
    capsys.readouterr()
    assert not out.exists() and not list(tmp_path.glob(".out.*"))


def test_a_really_full_disk_is_one_line_without_rerun_errors(small, tmp_path):
    """Item 10 on a real 64 KiB tmpfs (fails on main: tracebacks plus coloured rerun ERROR
    lines). Needs root and ``mount``; skipped otherwise (the monkeypatched test above covers
    the same path)."""
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "64k"):
        pytest.skip("cannot mount a tmpfs here (needs root and mount)")
    try:
        done = subprocess.run(
            slam_cmd(
                "run", str(small), "--out", str(disk / "out"), "--max-scans", SCANS, "--quiet"
            ),
            env=cli_env(),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 2, done.stderr
        err = one_line(done.stderr)
        assert f"{disk / 'out'}: No space left on device" in err
        assert list(disk.iterdir()) == []
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_eval_on_a_folder_that_cannot_be_entered(tmp_path, monkeypatch, capsys):
    """Item 10 (fails on main: a PermissionError traceback). As root ``chmod`` does not stop
    us, so entering the folder is refused by a patched ``os.stat``."""
    locked = tmp_path / "locked"
    locked.mkdir()
    reference = tmp_path / "reference.tum"
    reference.write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    refuse_inside(monkeypatch, "stat", locked, PermissionError, errno.EACCES)
    assert main(["eval", str(locked), "--reference", str(reference)]) == 2
    err = one_line(capsys.readouterr().err)
    assert f"{locked}/" in err and "Permission denied" in err


def test_sigint_inside_numba_during_loop_closing_exits_130(small, tmp_path, monkeypatch, capsys):
    """Item 10 (fails on main: ``SystemError: CPUDispatcher(solve_system) returned a result with
    an exception set``, exit 1). A real signal whose handler raises ``KeyboardInterrupt`` (what
    Python's SIGINT handler does) arrives every millisecond while loop closing calls the numba
    kernel ``solve_system``, until numba's dispatcher wraps the interrupt into a SystemError."""
    import numpy as np

    import slam.backend.global_loops
    import slam.graph
    from slam.kernels.graph import solve_system

    n = 300
    system = (np.tile(np.eye(3), (n, 1, 1)) * 4, np.zeros((n - 1, 3, 3)), np.zeros((0, 3, 3)),
              np.zeros(0, np.int64), np.zeros(0, np.int64), np.ones((n, 3)), 50, 1e-8)  # fmt: skip
    solve_system(*system)
    armed = []

    def interrupt(signum, frame):
        if armed:
            raise KeyboardInterrupt

    def closing_loops(*args, **kwargs):
        previous = signal.signal(signal.SIGALRM, interrupt)
        armed.append(True)
        signal.setitimer(signal.ITIMER_REAL, 0.001, 0.001)
        try:
            while True:
                try:
                    solve_system(*system)
                except KeyboardInterrupt:
                    continue  # raised between calls: wait for one inside the dispatcher
        finally:
            armed.clear()
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)

    monkeypatch.setattr(slam.graph, "close_loops", closing_loops)
    # the default loop closing is the one with the global search ([backend])
    monkeypatch.setattr(slam.backend.global_loops, "close_loops_global", closing_loops)
    out = tmp_path / "out"
    assert main(["run", str(small), "--out", str(out), "--quiet"]) == 130
    assert one_line(capsys.readouterr().err) == "slam: interrupted\n"
    assert list(tmp_path.iterdir()) == []


GRID_WORLD = """description = "a 30x30 colour map (big posteriors: the JSON is ~0.5 MB)"
[world]
cyclic = false
[world.random]
rows = 30
cols = 30
colours = ["blue", "green", "red", "white"]
counts = [225, 225, 225, 225]
seed = 7
[sensor]
type = "colour"
p_correct = 0.999
[motion]
type = "unknown_heading"
[run]
steps = ["sense blue", "move any", "sense white", "move any", "sense red", "move any",
         "sense green", "move any", "sense blue", "move any", "sense white"]
"""


def test_a_closed_pipe_ends_quietly(tmp_path):
    """Item 10 (fails on main: a BrokenPipeError traceback and an "Exception ignored" message,
    exit 1). ``slam grid run X --json | head -c 100``: the reader closes after 100 bytes of a
    JSON larger than the pipe's buffer; slam exits 141 (128 + SIGPIPE) with nothing on stderr."""
    scenario = tmp_path / "big.toml"
    scenario.write_text(GRID_WORLD)
    process = subprocess.Popen(
        slam_cmd("grid", "run", str(scenario), "--json"),
        env=cli_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert len(process.stdout.read(100)) == 100
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=60) == 141, err
    assert err == ""


def test_environment_errors_are_one_line_but_bugs_keep_their_traceback(
    small, tmp_path, monkeypatch
):
    """The CLI's top level turns only environment errors into one line: an OSError of another
    kind (or without a path) and any other exception still raise."""
    from slam.online import Slam

    def bug(*args, **kwargs):
        raise OSError(errno.EINVAL, "Invalid argument")

    monkeypatch.setattr(Slam, "finish", bug)
    with pytest.raises(OSError, match="Invalid argument"):
        main(["run", str(small), "--out", str(tmp_path / "o"), "--quiet"])
    monkeypatch.setattr(Slam, "finish", lambda *a, **k: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        main(["run", str(small), "--out", str(tmp_path / "o"), "--quiet"])
    assert list(tmp_path.iterdir()) == []


# --- item 11: viewer, web port, child processes, --set --------------------------------------


def test_viewer_without_display_keeps_its_word(small, tmp_path, monkeypatch, capsys):
    """Item 11 (fails on main: it said "the run still writes recording.rrd", then exited 2 with
    nothing written). A viewer that cannot start is one warning; the run goes on and writes its
    recording."""
    broken = tmp_path / "no-display-rerun"
    broken.write_text("#!/bin/sh\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setenv("RERUN_CLI_PATH", str(broken))
    out = tmp_path / "run"
    make_run(small, out, "--viewer")
    err = capsys.readouterr().err
    assert "the rerun viewer did not start listening" in err
    assert "the run goes on and writes recording.rrd" in err
    assert (out / "recording.rrd").stat().st_size > 1000


@pytest.fixture()
def recording(tmp_path) -> Path:
    """A run-like folder with a small recording."""
    import numpy as np
    import rerun as rr

    from slam.viz.stream import close_stream, open_stream

    folder = tmp_path / "rec"
    folder.mkdir()
    rec = open_stream(folder / "recording.rrd", name="t")
    rec.set_time("scan", sequence=0)
    rec.log("x", rr.Points2D(np.zeros((3, 2))))
    close_stream(rec)
    return folder


def test_view_web_on_a_taken_port_is_one_line(recording, capsys):
    """Item 11 (fails on main: it printed the URL of the port's other owner, then died)."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["view", str(recording), "--web", "--port", str(port)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"--port {port}: 127.0.0.1:{port} is not free" in one_line(captured.err)


def _children(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(c) for c in path.read_text().split()] if path.is_file() else []


def test_the_web_viewer_dies_with_a_killed_slam_view(recording):
    """Item 11 (fails on main: after SIGKILL of ``slam view --web`` its rerun child kept serving).
    The child gets PR_SET_PDEATHSIG: SIGKILL the parent, the child goes too."""
    if not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").is_file():
        pytest.skip("needs Linux /proc/<pid>/task/<pid>/children")
    from slam.viz.stream import free_port

    port = free_port()
    process = subprocess.Popen(
        slam_cmd("view", str(recording), "--web", "--port", str(port)),
        env=cli_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert process.stdout.readline().startswith(f"web viewer: http://127.0.0.1:{port}/")
        (child,) = _children(process.pid)
    finally:
        process.kill()
        process.wait(timeout=20)
    deadline = time.monotonic() + 10
    while Path(f"/proc/{child}").exists() and time.monotonic() < deadline:
        state = (
            Path(f"/proc/{child}/stat").read_text().split()[2]
            if Path(f"/proc/{child}/stat").exists()
            else "X"
        )
        if state == "Z":
            break  # dead, waiting to be reaped by init
        time.sleep(0.1)
    alive = (
        Path(f"/proc/{child}/stat").exists()
        and Path(f"/proc/{child}/stat").read_text().split()[2] != "Z"
    )
    if alive:
        os.kill(child, signal.SIGKILL)
    assert not alive, "the rerun web viewer outlived slam view"


def test_set_keeps_a_toml_literal_string_with_quotes():
    """Item 11 (fails on main: every ``'`` became ``"``, so ``'say "hi"'`` turned into the bare
    string ``"say "hi""``). Only the shortcut flags are quoted by slam."""
    import argparse

    from slam.commands.run import overrides_from
    from slam.config import parse_override

    args = argparse.Namespace(set=["""texture.mode='say "hi"'"""], method="odometry", seed=None)
    overrides = overrides_from(args)
    assert [parse_override(o) for o in overrides] == [
        ("texture", "mode", 'say "hi"'),
        ("filter", "method", "odometry"),
    ]


# --- item 12: the umask is honoured ---------------------------------------------------------


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_run_folders_honour_the_umask(small, tmp_path, umask):
    """Item 12 (fails on main: folders 0700 and files 0600 whatever the umask). Folders get
    ``0o777 & ~umask``, files ``0o666 & ~umask``."""
    previous = os.umask(umask)
    try:
        run = make_run(small, tmp_path / "run")
        assert main(["sim", "small", "--out", str(tmp_path / "sim"), "--duration", "1",
                     "--no-rgbd", "--quiet"]) == 0  # fmt: skip
    finally:
        os.umask(previous)
    for folder in (run, tmp_path / "sim"):
        assert stat.S_IMODE(folder.stat().st_mode) == 0o777 & ~umask
        files = [p for p in folder.iterdir() if p.is_file()]
        assert len(files) >= 4
        for path in files:
            assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path.name


def test_file_outputs_never_overwrite_their_input_or_a_folder(data_dir, tmp_path, capsys):
    """Item 1 for file outputs (fails on main: ``maze convert M M`` rewrote the maze it read, in
    the other format; ``--record`` naming a folder was a traceback)."""
    maze = tmp_path / "maze.txt"
    shutil.copy(data_dir / "maze" / "udacity" / "test_maze_01.txt", maze)
    before = maze.read_bytes()
    assert main(["maze", "convert", str(maze), str(maze)]) == 2
    assert "OUT is the maze being converted" in one_line(capsys.readouterr().err)
    assert maze.read_bytes() == before
    folder = tmp_path / "rec.rrd"
    folder.mkdir()
    assert main(["grid", "run", "tutorial-1d", "--record", str(folder)]) == 2
    assert "expected a file name, found a folder" in one_line(capsys.readouterr().err)
    assert folder.is_dir() and list(folder.iterdir()) == []


def test_a_signal_while_the_partial_folder_is_made_leaves_nothing(tmp_path, monkeypatch, request):
    """SIGTERM/Ctrl-C can land between the partial folder's ``mkdir`` and its owner record (seen
    once in the SIGTERM test above: a ``.X.<rand>.partial`` holding an empty ``.slam-partial``,
    which no later run may delete): the folder and the record go together."""
    import slam.io.atomic as atomic
    import slam.io.runfolder as runfolder

    def cut_short(folder, target):
        (Path(folder) / runfolder.OWNER_FILE).write_bytes(b"")  # created, not yet written
        raise KeyboardInterrupt

    monkeypatch.setattr(runfolder, "write_owner", cut_short)
    with pytest.raises(KeyboardInterrupt):
        runfolder.make_partial(tmp_path, "a")
    assert list(tmp_path.iterdir()) == []

    monkeypatch.undo()
    made = []

    def interrupted(parent, target):  # Ctrl-C arrives right after the folder is complete
        made.append(real(parent, target))
        os.kill(os.getpid(), signal.SIGINT)
        return made[-1]

    real = atomic.make_partial
    monkeypatch.setattr(atomic, "make_partial", interrupted)
    # Python's own handler, as in a terminal (a suite started as a background job of a shell
    # without job control inherits SIGINT ignored: cli_process.sigint_as_a_terminal_gives_it)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    request.addfinalizer(lambda: signal.signal(signal.SIGINT, previous))
    with pytest.raises(KeyboardInterrupt), atomic.atomic_dir(tmp_path / "runs" / "b"):
        raise AssertionError("the block must not start: the interrupt comes first")
    assert made and not made[0].exists()
    assert list((tmp_path / "runs").iterdir()) == []

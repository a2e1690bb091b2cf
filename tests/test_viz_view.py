"""``slam view`` and ``slam run --viewer``: viewers and servers listen on 127.0.0.1 only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from tool_modules import load_tool

from slam.cli import main
from slam.viz import blueprint as bp
from slam.viz.stream import free_port, rerun_executable, summarize, wait_for_port


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A run folder holding the golden scripted recording."""
    tool = load_tool("make_viz_reference")
    folder = tmp_path_factory.mktemp("run")
    tool.write_reference(folder / "recording.rrd")
    return folder


def listeners(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp*) of the sockets listening on ``port``."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not Path(table).is_file():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            address, hex_port = fields[1].rsplit(":", 1)
            if fields[3] == "0A" and int(hex_port, 16) == port:
                found.add(address)
    return found


LOOPBACK_HEX = "0100007F"


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time process ``pid`` has used so far (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_view_errors_are_one_line(tmp_path, capsys):
    assert main(["view", str(tmp_path / "nowhere")]) == 2
    assert "no such run folder or recording" in capsys.readouterr().err
    assert main(["view", str(tmp_path)]) == 2
    assert "no recording.rrd in this folder" in capsys.readouterr().err
    other = tmp_path / "notes.txt"
    other.write_text("x")
    assert main(["view", str(other)]) == 2
    assert "expected a run folder or a .rrd file" in capsys.readouterr().err
    assert main(["view", str(tmp_path), "--web", "--port", "70000"]) == 2
    capsys.readouterr()
    # not a recording: refused before a viewer serves it empty (the bug: exit 0, an empty viewer)
    fake = tmp_path / "fake.rrd"
    for content, found in ((b"", "an empty file"), (b'{"wall_s": 1}', "a file starting b'{\"wa'")):
        fake.write_bytes(content)
        assert main(["view", str(fake), "--web"]) == 2
        assert capsys.readouterr().err == (
            f"slam: error: {fake}: expected a rerun recording (starting b'RRF2'), found {found}\n"
        )


def test_view_without_a_display_points_at_web(recording, monkeypatch, capsys):
    """The bug: without a display the native viewer printed rerun's log lines and a winit
    error, exit 1."""
    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(recording)]) == 2
    assert capsys.readouterr().err == (
        f"slam: error: {recording}: no display for the native viewer (neither DISPLAY nor "
        "WAYLAND_DISPLAY is set): serve it to a browser with --web\n"
    )


@pytest.mark.skipif(not Path("/proc/net/tcp").is_file(), reason="needs Linux /proc/net/tcp")
def test_view_web_serves_on_loopback_and_prints_the_url(recording):
    port = free_port()
    env = dict(os.environ, RERUN_ANALYTICS="0")
    process = subprocess.Popen(
        [sys.executable, "-m", "slam", "view", str(recording), "--web", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = process.stdout.readline()
        assert line.startswith(
            f"web viewer: http://127.0.0.1:{port}/?url=http%3A%2F%2F127.0.0.1%3A"
        )
        assert line.rstrip().endswith("%2Frecording.rrd"), line
        file_port = int(line.split("%3A")[-1].split("%2F")[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as response:
            assert response.status == 200
            assert b"<html" in response.read().lower()
        # the page fetches the recording from slam view itself, the viewer's origin allowed
        url = f"http://127.0.0.1:{file_port}/recording.rrd"
        origin = f"http://localhost:{port}"
        request = urllib.request.Request(url, headers={"Origin": origin})
        with urllib.request.urlopen(request, timeout=10) as response:
            assert response.read() == (recording / "recording.rrd").read_bytes()
            assert response.headers["Access-Control-Allow-Origin"] == origin
        request = urllib.request.Request(url, headers={"Origin": "http://example.com"})
        with urllib.request.urlopen(request, timeout=10) as response:
            assert "Access-Control-Allow-Origin" not in response.headers  # no other site's
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(f"http://127.0.0.1:{file_port}/config.toml", timeout=10)
        rebound = urllib.request.Request(url, headers={"Host": f"attacker.example:{file_port}"})
        with pytest.raises(urllib.error.HTTPError, match="403"):  # (review) DNS rebinding
            urllib.request.urlopen(rebound, timeout=10)
        assert listeners(port) == {LOOPBACK_HEX}
        assert listeners(file_port) == {LOOPBACK_HEX}
        # and the viewer idles: no gRPC server whose loop spins (it took a whole core, ~2 s)
        (child,) = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
        before = _cpu_seconds(int(child))
        time.sleep(2.0)
        assert _cpu_seconds(int(child)) - before < 0.5
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=20)
    # the server went with it
    deadline = time.monotonic() + 10
    while listeners(port) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not listeners(port)


def _stand_in_viewer(tmp_path: Path) -> Path:
    """An executable that runs rerun with the given arguments plus ``--save live.rrd``."""
    (real,) = rerun_executable()
    script = tmp_path / "fake-rerun"
    script.write_text(
        "#!/bin/sh\n"
        f'echo "$@" > "{tmp_path}/args.txt"\n'
        f'echo $$ > "{tmp_path}/pid.txt"\n'
        f'exec "{real}" "$@" --save "{tmp_path}/live.rrd"\n'
    )
    script.chmod(0o755)
    return script


def _stop(pid: int) -> None:
    """End process ``pid``: SIGINT, then SIGTERM, then SIGKILL, each given a few seconds."""
    for sig, wait_s in ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            try:
                if os.waitpid(pid, os.WNOHANG)[0] == pid:
                    return
            except ChildProcessError:  # not our child: poll for its end
                try:
                    os.kill(pid, 0)
                except ProcessLookupError:
                    return
            time.sleep(0.1)


def test_run_viewer_streams_live_to_a_viewer_on_loopback(tmp_path, monkeypatch):
    """``--viewer`` spawns the viewer bound to 127.0.0.1 and streams to it while the run writes
    its own recording. The viewer is a stand-in: the real rerun binary with ``--save`` (a gRPC
    server writing what it receives, no window)."""
    log = tmp_path / "small"
    assert main(["sim", "small", "--out", str(log), "--duration", "4", "--no-rgbd", "--quiet"]) == 0
    monkeypatch.setenv("RERUN_CLI_PATH", str(_stand_in_viewer(tmp_path)))
    out = tmp_path / "run"
    code = main(
        ["run", str(log), "--out", str(out), "--particles", "4", "--max-scans", "40",
         "--viewer", "--quiet"]
    )  # fmt: skip
    assert code == 0
    args = (tmp_path / "args.txt").read_text().split()
    assert args[args.index("--bind") + 1] == "127.0.0.1"
    port = int(args[args.index("--port") + 1])
    assert listeners(port) == {LOOPBACK_HEX}
    # the viewer outlives the run: stop our stand-in, whatever it takes (rerun --save may
    # keep serving after SIGINT, and a test leaves no process behind)
    _stop(int((tmp_path / "pid.txt").read_text()))
    assert not listeners(port)
    live = summarize(tmp_path / "live.rrd")
    saved = summarize(out / "recording.rrd")
    for entity in (bp.TRAJECTORY, bp.N_EFF, bp.PARTICLES):
        assert live[f"/{entity}"].rows == saved[f"/{entity}"].rows, entity
    assert live[f"/{bp.TRAJECTORY}"].rows == 40


def test_a_viewer_that_never_listens_is_a_usage_error(tmp_path, monkeypatch):
    from slam.errors import UsageError
    from slam.viz.stream import spawn_viewer

    script = tmp_path / "broken-rerun"
    script.write_text("#!/bin/sh\nexit 3\n")
    script.chmod(0o755)
    monkeypatch.setenv("RERUN_CLI_PATH", str(script))
    with pytest.raises(UsageError, match="did not start listening on 127.0.0.1"):
        spawn_viewer(timeout_s=5)
    assert wait_for_port(free_port(), 0.3) is False


def test_screenshot_command_binds_loopback_and_keeps_the_pointer_off_the_window(tmp_path):
    from slam.viz.screenshot import main as screenshot_main
    from slam.viz.screenshot import screenshot_command

    cmd = screenshot_command(tmp_path / "r.rrd", tmp_path / "out.png", 800, 450)
    assert cmd[:4] == ["xvfb-run", "-a", "-s", "-screen 0 1600x900x24"]
    script = cmd[-1]
    assert "--bind 127.0.0.1" in script and "--window-size 800x450" in script
    assert "--screenshot-to" in script and "xdotool mousemove 1596 896" in script
    assert screenshot_main([str(tmp_path / "missing"), str(tmp_path / "o.png")]) == 2

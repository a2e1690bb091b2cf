"""``slam view RUN_DIR``: open a run's recording in the rerun viewer.

Open RUN_DIR/recording.rrd (or a .rrd file) in the rerun viewer: the native viewer, or with --web
the web viewer served on 127.0.0.1 (its URL is printed; Ctrl-C stops it), which fetches the
recording from :class:`slam.viz.webserve.RecordingServer` (rerun's own gRPC server would keep a
core busy while it idles). Every server started listens on 127.0.0.1 only (rerun's own default
is every interface). A port already taken is one
line and exit 2 before anything starts. The viewer process dies with
``slam view`` (Linux: ``PR_SET_PDEATHSIG``), even when ``slam view`` is killed with SIGKILL.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from slam.errors import DataError, UsageError

if TYPE_CHECKING:
    from slam.viz.webserve import RecordingServer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam view``."""
    parser.add_argument(
        "run_dir", metavar="RUN_DIR", type=Path, help="run folder (or a .rrd recording)"
    )
    parser.add_argument(
        "--web", action="store_true", help="serve the web viewer on 127.0.0.1 and print its URL"
    )
    parser.add_argument(
        "--port",
        type=int,
        help="with --web: HTTP port of the web viewer (default 9090); otherwise the native "
        "viewer's gRPC port (default: a free one)",
    )
    parser.set_defaults(func=view_command)


def find_recording(path: Path) -> Path:
    """``path/recording.rrd`` for a run folder, ``path`` itself for a ``.rrd`` file."""
    from slam.viz.recorder import RECORDING_NAME

    if path.is_dir():
        rrd = path / RECORDING_NAME
        if not rrd.is_file():
            raise DataError(
                f"{path}: no {RECORDING_NAME} in this folder (runs record unless --no-record; "
                "'slam grid run --record FILE' and 'slam maze run --record FILE' write elsewhere)"
            )
        return _checked_rrd(rrd)
    if path.is_file():
        if path.suffix != ".rrd":
            raise UsageError(f"{path}: expected a run folder or a .rrd file")
        return _checked_rrd(path)
    raise DataError(f"{path}: no such run folder or recording")


RRD_MAGIC = b"RRF2"
"""The first bytes of a rerun recording file."""


def _checked_rrd(path: Path) -> Path:
    """``path`` when it starts as a rerun recording does; else one :class:`DataError` (the
    viewer would serve an empty recording and say so only in its own log)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(RRD_MAGIC))
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head != RRD_MAGIC:
        found = "an empty file" if not head else f"a file starting {head!r}"
        raise DataError(
            f"{path}: expected a rerun recording (starting {RRD_MAGIC!r}), found {found}"
        )
    return path


def _check_port(port: int | None) -> None:
    if port is not None and not 1 <= port <= 65535:
        raise UsageError(f"--port {port}: expected 1..65535")


def view_command(args: argparse.Namespace) -> int:
    """Start the viewer on the recording; with ``--web`` print the URL and serve until stopped."""
    from slam.viz.stream import (
        check_port_free,
        die_with_parent,
        free_port,
        viewer_command,
        viewer_env,
    )

    rrd = find_recording(args.run_dir)
    _check_port(args.port)
    if args.port is not None or args.web:
        check_port_free(args.port or 9090, "--port")
    if not args.web:
        if sys.platform.startswith("linux") and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        ):
            raise UsageError(
                f"{args.run_dir}: no display for the native viewer (neither DISPLAY nor "
                "WAYLAND_DISPLAY is set): serve it to a browser with --web"
            )
        cmd = viewer_command(rrd, port=args.port or free_port())
        return subprocess.run(
            cmd, env=viewer_env(), check=False, preexec_fn=die_with_parent()
        ).returncode
    from slam.viz.webserve import RecordingServer

    web_port = args.port or 9090
    with RecordingServer(rrd, viewer_port=web_port) as server:
        return _serve_web(viewer_command(server.url, web=True, web_port=web_port), web_port, server)


def _serve_web(cmd: list[str], web_port: int, server: RecordingServer) -> int:
    """Run the web viewer ``cmd`` on ``web_port``, print its URL and wait until it ends or we are
    stopped (Ctrl-C, SIGTERM); the viewer process goes with us."""
    from slam.viz.stream import die_with_parent, viewer_env, wait_for_port, web_url

    process = subprocess.Popen(
        cmd, env=viewer_env(), stdout=subprocess.DEVNULL, preexec_fn=die_with_parent()
    )

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(0)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        if not wait_for_port(web_port, 30.0, process):
            raise UsageError(
                f"--web: the web viewer did not start on 127.0.0.1:{web_port} (is the port "
                "taken? choose another with --port)"
            )
        print(f"web viewer: {web_url(web_port, server.url)}", flush=True)
        print("serving on 127.0.0.1 only; press Ctrl-C to stop", file=sys.stderr, flush=True)
        return process.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        signal.signal(signal.SIGTERM, previous)
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()

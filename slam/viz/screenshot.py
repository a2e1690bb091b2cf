"""A headless screenshot of the rerun viewer on a recording (for the README).

``uv run python -m slam.viz.screenshot RECORDING_OR_RUN_DIR OUT.png [--size 1600x900]`` runs the
native viewer of rerun-sdk under a virtual X display (``xvfb-run``) with Mesa's software Vulkan
driver (llvmpipe), lets it load the recording and save a screenshot (``--screenshot-to``), then
quits. The viewer listens on 127.0.0.1 only. Needs Debian's ``xvfb``, ``mesa-vulkan-drivers``
and ``xdotool`` (a one-off tool, not a project dependency): see ``docs/viz.md``.

The pointer is kept outside the window so that no hover tooltip covers the views.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

from slam.errors import SlamError, UsageError
from slam.viz.stream import LOOPBACK, rerun_executable, viewer_env


def screenshot_command(recording: Path, out: Path, width: int, height: int) -> list[str]:
    """The ``xvfb-run`` command line that renders ``recording`` into ``out``."""
    (rerun,) = rerun_executable()
    # a screen twice the window's size: the pointer starts at the screen's centre, which is
    # then the window's bottom-right corner (no hover tooltip over the views)
    screen = f"-screen 0 {2 * width}x{2 * height}x24"
    viewer = (
        f'"{rerun}" --bind {LOOPBACK} --port 0 --renderer vulkan '
        f'--window-size {width}x{height} --screenshot-to "{out}" "{recording}"'
    )
    park = f"sleep 3; xdotool mousemove {2 * width - 4} {2 * height - 4} || true"
    script = f"{viewer} & viewer=$!; {park}; wait $viewer"
    return ["xvfb-run", "-a", "-s", screen, "bash", "-c", script]


def take_screenshot(
    recording: Path, out: Path, width: int = 1600, height: int = 900, timeout_s: float = 300
) -> Path:
    """Render the viewer on ``recording`` (a ``.rrd`` file) into the PNG ``out``."""
    for tool in ("xvfb-run", "xdotool"):
        if shutil.which(tool) is None:
            raise UsageError(
                f"{tool} not found: apt-get install xvfb xdotool mesa-vulkan-drivers "
                "(see docs/viz.md)"
            )
    out = Path(out).resolve()
    out.unlink(missing_ok=True)
    cmd = screenshot_command(Path(recording).resolve(), out, width, height)
    result = subprocess.run(
        cmd, env=viewer_env(), capture_output=True, text=True, timeout=timeout_s
    )
    if result.returncode != 0 or not out.is_file():
        tail = (result.stderr or result.stdout).strip().splitlines()[-3:]
        raise SlamError(f"{out}: the viewer wrote no screenshot ({' | '.join(tail)})")
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: ``python -m slam.viz.screenshot RECORDING OUT.png [--size WxH]``."""
    from slam.commands.view import find_recording

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", type=Path, help="run folder or .rrd file")
    parser.add_argument("out", type=Path, help="PNG to write")
    parser.add_argument("--size", default="1600x900", help="window size in points (WxH)")
    args = parser.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
        out = take_screenshot(find_recording(args.recording), args.out, width, height)
    except ValueError:
        print(f"slam: --size {args.size!r}: expected WIDTHxHEIGHT", file=sys.stderr)
        return 2
    except SlamError as exc:
        print(f"slam: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

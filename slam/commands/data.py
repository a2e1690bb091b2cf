"""``slam data``: which datasets are under the data directory, and are they sound.

List and verify the datasets of the registry (data/datasets.toml) under the data directory
(--data-dir, else $SLAM_DATA_DIR, else ./data); inspect what a log holds; calibrate a log's
odometry and laser mount from its data.

* ``slam data list [--data-dir D] [--json]``: every registry dataset as present, partial (with
  the missing files) or absent.
* ``slam data verify NAME [--data-dir D] [--json]``: sizes and hashes of the files present, then
  the loader's checks (keys, shapes, dtypes, timestamps, rates) and a summary per stream (counts,
  duration, rates, gaps, invalid beams, non-monotonic scans). Exit code 2 when a present file is
  wrong or nothing of the dataset is there; a partial dataset whose present files are sound
  exits 0 and lists what is missing.
* ``slam data inspect FILE [--json]``: what a ROS bag / MCAP file / ROS 2 bag folder, CARMEN log
  or ECE276A folder holds (topics, message types, counts, rates, time span, tf frames, or the
  loader's stream summary) and the ``slam run`` command that would use it.
* ``slam data calibrate LOG [--config F] [--set K=V] [--json]``: which odometry of the log agrees
  with its laser and where the laser sits on the robot, measured from the data
  (:mod:`slam.calibration`), beside what the log states.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slam.commands._common import (
    add_actions,
    add_bag_arguments,
    add_command,
    add_config_arguments,
    add_data_dir_argument,
    add_log_argument,
    bag_options_from,
    data_dir_from,
)
from slam.io.datadir import DATA_DIR_ENV

if TYPE_CHECKING:
    from slam.calibration import Disagreement
    from slam.config import RbpfConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the sub-commands of ``slam data`` and their arguments."""
    actions = add_actions(parser, "data_command", "ACTION")

    listing = add_command(
        actions, "list", __doc__, "show each dataset as present, partial or absent", layout=True
    )
    add_data_dir_argument(listing)
    listing.add_argument("--json", action="store_true", help="print JSON instead of a table")
    listing.set_defaults(func=run_list)

    verify = actions.add_parser(
        "verify",
        help="check a dataset's files and print its summary",
        description="Check sizes and hashes, keys, shapes, dtypes, timestamps and rates of a "
        "dataset's files and print counts, durations, rates and gaps per stream.",
    )
    verify.add_argument("name", help="dataset name (see `slam data list`)")
    add_data_dir_argument(verify)
    verify.add_argument("--json", action="store_true", help="print the report as JSON")
    verify.set_defaults(func=run_verify)

    inspect = actions.add_parser(
        "inspect",
        help="show what a bag, MCAP file, CARMEN log or ECE276A folder holds",
        description="Show what a log file or folder holds (format detected by content): topics, "
        "message types, counts, rates, time span and tf frames of a bag; streams of other logs; "
        "and the `slam run` command that would use it.",
    )
    inspect.add_argument("path", type=Path, metavar="FILE", help="log file or folder")
    inspect.add_argument("--json", action="store_true", help="print the report as JSON")
    add_bag_arguments(inspect)
    inspect.set_defaults(func=run_inspect)

    calibrate = actions.add_parser(
        "calibrate",
        help="measure the odometry's timing and the laser's mount from a log's own data",
        description="Measure, from the log's scans and odometry and without ground truth, which "
        "of its odometries (the poses written with the scans, the odometry messages at a lag) "
        'agrees with the laser (what `slam run` uses with robot.odometry_sync = "auto") and '
        "where the laser sits on the robot (a hand-eye fit over the turns), beside what the log "
        "states (docs/accuracy.md).",
    )
    add_log_argument(calibrate, "LOG")
    add_data_dir_argument(calibrate)
    add_config_arguments(calibrate)
    add_bag_arguments(calibrate)
    calibrate.add_argument("--json", action="store_true", help="print the report as JSON")
    calibrate.set_defaults(func=run_calibrate)


def _data_dir_origin(args: argparse.Namespace) -> str:
    if getattr(args, "data_dir", None):
        return "--data-dir"
    if os.environ.get(DATA_DIR_ENV):
        return f"${DATA_DIR_ENV}"
    return "default"


def _short(path: str, folder: str) -> str:
    prefix = folder.rstrip("/") + "/"
    return path[len(prefix) :] if path.startswith(prefix) else path


def run_list(args: argparse.Namespace) -> int:
    """``slam data list``."""
    from slam.io.registry import check_readable_dir, dataset_status, load_registry

    data_dir = data_dir_from(args)
    exists = check_readable_dir(data_dir, "data directory")
    statuses = [dataset_status(d, data_dir) for d in load_registry().values()]
    if args.json:
        report = {
            "data_dir": str(data_dir),
            "data_dir_exists": exists,
            "datasets": [s.as_dict() for s in statuses],
        }
        print(json.dumps(report, indent=2))
        return 0

    out = sys.stdout
    print(f"data directory: {data_dir} ({_data_dir_origin(args)})", file=out)
    if not exists:
        print(
            f"  (does not exist: every dataset is absent; pass --data-dir or set "
            f"{DATA_DIR_ENV}, see docs/data.md)",
            file=out,
        )
    rows = [("NAME", "LOADER", "STATUS", "MISSING")]
    for s in statuses:
        if s.state == "absent":
            missing = "everything"
        else:
            missing = ", ".join(_short(p, s.dataset.folder) for p in s.missing) or "-"
        rows.append((s.dataset.name, s.dataset.loader, s.state, missing))
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    for row in rows:
        head = "  ".join(cell.ljust(widths[i]) for i, cell in enumerate(row[:3]))
        print(f"{head}  {row[3]}", file=out)
    counts = {state: sum(s.state == state for s in statuses) for state in ("present", "partial")}
    absent = len(statuses) - counts["present"] - counts["partial"]
    print(
        f"\n{counts['present']} present, {counts['partial']} partial, {absent} absent. "
        f"Missing paths are relative to each dataset's folder; `slam data verify NAME` checks "
        f"a dataset, docs/data.md says where files go.",
        file=out,
    )
    return 0


def _fmt_stream(name: str, info: dict[str, Any]) -> str:
    count = info.get("count", 0)
    if not count:
        return f"  {name:<10} 0 readings"
    text = (
        f"  {name:<10} {count:>6} readings  {info['duration_s']:8.2f} s  "
        f"{info['rate_hz']:7.2f} Hz  median dt {info['median_dt_s'] * 1000:6.2f} ms  "
        f"max gap {info['max_gap_s']:.3f} s"
    )
    if info.get("backward_steps") and "non_monotonic" not in info:  # scans: said below
        text += f", {info['backward_steps']} steps backwards"
    extras = []
    if "beams" in info:
        from slam.io.log import beams_text

        extras.append(beams_text(info))
        extras.append(f"invalid beams {info['invalid_beams']}")
        extras.append(f"no-return beams {info['no_return_beams']}")
        extras.append(f"non-monotonic {info['non_monotonic']}")
    return text + (f"\n  {'':<10} " + ", ".join(extras) if extras else "")


def run_verify(args: argparse.Namespace) -> int:
    """``slam data verify NAME``."""
    from slam.errors import DataError
    from slam.io.registry import verify_dataset

    data_dir = data_dir_from(args)
    _refuse_a_path(args.name)
    report = verify_dataset(args.name, data_dir)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_verify(report, data_dir)
    if report["problems"]:
        raise DataError(
            f"{args.name}: {len(report['problems'])} problem(s) found: "
            + "; ".join(report["problems"])
        )
    return 0


def _refuse_a_path(name: str) -> None:
    """A file or folder given to ``slam data verify``, which takes a registry name: say which
    command reads a path (the mirror of ``slam data inspect`` given a name)."""
    from slam.errors import UsageError
    from slam.io.registry import load_registry

    path = Path(name)
    if name not in load_registry() and (path.exists() or path.is_symlink()):
        raise UsageError(
            f"slam data verify: {name!r} is a path, not a registry dataset: "
            f"`slam data inspect {shlex.quote(name)}` summarises a log file, `slam data list` "
            "names the datasets verify checks"
        )


def _print_verify(report: dict[str, Any], data_dir: Path) -> None:
    out = sys.stdout
    print(f"{report['name']} ({report['loader']}) in {data_dir}: {report['status']}", file=out)
    print("files:", file=out)
    for f in report["files"]:
        if "entries" in f:
            detail = f"{f['entries']} files"
        else:
            detail = f"{f['size']} bytes"
            if f.get("sha256") == "ok":
                detail += ", sha256 ok"
        state = "ok" if f["status"] == "ok" else "BAD"
        print(f"  {state:<8} {f['path']}  ({detail})", file=out)
        for problem in f["problems"]:
            print(f"  {'':<8} {problem}", file=out)
    for path in report["missing"]:
        print(f"  {'missing':<8} {path}", file=out)
    summary = report["summary"]
    streams = [k for k, v in summary.items() if isinstance(v, dict)]
    if streams:
        print("streams:", file=out)
        for name in streams:
            print(_fmt_stream(name, summary[name]), file=out)
        notes = {
            k: v
            for k, v in summary.items()
            if not isinstance(v, dict) and k not in ("name", "kind")
        }
        if notes:
            print("notes:", file=out)
            for key, value in notes.items():
                print(f"  {key}: {value}", file=out)
    for warning in report.get("warnings", []):
        print(f"warning: {warning}", file=out)
    if report["problems"]:
        print(f"result: {len(report['problems'])} problem(s)", file=out)
    elif report["missing"]:
        print(
            f"result: the files present check out; {len(report['missing'])} missing "
            f"(see docs/data.md for where to put them)",
            file=out,
        )
    else:
        print("result: all files present and sound", file=out)


def run_inspect(args: argparse.Namespace) -> int:
    """``slam data inspect FILE``."""
    from slam.errors import UsageError
    from slam.io.inspect import format_inspection, inspect_path
    from slam.io.registry import load_registry

    name = str(args.path)
    if not args.path.exists() and not args.path.is_symlink() and name in load_registry():
        raise UsageError(
            f"slam data inspect: {name!r} is a registry dataset, not a path: "
            f"`slam data verify {name}` summarises it, or give its file"
        )
    report = inspect_path(args.path, bag_options_from(args))
    print(json.dumps(report, indent=2) if args.json else format_inspection(report), end="")
    return 0


def run_calibrate(args: argparse.Namespace) -> int:
    """``slam data calibrate``: the odometry synchronisation and the mount estimate."""
    from slam.calibration import calibrate_mount, measure_beam_step
    from slam.commands.run import overrides_from
    from slam.config import load_config
    from slam.io.plausibility import check_plausibility
    from slam.io.sources import resolve
    from slam.pipeline import load_source
    from slam.scans import LogScans

    data_dir = data_dir_from(args)
    ref = resolve(args.name, data_dir, where="slam data calibrate LOG")
    name = ref.config_name if ref.shipped_config else ""
    config = load_config(name, args.config, overrides_from(args))
    source = load_source(args.name, data_dir, config, bag=bag_options_from(args))
    config = source.configured(config)  # the beam step measured when it loaded, if applied
    log = source.log
    doubts = check_plausibility(log, config)  # what `slam run` refuses, refused here too
    with warnings.catch_warnings(record=True) as caught:  # said as `slam run` says them
        warnings.simplefilter("always")
        scans = LogScans.from_log(log, config)
    for message in sorted({*doubts, *(str(w.message) for w in caught)}):
        print(f"slam: warning: {message}", file=sys.stderr, flush=True)
    sync = scans.odometry_sync
    laser = scans.odometry_source == "laser"
    mount = None
    if not laser:  # laser odometry turns with the laser: no mount to measure against it
        try:
            mount = calibrate_mount(scans, config)
        except ValueError as exc:
            from slam.errors import DataError

            raise DataError(f"{log.source or args.name}: the laser's mount: {exc}") from exc
    from slam.calibration import noise_multiple, noise_picks, odometry_disagreement

    steps = odometry_disagreement(lambda k: scans.scan(k).hits(), scans.odometry, config)
    picks = scans.indices[noise_picks(len(scans))]  # the scans a run's smoothing reads
    reference = config.rbpf.smooth_noise_ref
    ranges = log.scans.ranges[picks]  # type: ignore[union-attr]
    multiple, noise, triples = noise_multiple(ranges, reference)
    stated = [float(v) for v in log.scans.laser_offset]  # type: ignore[union-attr]
    beams = source.beam_geometry  # measured as the log loaded (what a run does) ...
    if beams is None:  # ... or not (a declared step, the measurement off): the same measurement
        check = measure_beam_step(log, config)
        beams = None if check is None else {**check.as_dict(), "applied": False}
        declarable = check is not None and check.declares_step
    else:
        declarable = bool(beams["applied"])
    report = {
        "log": str(log.source or args.name),
        "scans": len(scans),
        "odometry_source": scans.odometry_source,
        "odometry_sync": None if sync is None else sync.as_dict(),
        "mount": None if mount is None else mount.as_dict(),
        "stated_mount": {"x": stated[0], "y": stated[1], "yaw_deg": math.degrees(stated[2])},
        "beam_geometry": beams,
        "range_noise": {
            "noise_m": None if not math.isfinite(noise) else round(noise, 4),
            "triples": triples,
            "reference_m": reference,
            "multiple": round(multiple, 4),
        },
        "odometry_steps": _steps_report(steps, config.rbpf),
        "beam_step_deg": config.lidar.beam_step_deg,
        "beam_step_measured": source.beam_step_deg is not None,
        "beam_step_declarable": declarable,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    for line in _calibration_lines(report, config.robot.odometry_sync):
        print(line)
    return 0


def _calibration_lines(report: dict[str, Any], mode: str) -> list[str]:
    """The text form of a ``slam data calibrate`` report."""
    lines = [f"{report['log']}: {report['scans']} scans"]
    sync = report["odometry_sync"]
    if report["odometry_source"] == "laser":
        lines.append(
            "odometry  none of the log's: laser odometry (scan matching) stands in "
            '(robot.odometry; docs/slam.md, "A robot without odometry")'
        )
    elif sync is None:
        lines.append("odometry  the log has one odometry; nothing to choose")
    elif sync["pairs"] == 0:
        lines.append(f"odometry  {sync['source']} at {sync['lag_s']:+.2f} s (set, not measured)")
    else:
        first = (
            "the poses written with the scans"
            if sync.get("written", True)
            else "the odometry messages at the scans' times"
        )
        lines.append(
            f"odometry  {first} disagree with the laser's rotations by "
            f"{sync['scan_disagreement_deg']:.3f}° (trimmed RMS over {sync['pairs']} pairs of "
            f"consecutive scans), the odometry messages at {sync['stream_lag_s']:+.2f} s by "
            f"{sync['stream_disagreement_deg']:.3f}°"
        )
        chosen = (
            "the written poses"
            if sync["source"] == "scan"
            else (f"the messages at {sync['lag_s']:+.2f} s")
        )
        lines.append(f"          robot.odometry_sync = {json.dumps(mode)}: {chosen}")
    m, st = report["mount"], report["stated_mount"]
    if m is None:
        lines.append(
            f"laser     the log states x {st['x']:+.3f} m, y {st['y']:+.3f} m, yaw "
            f"{st['yaw_deg']:+.2f}°; not measured: laser odometry turns with the laser"
        )
    else:
        lines += _mount_lines(m, st)
    lines.append(_steps_line(report["odometry_steps"]))
    lines.append(_noise_line(report["range_noise"]))
    beams = report.get("beam_geometry")
    if beams:
        from slam.calibration import BEAM_MARGIN

        short = beams["short"]
        lines.append(
            f"beams     scans of {short} and {short + 1} readings over {beams['fov_deg']:g}°: the "
            f"matcher's rotation against the odometry's (trimmed RMS, pairs that fit) with the "
            f"{short}-reading beams"
        )
        for name, row in beams["geometries"].items():
            lines.append(
                f"          {name:10s} {row['rotation_rms_deg']:.3f}°, {row['pairs_fitted']} pairs"
            )
        step = report.get("beam_step_deg")
        if report.get("beam_step_measured"):
            lines.append(
                f"          {beams['best']} fits best; `slam run` measures it when the log loads "
                f"and reads the log with lidar.beam_step_deg = {step:g} (lidar.measure_beam_step; "
                "docs/accuracy.md, the beam step of the 180-reading logs)"
            )
        elif step is not None:
            lines.append(
                f"          {beams['best']} fits best; declared: lidar.beam_step_deg = {step:g}"
            )
        elif report.get("beam_step_declarable"):
            lines.append(
                f"          centred fits best: --set lidar.beam_step_deg={beams['beam_step_deg']:g} "
                "declares it (docs/accuracy.md, the beam step of the 180-reading logs)"
            )
        else:
            lines.append(
                f"          {beams['best']} fits best; read spread, as the lines say (a run reads "
                f"them centred only when that fits {BEAM_MARGIN:.0%} better than spread)"
            )
    return lines


def _mount_lines(m: dict[str, Any], st: dict[str, Any]) -> list[str]:
    """The ``laser`` lines of a ``slam data calibrate`` report: the measured mount ``m`` against
    the stated one ``st``, and the options that apply it."""
    lines = [
        f"laser     measured at x {m['x']:+.3f} m, y {m['y']:+.3f} m, yaw {m['yaw_deg']:+.2f}° on "
        f"the robot (± {m['std_x']:.3f} m, {m['std_y']:.3f} m, {m['std_yaw_deg']:.2f}°; "
        f"{m['pairs']} turning pairs), residual {m['residual_m'] * 100:.1f} cm",
        f"          the log states x {st['x']:+.3f} m, y {st['y']:+.3f} m, yaw "
        f"{st['yaw_deg']:+.2f}°: residual {m['residual_stated_m'] * 100:.1f} cm",
        f"          to use the measured mount: --set lidar.use_log_laser_pose=false "
        f"--set lidar.x={m['x']:.3f} --set lidar.y={m['y']:.3f} "
        f"--set lidar.yaw={math.radians(m['yaw_deg']):.4f} (docs/accuracy.md: ground truth may "
        f"refer to the laser or to the odometry point)",
    ]
    return lines


def _steps_report(steps: Disagreement, rc: RbpfConfig) -> dict[str, Any]:
    """The odometry's measured disagreement with the matcher (what the smoothing weighs each
    odometry step by, ``rbpf.smooth_factor`` times it), as plain values."""
    known = steps.pairs > 0
    return {
        "along_m": round(steps.along, 4) if known else None,
        "across_m": round(steps.across, 4) if known else None,
        "heading_deg": round(math.degrees(steps.heading), 3) if known else None,
        "pairs": steps.pairs,
        "factor": rc.smooth_factor,
        "smoothing": rc.smooth_odometry,
    }


def _steps_line(steps: dict[str, Any]) -> str:
    """The ``steps`` line of a ``slam data calibrate`` report: how far the odometry's steps
    differ from the matcher's along and across the heading, and what the smoothing makes of it."""
    if not steps["pairs"]:
        return "steps     no pair of consecutive scans fitted: the odometry's steps not measured"
    head = (
        f"steps     the odometry differs from the matcher between consecutive scans by "
        f"{steps['along_m']:.4f} m along the heading, {steps['across_m']:.4f} m across and "
        f"{steps['heading_deg']:.3f}° (trimmed RMS over {steps['pairs']} pairs)"
    )
    if not steps["smoothing"]:
        return f"{head}; rbpf.smooth_odometry = false: not used"
    return (
        f"{head}: the smoothing weighs each odometry step by {steps['factor']:g} times these "
        "(rbpf.smooth_factor; docs/accuracy.md, the odometry's disagreement along and across "
        "the heading)"
    )


def _noise_line(noise: dict[str, Any]) -> str:
    """The ``ranges`` line of a ``slam data calibrate`` report: the laser's measured scatter and
    what the smoothing makes of it (``rbpf.smooth_noise_ref``)."""
    if noise["reference_m"] <= 0:
        return "ranges    not measured (rbpf.smooth_noise_ref = 0: the registration's own weight)"
    if noise["noise_m"] is None:
        return "ranges    no three neighbouring readings of 0.5-3 m: scatter not measured"
    head = (
        f"ranges    scatter {noise['noise_m']:.4f} m (second differences of neighbouring "
        f"readings of 0.5-3 m, {noise['triples']} triples)"
    )
    if noise["multiple"] <= 1.0:
        return f"{head}: at most rbpf.smooth_noise_ref = {noise['reference_m']:g} m, no change"
    return (
        f"{head}: a registered pose counts {noise['multiple']:.2f} times less against the "
        f"odometry than a {noise['reference_m']:g} m laser's (rbpf.smooth_noise_ref; "
        "docs/accuracy.md, the registration's weight from the laser's noise)"
    )

"""Frame pairing: which RGB-D frames the texture uses, with which partner, and at which poses.

This module owns the first two steps of the texture stage (docs/texture.md):

* every ``frame_stride``-th RGB frame whose PNG exists is paired with the disparity frame nearest
  in time (among those whose PNG exists) when they are at most ``pair_tolerance_s`` apart; frames
  outside the trajectory's time span are skipped, since poses are never extrapolated
  (:func:`pair_frames`, :func:`plan_frames`, checking the image folders);
* the robot pose at each pair's disparity time and RGB time, linearly interpolated from the
  trajectory (:func:`frame_poses`);
* why the other frames were skipped, counted by reason (:data:`SKIP_REASONS`) and reported as one
  :class:`TextureWarning` per reason (:func:`warn_skips`).
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.config import TextureConfig
from slam.io.log import RgbdIndex
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

SKIP_REASONS: dict[str, str] = {
    "missing_rgb": "RGB PNG missing",
    "corrupt_rgb": "RGB PNG unreadable or of the wrong size",
    "corrupt_disparity": "disparity PNG unreadable or of the wrong size",
    "no_disparity": "no disparity frame (with a PNG) within the pairing tolerance",
    "outside_trajectory": "frame time outside the trajectory's time span",
}
"""Why an RGB frame can be skipped, as counted under ``texture.skipped`` in ``metrics.json``."""


class TextureWarning(UserWarning):
    """A texture-mapping problem that was skipped over (bad frames, missing image folders)."""


@dataclass
class FramePlan:
    """Which RGB frames are used with which disparity frame, and why the others are not."""

    rgb: I64
    """0-based RGB frame indices to use, in time order."""
    disparity: I64
    """0-based disparity frame paired with each of them."""
    rgb_time: F64
    """Times of the RGB frames used (s)."""
    disparity_time: F64
    """Times of their disparity frames (s)."""
    considered: int
    """RGB frames considered (every ``frame_stride``-th of the log)."""
    skipped: dict[str, int] = field(default_factory=dict)
    """RGB frames skipped, by reason (keys of :data:`SKIP_REASONS`)."""
    examples: dict[str, str] = field(default_factory=dict)
    """One example (file or time) per skip reason, for the warnings."""
    count_mismatch: dict[str, dict[str, int]] = field(default_factory=dict)
    """Streams whose folder holds a different number of PNGs than the log has timestamps."""

    def skip(self, reason: str, count: int, example: str) -> None:
        """Count ``count`` RGB frames skipped for ``reason``."""
        if count <= 0:
            return
        self.skipped[reason] = self.skipped.get(reason, 0) + int(count)
        self.examples.setdefault(reason, example)


def nearest_frames(query: F64, times: F64) -> tuple[I64, F64]:
    """Index into ``times`` of the nearest time to each query and the signed gap ``query − time``.

    ``times`` need not be sorted; ties go to the earlier frame. ``times`` must not be empty.
    """
    query = np.asarray(query, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    order = np.argsort(times, kind="stable")
    sorted_t = times[order]
    right = np.clip(np.searchsorted(sorted_t, query), 1, max(sorted_t.size - 1, 1))
    left = right - 1
    if sorted_t.size == 1:
        pick = np.zeros(query.shape, dtype=np.int64)
    else:
        pick = np.where(
            np.abs(query - sorted_t[left]) <= np.abs(sorted_t[right] - query), left, right
        )
    index = order[pick]
    return index.astype(np.int64), query - times[index]


def pair_frames(
    rgb_time: F64,
    disparity_time: F64,
    tolerance: float,
    *,
    stride: int = 1,
    rgb_available: NDArray[np.bool_] | None = None,
    disparity_available: NDArray[np.bool_] | None = None,
    time_range: tuple[float, float] | None = None,
) -> FramePlan:
    """Pair every ``stride``-th RGB frame with the nearest available disparity frame in time.

    ``*_available`` mark frames whose PNG exists (default: all). An RGB frame is skipped when its
    PNG is missing (``missing_rgb``), when no available disparity frame is within ``tolerance``
    seconds (``no_disparity``), or when either time falls outside ``time_range`` (the
    trajectory's span; ``outside_trajectory``).
    """
    rgb_time = np.asarray(rgb_time, dtype=np.float64)
    disparity_time = np.asarray(disparity_time, dtype=np.float64)
    candidates = np.arange(0, rgb_time.size, max(int(stride), 1), dtype=np.int64)
    candidates = candidates[np.argsort(rgb_time[candidates], kind="stable")]
    plan = FramePlan(
        rgb=np.zeros(0, np.int64),
        disparity=np.zeros(0, np.int64),
        rgb_time=np.zeros(0),
        disparity_time=np.zeros(0),
        considered=int(candidates.size),
    )
    if rgb_available is not None:
        present = np.asarray(rgb_available, dtype=bool)[candidates]
        missing = candidates[~present]
        plan.skip(
            "missing_rgb", missing.size, f"RGB frame {missing[0] + 1}" if missing.size else ""
        )
        candidates = candidates[present]
    usable = np.arange(disparity_time.size, dtype=np.int64)
    if disparity_available is not None:
        usable = usable[np.asarray(disparity_available, dtype=bool)]
    if usable.size == 0:
        plan.skip("no_disparity", candidates.size, "no disparity PNG at all")
        return plan
    near, gap = nearest_frames(rgb_time[candidates], disparity_time[usable])
    paired = usable[near]
    ok = np.abs(gap) <= tolerance
    if (~ok).any():
        worst = candidates[~ok][0]
        plan.skip(
            "no_disparity",
            int((~ok).sum()),
            f"RGB frame {worst + 1}: nearest disparity {abs(gap[~ok][0]):.3f} s away",
        )
    candidates, paired = candidates[ok], paired[ok]
    if time_range is not None:
        lo, hi = time_range
        t_r, t_d = rgb_time[candidates], disparity_time[paired]
        inside = (t_r >= lo) & (t_r <= hi) & (t_d >= lo) & (t_d <= hi)
        if (~inside).any():
            first = candidates[~inside][0]
            plan.skip(
                "outside_trajectory",
                int((~inside).sum()),
                f"RGB frame {first + 1} at t={rgb_time[first]:.3f} s, trajectory "
                f"{lo:.3f}..{hi:.3f} s",
            )
        candidates, paired = candidates[inside], paired[inside]
    plan.rgb = candidates
    plan.disparity = paired
    plan.rgb_time = rgb_time[candidates]
    plan.disparity_time = disparity_time[paired]
    return plan


def frame_numbers(directory: Path, pattern: str) -> set[int]:
    """The frame numbers ``k`` (1-based) whose file ``pattern.format(k)`` exists in ``directory``."""
    prefix, _, suffix = pattern.partition("{}")
    regex = re.compile(re.escape(prefix) + r"([0-9]+)" + re.escape(suffix) + r"\Z")
    found: set[int] = set()
    try:
        with os.scandir(directory) as entries:
            for entry in entries:
                match = regex.match(entry.name)
                if match:
                    found.add(int(match.group(1)))
    except OSError:
        return set()
    return found


def plan_frames(
    index: RgbdIndex, config: TextureConfig, time_range: tuple[float, float] | None
) -> FramePlan:
    """Pair the frames of ``index`` (see :func:`pair_frames`), checking which PNGs exist.

    A folder holding a different number of PNGs than the log has timestamps is recorded in
    ``count_mismatch`` (frames are matched by number: frame ``k`` is ``…_k.png`` at the ``k``-th
    timestamp; timestamps without a file are skipped as missing, extra files are ignored).
    """
    streams = (
        ("rgb", index.rgb_dir, index.rgb_pattern, index.rgb_time.size),
        ("disparity", index.disparity_dir, index.disparity_pattern, index.disparity_time.size),
    )
    available: dict[str, NDArray[np.bool_]] = {}
    mismatch: dict[str, dict[str, int]] = {}
    for name, directory, pattern, n in streams:
        numbers = frame_numbers(directory, pattern)
        mask = np.zeros(n, dtype=bool)
        inside = [k - 1 for k in numbers if 1 <= k <= n]
        mask[inside] = True
        available[name] = mask
        if len(numbers) != n:
            mismatch[name] = {"files": len(numbers), "timestamps": int(n)}
    plan = pair_frames(
        index.rgb_time,
        index.disparity_time,
        config.pair_tolerance_s,
        stride=config.frame_stride,
        rgb_available=available["rgb"],
        disparity_available=available["disparity"],
        time_range=time_range,
    )
    if "missing_rgb" in plan.skipped:  # name the first missing file in the warning
        strided = np.arange(0, index.rgb_time.size, config.frame_stride)
        plan.examples["missing_rgb"] = str(
            index.rgb_path(int(strided[~available["rgb"][strided]][0]))
        )
    plan.count_mismatch = mismatch
    return plan


def frame_poses(plan: FramePlan, trajectory: Trajectory) -> tuple[F64, F64]:
    """Robot poses ``(N, 3)`` at the disparity and at the RGB time of each planned pair,
    interpolated along ``trajectory`` (angles unwrapped)."""
    return trajectory.at(plan.disparity_time), trajectory.at(plan.rgb_time)


def warn_skips(plan: FramePlan, index: RgbdIndex) -> list[str]:
    """One :class:`TextureWarning` per skip reason and per count mismatch; return their texts."""
    messages = []
    for stream, info in plan.count_mismatch.items():
        folder = index.rgb_dir if stream == "rgb" else index.disparity_dir
        messages.append(
            f"texture: {folder} holds {info['files']} {stream} PNGs but the log has "
            f"{info['timestamps']} {stream} timestamps; frames are matched by number"
        )
    for reason, count in plan.skipped.items():
        messages.append(
            f"texture: skipped {count} RGB frame(s): {SKIP_REASONS[reason]} "
            f"(e.g. {plan.examples.get(reason, '')})"
        )
    for message in messages:
        warnings.warn(message, TextureWarning, stacklevel=3)
    return messages

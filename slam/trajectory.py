"""The ``Trajectory`` value type: time-stamped planar poses, the one form every module passes.

A trajectory is ``times (N,)`` seconds and ``poses (N, 3)`` rows ``(x, y, θ)``, optionally with the
log index of the scan each pose belongs to. It is validated once, when it is made (same length,
finite values), so the code that receives one can trust it. Times need not be sorted: CARMEN logs
keep scans in file order, whose time stamps go backwards now and then; :meth:`sorted_by_time` and
:meth:`at` sort when they must.

For code written against the older ``(times, poses)`` tuples a trajectory still unpacks as one:
``times, poses = read_tum(path)``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.geometry import interpolate_poses

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Time-stamped planar poses (see the module docstring)."""

    times: F64
    """``(N,)`` pose times (s)."""
    poses: F64
    """``(N, 3)`` poses ``(x, y, θ)``."""
    scan_indices: NDArray[np.int64] | None = None
    """``(N,)`` log index of the scan each pose was estimated at, when there is one."""

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=np.float64)
        poses = np.asarray(self.poses, dtype=np.float64)
        if times.ndim != 1:
            raise ValueError(f"trajectory times: expected shape (N,), found {times.shape}")
        if poses.ndim != 2 or poses.shape[1] != 3:
            raise ValueError(f"trajectory poses: expected shape (N, 3), found {poses.shape}")
        if times.shape[0] != poses.shape[0]:
            raise ValueError(f"trajectory: {times.shape[0]} times for {poses.shape[0]} poses")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(poses))):
            bad = int(np.argmax(~(np.isfinite(times) & np.all(np.isfinite(poses), axis=1))))
            raise ValueError(f"trajectory: pose {bad} has a NaN or infinite value")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "poses", poses)
        if self.scan_indices is not None:
            indices = np.asarray(self.scan_indices, dtype=np.int64)
            if indices.shape != times.shape:
                raise ValueError(
                    f"trajectory scan_indices: expected shape {times.shape}, found {indices.shape}"
                )
            object.__setattr__(self, "scan_indices", indices)

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def __iter__(self) -> Iterator[F64]:
        """Unpack as ``times, poses`` (the form of the older tuple-based code)."""
        return iter((self.times, self.poses))

    def is_sorted(self) -> bool:
        """Whether the times never decrease."""
        return bool(np.all(np.diff(self.times) >= 0))

    def sorted_by_time(self) -> Trajectory:
        """The same poses in time order (stable: equal times keep their order)."""
        if self.is_sorted():
            return self
        order = np.argsort(self.times, kind="stable")
        indices = None if self.scan_indices is None else self.scan_indices[order]
        return Trajectory(self.times[order], self.poses[order], indices)

    def path_length(self) -> float:
        """Length of the polyline through the positions, in the stored order (m)."""
        if len(self) < 2:
            return 0.0
        return float(np.sum(np.hypot(*np.diff(self.poses[:, :2], axis=0).T)))

    def duration(self) -> float:
        """Time from the earliest to the latest pose (s)."""
        return float(self.times.max() - self.times.min()) if len(self) else 0.0

    def at(self, query: ArrayLike) -> F64:
        """Poses ``(M, 3)`` interpolated at the ``query`` times (headings unwrapped first).

        Queries outside the trajectory's time range get the nearest end pose (no extrapolation).
        """
        ordered = self.sorted_by_time()
        return interpolate_poses(ordered.times, ordered.poses, np.asarray(query, np.float64))

    def with_poses(self, poses: ArrayLike) -> Trajectory:
        """The same times (and scan indices) with other poses."""
        return Trajectory(self.times, np.asarray(poses, np.float64), self.scan_indices)

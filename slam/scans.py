"""Laser scans as the filter sees them: one :class:`Scan`, and the :class:`ScanSequence` of a run.

* :class:`Scan` is the value a user hands to :meth:`slam.online.Slam.update`: a time, the ranges
  and the beam angles, and optionally the range semantics (``range_min``, ``range_max``,
  ``no_return``) and the laser's pose on the robot. What a scan leaves out comes from the
  configuration's ``[lidar]`` section (:meth:`Scan.resolved`).
* :class:`ScanSequence` holds the scans a run has processed, in order, with the odometry pose of
  each. It grows one scan at a time while the filter runs, and the post-filter stages
  (:mod:`slam.stages`) read the whole of it afterwards: robot-frame hits (thinned to a beam
  budget, with surface normals for the signed field) and rays for occupancy updates.
* :class:`LogScans` turns a recorded :class:`~slam.io.log.Log` into the scans a ``slam run``
  processes (``filter.every``, ``filter.max_scans``), with the log's odometry at each: the
  batch pipeline feeds them to the same :class:`~slam.online.Slam` object an online user has.

Ranges are stored as float32 (the :class:`~slam.io.log.Log`'s convention: a laser's millimetres
are far above float32's precision), angles and poses as float64. A scan copies the arrays it is
given, except read-only ones of those dtypes: :class:`LogScans` hands its scans read-only views
of the log's arrays, so a run holds no copy of them per scan.
"""

from __future__ import annotations

import time
import warnings
import weakref
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.config import Config, LidarConfig
from slam.errors import DataError, UsageError
from slam.geometry import row_trig, spread_picks
from slam.io.log import Log

if TYPE_CHECKING:
    from slam.calibration import OdometrySync

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]


def nominal_scan_period(times: ArrayLike) -> float:
    """Nominal time between scans: the median positive time step (robust to CARMEN logs whose
    time stamps go backwards now and then); 0 when there is none."""
    steps = np.diff(np.asarray(times, dtype=np.float64))
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else 0.0


def _kept(values: ArrayLike, dtype: type, where: str, name: str) -> NDArray:
    """``values`` as the 1-D ``dtype`` array a :class:`Scan` keeps: a read-only one of that
    dtype as it is (a log's own arrays, shared by its scans: :class:`LogScans`), anything else
    copied (a driver may reuse its buffer). :class:`DataError` naming ``where`` and ``name``
    when they are not a 1-D sequence of numbers (a scalar, a 2-D array, strings, ``None``)."""
    if (
        isinstance(values, np.ndarray)
        and values.dtype == dtype
        and values.ndim == 1
        and not values.flags.writeable
    ):
        return values
    try:
        array = np.array(values, dtype=dtype)
    except (TypeError, ValueError):
        raise DataError(f"{where}: {name} must be numbers, found {_short(values)}") from None
    if array.ndim != 1:
        raise DataError(
            f"{where}: {name} must be a 1-D array (one value per beam), found shape {array.shape}"
        )
    return array


def _check_angles(angles: F64, where: str) -> None:
    """Refuse beam angles that are infinite or span more than a turn (degrees given for
    radians; a float32 turn of a 360° laser may overshoot 2π by a few 1e-7, which passes); NaN
    marks a beam that is not there (the padding of a log's shorter scans). A read-only view of
    a float64 array is checked with every row of that array, once: a log's scans are such views
    of its one angle array (:class:`LogScans`), and the array is remembered, weakly, until the
    next one."""
    base = angles.base
    if isinstance(base, np.ndarray):
        if _checked[0] is not None and _checked[0]() is base:
            return
        if (
            not angles.flags.writeable
            and base.dtype == np.float64
            and base.ndim <= 2
            and not _bad_rows(base).any()
        ):
            _checked[0] = weakref.ref(base)
            return
    if _bad_rows(angles).any():
        finite = angles[np.isfinite(angles)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
        infinite = bool(np.isinf(angles).any())
        raise DataError(
            f"{where}: angles must be radians spanning at most 2π (360°), found {lo:.6g} .. "
            f"{hi:.6g}{' and infinities' if infinite else ''} (degrees? multiply by π/180)"
        )


def _bad_rows(angles: NDArray) -> NDArray[np.bool_]:
    """Per row of ``angles`` (``(B,)`` or ``(S, B)``): whether an angle is infinite or the
    finite ones span more than 2π + 1e-3 rad."""
    rows = np.atleast_2d(angles)
    if rows.shape[1] == 0:  # scans without a beam
        return np.zeros(rows.shape[0], dtype=bool)
    finite = np.isfinite(rows)
    lo = np.where(finite, rows, np.inf).min(axis=1)
    hi = np.where(finite, rows, -np.inf).max(axis=1)
    span = np.where(finite.any(axis=1), hi - lo, 0.0)
    return np.isinf(rows).any(axis=1) | (span > 2 * np.pi + 1e-3)


_checked: list[weakref.ref | None] = [None]
"""The last base array whose every row :func:`_check_angles` passed (weakly held)."""


def _short(value: object) -> str:
    """``repr(value)`` cut to a readable length for a message."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _limit(value: object, where: str, name: str) -> float:
    """A range limit of a scan as a float: a number ≥ 0 (``inf`` allowed), else
    :class:`DataError` naming ``where`` and ``name``."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        number = float("nan")
    if not number >= 0:
        raise DataError(f"{where}: {name} must be a number of metres ≥ 0, found {_short(value)}")
    return number


@dataclass(frozen=True, eq=False)
class Scan:
    """One 2D laser scan (see the module docstring)."""

    time: float
    """Time the scan was taken (s)."""
    ranges: F32
    """``(B,)`` ranges (m); NaN, 0 or anything below ``range_min`` marks an invalid beam."""
    angles: F64
    """``(B,)`` beam angles in the laser frame (rad, counter-clockwise, 0 = forward)."""
    range_min: float | None = None
    """Shortest valid range (m); ``None``: ``lidar.range_min``, else 0."""
    range_max: float | None = None
    """Longest range that counts as an obstacle hit (m); ``None``: ``lidar.range_max``, else no
    limit (capped at ``no_return`` in any case)."""
    no_return: float | None = None
    """Readings at or beyond this mean "no return" (m); ``None``: ``lidar.no_return``, else none do."""
    laser_offset: F64 | None = None
    """``(3,)`` laser pose in the robot frame; ``None``: ``(lidar.x, lidar.y, lidar.yaw)``."""
    index: int | None = None
    """The scan's index in its log (the result's ``scan_indices``); ``None``: its position in the
    run."""
    _ends: tuple[F32, F32] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        try:
            time = float(self.time)
        except (TypeError, ValueError):
            time = float("nan")
        if not np.isfinite(time):
            raise DataError(
                f"scan: time must be a finite number of seconds, found {_short(self.time)}"
            )
        where = f"scan at t={time:.6f}"
        ranges = _kept(self.ranges, np.float32, where, "ranges")
        angles = _kept(self.angles, np.float64, where, "angles")
        if ranges.shape != angles.shape:
            raise DataError(f"{where}: {ranges.size} ranges for {angles.size} beam angles")
        _check_angles(angles, where)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "angles", angles)
        if self.laser_offset is not None:
            offset = np.array(self.laser_offset, dtype=np.float64).reshape(-1)
            if offset.shape != (3,) or not np.all(np.isfinite(offset)):
                raise DataError(
                    f"scan at t={time:.6f}: laser_offset must be 3 finite numbers (x, y, yaw), "
                    f"found {self.laser_offset!r}"
                )
            object.__setattr__(self, "laser_offset", offset)
        for name in ("range_min", "range_max", "no_return"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _limit(value, where, name))

    @classmethod
    def from_angle_range(
        cls,
        time: float,
        ranges: ArrayLike,
        angle_min: float,
        angle_increment: float,
        **fields: object,
    ) -> Scan:
        """A scan whose beam ``i`` points at ``angle_min + i · angle_increment`` (ROS
        ``LaserScan`` style); ``fields`` are the other :class:`Scan` fields."""
        ranges = np.asarray(ranges)
        for name, value in (("angle_min", angle_min), ("angle_increment", angle_increment)):
            if not isinstance(value, int | float | np.number) or not np.isfinite(value):
                raise DataError(f"scan at t={time}: {name} must be finite radians, found {value!r}")
        if angle_increment == 0 and ranges.size > 1:
            raise DataError(
                f"scan at t={time}: angle_increment is 0: every one of the {ranges.size} beams "
                "would point the same way"
            )
        angles = angle_min + angle_increment * np.arange(ranges.size, dtype=np.float64)
        return cls(time, ranges, angles, **fields)  # type: ignore[arg-type]

    @property
    def num_beams(self) -> int:
        """Beams in the scan."""
        return int(self.ranges.shape[0])

    @property
    def is_resolved(self) -> bool:
        """Whether every optional field has a value (the filter needs them all)."""
        fields = (self.range_min, self.range_max, self.no_return, self.laser_offset)
        return all(value is not None for value in fields)

    def resolved(self, lidar: LidarConfig) -> Scan:
        """This scan with what it leaves out taken from ``lidar`` (see the field docs)."""
        if self.is_resolved:
            if not self.range_min < self.range_max:  # type: ignore[operator]
                raise DataError(
                    f"scan at t={self.time:.6f}: no reading can be a return: range_min "
                    f"{self.range_min:g} m is not below range_max {self.range_max:g} m"
                )
            return self

        def pick(own: float | None, configured: float | None, default: float) -> float:
            if own is not None:
                return own
            return configured if configured is not None else default

        no_return = pick(self.no_return, lidar.no_return, np.inf)
        range_max = float(min(pick(self.range_max, lidar.range_max, np.inf), no_return))
        range_min = pick(self.range_min, lidar.range_min, 0.0)
        if not range_min < range_max:
            raise DataError(
                f"scan at t={self.time:.6f}: no reading can be a return: range_min "
                f"{range_min:g} m is not below range_max {range_max:g} m (the smaller of "
                "range_max and no_return, the scan's or else lidar.*)"
            )
        offset = self.laser_offset
        if offset is None:
            offset = np.array([lidar.x, lidar.y, lidar.yaw], dtype=np.float64)
        return replace(
            self, range_min=range_min, range_max=range_max, no_return=no_return,
            laser_offset=offset,
        )  # fmt: skip

    def _require_resolved(self) -> None:
        if not self.is_resolved:
            raise UsageError(
                f"scan at t={self.time:.6f}: range_min, range_max, no_return and laser_offset "
                "must be known; call scan.resolved(config.lidar) first"
            )

    def endpoints(self) -> tuple[F32, F32]:
        """Robot-frame endpoints ``(ex, ey)``, each ``(B,)`` float32, NaN where not a return.

        Computed once and kept (the scan is immutable).
        """
        if self._ends is None:
            ex, ey = endpoint_rows([self], self.num_beams)  # the one formula, for one scan
            object.__setattr__(self, "_ends", (ex[0], ey[0]))
        return self._ends  # type: ignore[return-value]

    def hits(self, max_beams: int = 0) -> tuple[F64, F64]:
        """Robot-frame endpoints ``(ex, ey)`` of the obstacle returns.

        With ``max_beams`` the returns are thinned to at most that many, evenly spread.
        """
        ex_all, ey_all = self.endpoints()
        valid = np.flatnonzero(~np.isnan(ex_all))
        if max_beams and valid.size > max_beams:
            valid = valid[spread_picks(valid.size, max_beams)]
        return (
            np.ascontiguousarray(ex_all[valid], dtype=np.float64),
            np.ascontiguousarray(ey_all[valid], dtype=np.float64),
        )

    def hits_with_normals(self, max_beams: int = 0) -> tuple[F64, F64, F64, F64]:
        """Robot-frame endpoints and unit surface normals ``(ex, ey, nx, ny)``.

        See :func:`surface_normals`; normals are estimated before thinning to ``max_beams``.
        """
        ex, ey = self.hits()
        lx, ly, _ = self.laser_offset  # type: ignore[misc]
        nx, ny = surface_normals(ex, ey, lx, ly)
        if max_beams and ex.size > max_beams:
            pick = spread_picks(ex.size, max_beams)
            ex, ey, nx, ny = ex[pick], ey[pick], nx[pick], ny[pick]
        return (
            np.ascontiguousarray(ex),
            np.ascontiguousarray(ey),
            np.ascontiguousarray(nx),
            np.ascontiguousarray(ny),
        )

    def rays(self, free_range_no_return: float, stride: int = 1) -> tuple[F64, NDArray[np.bool_]]:
        """Robot-frame ray ends ``(K, 2)`` and hit flags for an occupancy update.

        Returns are hits; readings between ``range_max`` and ``no_return`` clear free space up to
        ``range_max``; "no return" readings clear up to ``free_range_no_return`` (0: not at all).
        Only every ``stride``-th non-hit ray is kept (hits are always kept).
        """
        self._require_resolved()
        r = self.ranges.astype(np.float64)
        a = self.angles
        limits = (self.range_min, self.range_max, self.no_return)  # resolved: numbers
        keep, hit, length = ray_kinds(r, a, *limits, free_range_no_return, stride)  # type: ignore
        lx, ly, lt = self.laser_offset  # type: ignore[misc]
        c, s = np.cos(lt + a[keep]), np.sin(lt + a[keep])
        ends = np.stack([lx + length[keep] * c, ly + length[keep] * s], axis=1)
        return ends, hit[keep]


def ray_kinds(
    r: F64,
    a: F64,
    range_min: float | F64,
    range_max: float | F64,
    no_return: float | F64,
    free_range_no_return: float,
    stride: int = 1,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], F64]:
    """Which readings ``r`` (at beam angles ``a``; one scan ``(B,)`` or scans ``(S, B)`` with
    ``(S, 1)`` limits) give a ray for an occupancy update, which of those are hits, and each
    ray's length: the range semantics of :meth:`Scan.rays` and :meth:`ScanSequence.ray_table`.
    Returns ``(keep, hit, length)``, ``hit`` over all readings."""
    valid = np.isfinite(r) & np.isfinite(a) & (r >= range_min) & (r > 0)
    hit = valid & (r < range_max)
    length = np.where(r < no_return, np.minimum(r, range_max), free_range_no_return)
    keep = hit | (valid & (length > 0))
    if stride > 1:  # every stride-th beam of each scan (hits are always kept)
        thin = np.zeros_like(keep)
        thin[..., ::stride] = True
        keep &= hit | thin
    return keep, hit, length


def endpoint_rows(scans: list[Scan], width: int) -> tuple[F32, F32]:
    """The robot-frame endpoints of ``scans`` (resolved) as ``(S, width)`` float32 rows, NaN
    where no return or no beam, in one pass: the formula :meth:`Scan.endpoints` uses too (one
    scan, one row), so a row is that scan's endpoints to the bit.

    A return is a finite reading in ``[range_min, range_max)`` above 0 (a driver's 0 marks no
    reading, whatever ``range_min`` says), the float32 ranges compared with
    each scan's limits in float32; its endpoint is the laser pose plus the range along the beam,
    in float64, then float32. The cosines and sines, most of the cost, are computed once for all
    the rows whose beam directions (laser heading plus beam angles) have the bits of the first
    row's, as in a log of one laser, and row by row for the others
    (:func:`slam.geometry.row_trig`)."""
    r = np.full((len(scans), width), np.nan, dtype=np.float32)
    a = np.full((len(scans), width), np.nan)
    limits = np.empty((len(scans), 5))  # range_min, range_max, laser x, y, yaw
    for i, scan in enumerate(scans):
        scan._require_resolved()
        r[i, : scan.num_beams] = scan.ranges
        a[i, : scan.num_beams] = scan.angles
        limits[i, :2] = scan.range_min, scan.range_max
        limits[i, 2:] = scan.laser_offset
    low, high = limits[:, 0:1].astype(np.float32), limits[:, 1:2].astype(np.float32)
    r[~(np.isfinite(r) & np.isfinite(a) & (r >= low) & (r > 0) & (r < high))] = np.nan
    cos, sin = row_trig(limits[:, 4:5] + a)
    ex = (limits[:, 2:3] + r * cos).astype(np.float32)
    ey = (limits[:, 3:4] + r * sin).astype(np.float32)
    return ex, ey


def odometry_pose(scan: Scan, odometry: ArrayLike) -> NDArray[np.float64]:
    """``odometry``, the pose the robot's odometry gave at ``scan``, as ``(3,)`` float64;
    :class:`DataError` naming the scan's time when it is not a finite ``(x, y, theta)``."""
    try:
        pose = np.asarray(odometry, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        pose = np.full(0, np.nan)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise DataError(
            f"scan at t={scan.time:.6f}: odometry must be a finite pose (x, y, theta), "
            f"found {odometry!r}"
        )
    return pose


def surface_normals(
    ex: F64, ey: F64, sx: float, sy: float, gap: float = 0.1, relative_gap: float = 0.02
) -> tuple[F64, F64]:
    """Unit normals at scan endpoints ``(ex, ey)`` (in beam order), facing the sensor ``(sx, sy)``.

    The tangent at a point is the chord between its two neighbours when both are close (closer
    than ``gap + relative_gap·range``), else the chord to the one close neighbour; points with no
    close neighbour (isolated returns) face the sensor along their beam.
    """
    n = ex.shape[0]
    bx = sx - ex
    by = sy - ey
    rng = np.hypot(bx, by)
    rng = np.where(rng > 0, rng, 1.0)
    tx = np.zeros(n)
    ty = np.zeros(n)
    if n >= 2:
        dx = np.diff(ex)
        dy = np.diff(ey)
        limit = gap + relative_gap * np.minimum(rng[1:], rng[:-1])
        close = np.hypot(dx, dy) < limit
        # chord to the next neighbour (forward) and from the previous one (backward)
        fwd = np.zeros(n, dtype=bool)
        bwd = np.zeros(n, dtype=bool)
        fwd[:-1] = close
        bwd[1:] = close
        tx[:-1] += np.where(close, dx, 0.0)
        ty[:-1] += np.where(close, dy, 0.0)
        tx[1:] += np.where(close, dx, 0.0)
        ty[1:] += np.where(close, dy, 0.0)
        has = fwd | bwd
    else:
        has = np.zeros(n, dtype=bool)
    norm = np.hypot(tx, ty)
    has &= norm > 1e-9
    norm = np.where(has, norm, 1.0)
    nx = np.where(has, -ty / norm, bx / rng)
    ny = np.where(has, tx / norm, by / rng)
    flip = nx * bx + ny * by < 0
    nx = np.where(flip, -nx, nx)
    ny = np.where(flip, -ny, ny)
    return nx, ny


class ScanSequence:
    """The scans a run has processed, in order, with the odometry pose of each.

    Grows by :meth:`append` (amortised O(1): times, odometry and indices live in arrays that double
    when full); ``times``, ``odometry`` and ``indices`` are views of the filled part.
    """

    def __init__(self, capacity: int = 1024) -> None:
        capacity = max(int(capacity), 1)
        self._scans: list[Scan] = []
        self._times = np.empty(capacity)
        self._odometry = np.empty((capacity, 3))
        self._indices = np.empty(capacity, dtype=np.int64)
        self._beams = 0
        self.odometry_source = "log"
        """Where the odometry comes from: ``"log"`` dead reckoning, ``"laser"`` scan matching
        (:attr:`LogScans.odometry_source`)."""

    def __len__(self) -> int:
        return len(self._scans)

    def append(self, scan: Scan, odometry: ArrayLike) -> int:
        """Add a resolved scan taken at the odometry pose ``odometry``; return its number."""
        if not scan.is_resolved:
            raise UsageError(f"scan at t={scan.time:.6f}: resolve it (Scan.resolved) before a run")
        pose = odometry_pose(scan, odometry)
        k = len(self._scans)
        last = self._scans[-1].angles if k else None
        if (
            last is not None
            and scan.angles is not last
            and scan.angles.shape == last.shape
            and np.array_equal(scan.angles, last, equal_nan=True)
        ):  # one array for a laser's scans: a driver's angles, copied into each Scan, would
            # cost 8 bytes a reading for the whole run (415 MB over 48,000 1081-beam scans);
            # read-only, so that writing into one scan's angles cannot change another's
            last.flags.writeable = False
            object.__setattr__(scan, "angles", last)
        if k == self._times.shape[0]:
            self._times = np.concatenate([self._times, np.empty(k)])
            self._odometry = np.concatenate([self._odometry, np.empty((k, 3))])
            self._indices = np.concatenate([self._indices, np.empty(k, dtype=np.int64)])
        self._scans.append(scan)
        self._times[k] = scan.time
        self._odometry[k] = pose
        self._indices[k] = k if scan.index is None else int(scan.index)
        self._beams = max(self._beams, scan.num_beams)
        return k

    @property
    def times(self) -> F64:
        """``(N,)`` scan times (s)."""
        return self._times[: len(self)]

    @property
    def odometry(self) -> F64:
        """``(N, 3)`` odometry pose of the robot at each scan."""
        return self._odometry[: len(self)]

    @property
    def indices(self) -> NDArray[np.int64]:
        """``(N,)`` index of each scan in its log."""
        return self._indices[: len(self)]

    @property
    def laser_offset(self) -> F64:
        """``(3,)`` laser pose in the robot frame (of the first scan)."""
        if not self._scans:
            raise UsageError("scan sequence: no scans yet")
        return self._scans[0].laser_offset  # type: ignore[return-value]

    @property
    def num_beams(self) -> int:
        """Beams per scan (the widest scan when beam counts vary)."""
        return self._beams

    def scan(self, k: int) -> Scan:
        """Scan number ``k``."""
        return self._scans[k]

    def scan_period(self) -> float:
        """Nominal time between the scans (:func:`nominal_scan_period`)."""
        return nominal_scan_period(self.times)

    def hits(self, k: int, max_beams: int = 0) -> tuple[F64, F64]:
        """Robot-frame obstacle returns of scan ``k`` (:meth:`Scan.hits`)."""
        return self._scans[k].hits(max_beams)

    def hits_with_normals(self, k: int, max_beams: int = 0) -> tuple[F64, F64, F64, F64]:
        """Returns and surface normals of scan ``k`` (:meth:`Scan.hits_with_normals`)."""
        return self._scans[k].hits_with_normals(max_beams)

    def hit_table(self, steps: ArrayLike, max_beams: int = 0, normals: bool = False) -> ScanHits:
        """The hits of scans ``steps`` (:meth:`hits`, or :meth:`hits_with_normals` with
        ``normals``) side by side, in that order."""
        parts = []
        reach = np.zeros(len(steps))
        for i, k in enumerate(np.asarray(steps, dtype=np.int64)):
            if normals:
                part = self.hits_with_normals(int(k), max_beams)
            else:
                part = self.hits(int(k), max_beams)
            hx, hy = part[0], part[1]
            if hx.size:
                reach[i] = float(np.sqrt((hx * hx + hy * hy).max()))
            parts.append(part)
        offsets = np.zeros(len(parts) + 1, dtype=np.int64)
        np.cumsum([part[0].size for part in parts], out=offsets[1:])
        rows = 4 if normals else 2
        xy = np.empty((rows, int(offsets[-1])))
        for i, part in enumerate(parts):
            for r in range(rows):
                xy[r, offsets[i] : offsets[i + 1]] = part[r]
        return ScanHits(xy, offsets, reach)

    def rays(
        self, k: int, free_range_no_return: float, stride: int = 1
    ) -> tuple[F64, NDArray[np.bool_]]:
        """Rays of scan ``k`` for an occupancy update (:meth:`Scan.rays`)."""
        return self._scans[k].rays(free_range_no_return, stride)

    def readings(
        self, steps: ArrayLike, width: int = 0, beams: ArrayLike | None = None
    ) -> tuple[F64, F64]:
        """The ranges and beam angles of scans ``steps`` as ``(S, W)`` float64 rows, ``W`` the
        widest of them (at least ``width``), NaN where a scan has no beam; with ``beams``, only
        those columns of the rows (``(S, len(beams))``, never the whole width)."""
        scans = [self._scans[int(k)] for k in np.asarray(steps, dtype=np.int64)]
        width = max(width, max((scan.num_beams for scan in scans), default=0))
        if beams is None:
            r = np.full((len(scans), width), np.nan)
            a = np.full((len(scans), width), np.nan)
            for i, scan in enumerate(scans):
                r[i, : scan.num_beams] = scan.ranges
                a[i, : scan.num_beams] = scan.angles
            return r, a
        cols = np.asarray(beams, dtype=np.int64)
        r = np.full((len(scans), cols.size), np.nan)
        a = np.full((len(scans), cols.size), np.nan)
        for i, scan in enumerate(scans):
            there = cols < scan.num_beams
            r[i, there] = scan.ranges[cols[there]]
            a[i, there] = scan.angles[cols[there]]
        return r, a

    def endpoint_table(self, steps: ArrayLike) -> tuple[F32, F32]:
        """Robot-frame endpoints of scans ``steps`` as ``(S, W)`` float32 rows, ``W`` the widest
        of them, NaN where no return or no beam: :meth:`Scan.endpoints` scan by scan, to the
        bit.

        The scans whose endpoints are known are copied; the others are computed in one pass
        (:func:`endpoint_rows`), and each keeps its row as its endpoints (later calls, and
        :meth:`Scan.endpoints`, return it)."""
        scans = [self._scans[int(k)] for k in np.asarray(steps, dtype=np.int64)]
        width = max((scan.num_beams for scan in scans), default=0)
        todo = [i for i, scan in enumerate(scans) if scan._ends is None]
        if len(todo) == len(scans):
            ex, ey = endpoint_rows(scans, width)
        else:
            ex = np.full((len(scans), width), np.nan, dtype=np.float32)
            ey = np.full((len(scans), width), np.nan, dtype=np.float32)
            if todo:
                ex[todo], ey[todo] = endpoint_rows([scans[i] for i in todo], width)
            for i, scan in enumerate(scans):
                if scan._ends is not None:
                    ex[i, : scan.num_beams], ey[i, : scan.num_beams] = scan._ends
        for i in todo:
            scan = scans[i]
            object.__setattr__(scan, "_ends", (ex[i, : scan.num_beams], ey[i, : scan.num_beams]))
        return ex, ey

    def ray_table(
        self, steps: ArrayLike, free_range_no_return: float, stride: int = 1
    ) -> tuple[F64, NDArray[np.bool_], NDArray[np.int64]]:
        """The rays of scans ``steps`` (:meth:`rays`) side by side: robot-frame ends ``(N, 2)``,
        hit flags ``(N,)`` and ``(len(steps) + 1,)`` offsets (scan ``i``'s rays are rows
        ``offsets[i]:offsets[i + 1]``).

        The values of :meth:`Scan.rays` scan by scan, to the bit, in one pass: the scans'
        readings padded to one width (NaN: no beam, never kept) and each scan's limits and laser
        pose as a column, so every element meets the same element-wise operations.
        """
        steps = np.asarray(steps, dtype=np.int64)
        scans = [self._scans[int(k)] for k in steps]
        limits = np.empty((len(scans), 6))  # range_min, range_max, no_return, laser x, y, yaw
        for i, scan in enumerate(scans):
            scan._require_resolved()
            limits[i, :3] = scan.range_min, scan.range_max, scan.no_return
            limits[i, 3:] = scan.laser_offset
        r, a = self.readings(steps)
        range_min, range_max, no_return, lx, ly, lt = (limits[:, j, None] for j in range(6))
        keep, hit, length = ray_kinds(
            r, a, range_min, range_max, no_return, free_range_no_return, stride
        )
        rows = np.nonzero(keep)[0]
        cos, sin = row_trig(lt + a)  # once for the scans of one laser
        c, s = np.broadcast_to(cos, keep.shape)[keep], np.broadcast_to(sin, keep.shape)[keep]
        reach = length[keep]
        ends = np.stack([lx[rows, 0] + reach * c, ly[rows, 0] + reach * s], axis=1)
        offsets = np.zeros(len(scans) + 1, dtype=np.int64)
        np.cumsum(np.count_nonzero(keep, axis=1), out=offsets[1:])
        return ends, hit[keep], offsets

    @classmethod
    def from_log(cls, log: Log, config: Config) -> ScanSequence:
        """The scans a run of ``log`` processes (:class:`LogScans`), with their odometry."""
        return cls.from_scans(LogScans.from_log(log, config))

    @classmethod
    def from_scans(cls, source: LogScans) -> ScanSequence:
        """The scans of ``source``, with their odometry, in a sequence."""
        seq = cls(len(source))
        seq.odometry_source = source.odometry_source
        for scan, odometry in source:
            seq.append(scan, odometry)
        return seq


@dataclass(frozen=True, eq=False)
class ScanHits:
    """The obstacle returns of some scans of a :class:`ScanSequence`, side by side: what the
    back end inserts into its submaps, thinned once instead of at every insertion.

    Row ``i`` (the ``i``-th of the scans asked for) is ``xy[:, offsets[i]:offsets[i + 1]]``.
    """

    xy: F64
    """``(2, N)`` robot-frame hits ``(hx, hy)`` of every scan, or ``(4, N)`` with the unit
    surface normals ``(nx, ny)`` below them."""
    offsets: NDArray[np.int64]
    """``(S + 1,)`` where each scan's hits start (and the end)."""
    reach: F64
    """``(S,)`` distance of each scan's farthest hit from the robot (m; 0 without hits)."""

    def take(self, rows: NDArray[np.int64]) -> tuple[F64, NDArray[np.int64], F64]:
        """The hits of scans ``rows`` for :meth:`slam.mapping.ParticleMaps.insert_scans`:
        ``(2, N')`` hits or ``(4, N')`` hits and normals (as kept), their ``(len(rows) + 1,)``
        offsets and the scans' reach."""
        rows = np.asarray(rows, dtype=np.int64)
        first = self.offsets[rows]
        counts = self.offsets[rows + 1] - first
        offsets = np.zeros(rows.size + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        index = np.repeat(first - offsets[:-1], counts) + np.arange(offsets[-1])
        return self.xy[:, index], offsets, self.reach[rows]


PAUSE_S = 1.0
"""A pause in the scans is longer than this (s) ..."""
PAUSE_PERIODS = 5.0
"""... and than this many nominal scan periods (:func:`nominal_scan_period`)."""


def scan_pauses(times: ArrayLike) -> NDArray[np.int64]:
    """Indices ``k`` of the scans after which the log pauses (``times[k + 1] - times[k]`` over
    :data:`PAUSE_S` and :data:`PAUSE_PERIODS` scan periods): where laser odometry, which sees
    nothing of the motion there, has to guess it."""
    times = np.asarray(times, dtype=np.float64)
    if times.size < 2:
        return np.zeros(0, dtype=np.int64)
    gaps = np.diff(times)
    limit = max(PAUSE_S, PAUSE_PERIODS * nominal_scan_period(times))
    return np.flatnonzero(gaps > limit).astype(np.int64)


def _log_odometry(log: Log, idx: NDArray[np.int64], config: Config) -> tuple[F64 | None, str]:
    """The log's odometry at the selected scans ``idx`` (:func:`slam.odometry.scan_odometry`), or
    ``None`` where ``robot.odometry`` takes the laser's instead, with why when ``"auto"`` chose
    it ("": ``"laser"`` asked for it). With ``"auto"``, poses written with the scans that never
    move give way to the log's odometry messages when those move, else to the laser's."""
    from slam.odometry import has_odometry, moving_stream, never_moves, scan_odometry

    mode = config.robot.odometry
    if mode == "laser":
        return None, ""
    if mode == "auto" and not has_odometry(log):
        return None, "the log has no odometry (no odometry messages, encoders or scan poses)"
    odometry = np.ascontiguousarray(scan_odometry(log, config.robot)[idx], dtype=np.float64)
    if mode != "auto" or not never_moves(odometry):
        return odometry, ""
    stream = log.odometry
    if stream is None or not moving_stream(log):
        return None, f"the log's odometry never moves (every scan's pose is {odometry[0].tolist()})"
    from slam.io.plausibility import DataWarning
    from slam.odometry import poses_at

    warnings.warn(
        f"{log.name}: the poses written with the scans never move (every one is "
        f"{odometry[0].tolist()}); the odometry messages at the scans' times stand in",
        DataWarning,
        stacklevel=3,
    )
    order = np.argsort(stream.time, kind="stable")
    times = np.asarray(log.scans.time, dtype=np.float64)[idx]  # type: ignore[union-attr]
    return np.ascontiguousarray(poses_at(stream.time[order], stream.poses[order], times)), ""


@dataclass(frozen=True, eq=False)
class LogScans:
    """The scans of a recorded log that a run processes, ready to be fed one by one."""

    log: Log
    """The log."""
    indices: NDArray[np.int64]
    """``(M,)`` log index of each selected scan (``filter.every``, ``filter.max_scans``)."""
    odometry: F64
    """``(M, 3)`` odometry pose of the robot at each selected scan."""
    range_min: float
    """Shortest valid range (m): ``lidar.range_min``, else the log's."""
    range_max: float
    """Longest hit (m): ``lidar.range_max``, else the log's; at most ``no_return``."""
    no_return: float
    """"No return" reading (m): ``lidar.no_return``, else the log's."""
    odometry_sync: OdometrySync | None = None
    """Which odometry ``robot.odometry_sync`` chose for a log that has two (None: the log has one)."""
    odometry_source: str = "log"
    """Where :attr:`odometry` comes from: ``"log"`` the log's, ``"laser"`` scan matching
    (:mod:`slam.laser_odometry`; ``robot.odometry``)."""
    laser_odometry: dict[str, float] | None = None
    """With laser odometry: its :meth:`~slam.laser_odometry.LaserOdometry.counts` (the scans its
    matcher placed, those that kept the constant-velocity prediction, and with a gyro its turns,
    agreement and where it was set aside) and the time it took (``seconds``)."""

    @classmethod
    def from_log(cls, log: Log, config: Config) -> LogScans:
        """Select the scans to process, with the odometry at each (:func:`slam.odometry.scan_odometry`:
        computed from the whole log, so ECE276A logs get the zero-phase filtered gyro).

        :class:`DataError` when no selected scan has a valid beam, a :class:`DataWarning` when
        too many are sparse (:func:`slam.io.plausibility.check_valid_beams`).
        """
        from slam.io.plausibility import DataWarning, check_valid_beams

        if log.scans is None:
            raise DataError(f"{log.name}: the log has no laser scans to run SLAM on")
        scans = log.scans
        idx = np.arange(len(scans), dtype=np.int64)[:: config.filter.every]
        if config.filter.max_scans:
            idx = idx[: config.filter.max_scans]
        if idx.size == 0:
            raise DataError(f"{log.name}: no scans selected (every={config.filter.every})")
        lidar = config.lidar
        range_max = lidar.range_max if lidar.range_max is not None else scans.range_max
        no_return = lidar.no_return if lidar.no_return is not None else scans.no_return
        range_min = lidar.range_min if lidar.range_min is not None else scans.range_min
        sparse = check_valid_beams(
            log, scans.ranges[idx], range_min, min(range_max, no_return), no_return, config.checks
        )
        if sparse is not None:  # the pipeline records warnings in metrics.json and on stderr
            warnings.warn(sparse, DataWarning, stacklevel=2)
        odometry, why = _log_odometry(log, idx, config)
        selected = cls(
            log=log,
            indices=idx,
            odometry=np.zeros((idx.size, 3)) if odometry is None else odometry,
            range_min=float(range_min),
            range_max=float(min(range_max, no_return)),
            no_return=float(no_return),
        )
        if odometry is not None:
            return selected.synchronised(config)
        if why:  # robot.odometry = "auto" found none: say so (metrics.json and stderr)
            warnings.warn(
                f"{log.name}: {why}; the odometry comes from matching the scans "
                '(robot.odometry = "auto"; docs/slam.md, "A robot without odometry")',
                DataWarning,
                stacklevel=2,
            )
        return selected.with_laser_odometry(config)

    def with_laser_odometry(self, config: Config) -> LogScans:
        """These scans with the odometry :class:`slam.laser_odometry.LaserOdometry` gives them,
        and a :class:`DataWarning` when the robot moved during pauses in the scans
        (:func:`scan_pauses` after which the scan did not fit where the motion before put it)."""
        from slam.io.plausibility import DataWarning
        from slam.laser_odometry import laser_odometry

        start = time.perf_counter()
        poses, made = laser_odometry([self.scan(i) for i in range(len(self))], config, self.log.imu)
        counts = made.counts() | {"seconds": round(time.perf_counter() - start, 3)}
        if made.gyro_set_aside_at is not None:
            aside = made.gyro_set_aside_at
            correlation, ratio = made.gyro_agreement
            warnings.warn(
                f"{self.log.name}: the gyro's turns disagree with the scans' (correlation "
                f"{correlation:.2f}, {ratio:.2f} times their size over the first turns; 1 and 1 "
                f"where they agree), so laser odometry stops using it "
                f"{self.times[aside] - self.times[0]:.1f} s into the log: is the IMU mounted as "
                "its frame says, and its rate in rad/s? (robot.laser_odometry_gyro = false leaves "
                "it out)",
                DataWarning,
                stacklevel=2,
            )
        times = self.times
        pauses = np.intersect1d(scan_pauses(times) + 1, made.unfit) - 1  # moved while unseen
        if pauses.size:
            seen = "sees nothing of that motion and guesses it"
            if made.gyro is not None and made.gyro_set_aside_at is None:
                seen = "sees only the gyro's turn of that motion and guesses the rest"
            longest = int(pauses[np.argmax(times[pauses + 1] - times[pauses])])
            warnings.warn(
                f"{self.log.name}: after {pauses.size} pause(s) in the scans the next scan did "
                f"not fit where the motion before put it (the robot moved meanwhile), the longest "
                f"{times[longest + 1] - times[longest]:.2f} s at {times[longest] - times[0]:.1f} s "
                f"into the log; laser odometry {seen} "
                '(docs/slam.md, "A robot without odometry")',
                DataWarning,
                stacklevel=2,
            )
        return replace(self, odometry=poses, odometry_source="laser", laser_odometry=counts)

    def synchronised(self, config: Config) -> LogScans:
        """These scans with the odometry ``robot.odometry_sync`` picks when the log has a stream
        of odometry messages (:mod:`slam.calibration`): against the pose written with each
        scan (CARMEN), or, where the scans carry none (a bag, raw CARMEN scans), against the
        stream at the scans' own times, which :func:`slam.odometry.scan_odometry` gave and
        which stays unless the stream at a lag agrees with the laser clearly better.
        Unchanged with ``"scan"`` or without a stream."""
        from slam.calibration import OdometrySync, stream_at, synchronise_odometry

        mode, stream = config.robot.odometry_sync, self.log.odometry
        if mode == "scan" or stream is None or len(stream.time) < 2 or len(self) < 2:
            return self
        written = self.log.scans.odometry is not None  # type: ignore[union-attr]
        if mode == "stream":
            lag = config.robot.odometry_lag_s
            poses = stream_at(stream.time, stream.poses, self.times + lag)
            nan = float("nan")
            sync = OdometrySync("stream", lag, nan, nan, lag, nan, 0, written)
        else:
            poses, sync = synchronise_odometry(
                lambda k: self.scan(k).hits(), self.times, self.odometry,
                (stream.time, stream.poses), config,
            )  # fmt: skip
            sync = replace(sync, written=written)
            if not written and sync.source == "scan":  # the stream at the scans' times, kept
                return replace(self, odometry_sync=replace(sync, source="stream"))
        return replace(self, odometry=np.ascontiguousarray(poses), odometry_sync=sync)

    def __len__(self) -> int:
        return int(self.indices.shape[0])

    @property
    def times(self) -> F64:
        """``(M,)`` times of the selected scans (s)."""
        return np.asarray(self.log.scans.time[self.indices], np.float64)  # type: ignore[union-attr]

    def scan_period(self) -> float:
        """Nominal time between the selected scans (:func:`nominal_scan_period`)."""
        return nominal_scan_period(self.times)

    def scan(self, i: int) -> Scan:
        """Selected scan ``i`` as a resolved :class:`Scan` (laser offset: the log's)."""
        scans = self.log.scans
        k = int(self.indices[i])
        ranges, angles = scans.ranges[k].view(), scans.scan_angles(k).view()  # type: ignore[union-attr]
        ranges.flags.writeable = angles.flags.writeable = False  # shared with the log, not copied
        return Scan(
            time=float(scans.time[k]),  # type: ignore[union-attr]
            ranges=ranges,
            angles=angles,
            range_min=self.range_min,
            range_max=self.range_max,
            no_return=self.no_return,
            laser_offset=scans.laser_offset,  # type: ignore[union-attr]
            index=k,
        )

    def __iter__(self) -> Iterator[tuple[Scan, F64]]:
        """``(scan, odometry pose)`` for every selected scan, in order."""
        for i in range(len(self)):
            yield self.scan(i), self.odometry[i]

"""Entity paths and default layouts (blueprints) of the recordings.

``slam run`` recordings (:func:`run_blueprint`): the map view (occupancy map, trajectories,
particles, scan, robot) beside the time series (N_eff, max weight, scans/s), with a second tab
for the floor texture. ``slam grid run`` and ``slam maze run`` have their own
(:func:`grid_blueprint`, :func:`maze_blueprint`).

World coordinates have +y up while rerun's 2D views draw +y down: the ``world`` entity carries a
static transform that flips y (:func:`world_flip`), every world-placed entity lives under it, and
the views' origin is the root, so maps read like ``map.png``.

Trajectories are logged one segment per step; the map view shows the whole history of those
entities up to the time cursor (a visible-time-range override), and only the latest particles,
scan and robot pose.
"""

from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb

WORLD = "world"
MAP = "world/map"
TEXTURE = "world/texture"
TRAJECTORY = "world/trajectory/live"
TRAJECTORY_FINAL = "world/trajectory/final"
GROUND_TRUTH = "world/ground_truth"
PARTICLES = "world/particles"
SCAN = "world/scan"
ROBOT = "world/robot"
N_EFF = "metrics/n_eff"
MAX_WEIGHT = "metrics/max_weight"
SCANS_PER_S = "metrics/scans_per_s"

TIMELINES = ("scan", "time")
"""Timelines of every slam recording."""


def world_flip() -> rr.Transform3D:
    """Static transform of the ``world`` entity: +y up on screen."""
    return rr.Transform3D(mat3x3=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])


def history(
    *paths: str, timelines: tuple[str, ...] = TIMELINES
) -> dict[str, rrb.VisibleTimeRanges]:
    """Overrides that show everything logged at ``paths`` up to the time cursor on ``timelines``
    (name only timelines the recording has: the viewer shows nothing for an unknown one)."""
    ranges = rrb.VisibleTimeRanges(
        [
            rr.VisibleTimeRange(
                timeline,
                start=rr.TimeRangeBoundary.infinite(),
                end=rr.TimeRangeBoundary.cursor_relative(),
            )
            for timeline in timelines
        ]
    )
    return {f"/{path}": ranges for path in paths}


def whole_run() -> rrb.TimeAxis:
    """Time axis of a plot showing the whole run, not a window around the time cursor."""
    everything = rr.TimeRange(
        start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite()
    )
    return rrb.TimeAxis(view_range=everything)


def _panels(timeline: str) -> list:
    """Side panels collapsed; the time panel on ``timeline``, following the latest data."""
    return [
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=timeline, play_state="following"),
    ]


def run_blueprint() -> rrb.Blueprint:
    """``slam run``: map and texture tabs beside N_eff, max weight and scans/s."""
    map_view = rrb.Spatial2DView(
        name="map",
        origin="/",
        contents=["+ /world/**", f"- /{TEXTURE}"],
        overrides=history(TRAJECTORY),
    )
    texture_view = rrb.Spatial2DView(
        name="texture", origin="/", contents=[f"+ /{TEXTURE}", f"+ /{TRAJECTORY_FINAL}"]
    )
    series = rrb.Vertical(
        *(
            rrb.TimeSeriesView(name=name, origin=f"/{path}", axis_x=whole_run())
            for name, path in (
                ("N_eff", N_EFF),
                ("max weight", MAX_WEIGHT),
                ("scans/s", SCANS_PER_S),
            )
        )
    )
    layout = rrb.Horizontal(
        rrb.Tabs(map_view, texture_view, active_tab=0), series, column_shares=[3, 2]
    )
    return rrb.Blueprint(layout, *_panels("scan"))


def grid_blueprint() -> rrb.Blueprint:
    """``slam grid run``: the posterior heat map beside the probability of the best cell."""
    layout = rrb.Horizontal(
        rrb.Spatial2DView(name="posterior", origin="/grid"),
        rrb.TimeSeriesView(name="max probability", origin="/metrics", axis_x=whole_run()),
        column_shares=[3, 2],
    )
    return rrb.Blueprint(layout, *_panels("step"))


def maze_blueprint() -> rrb.Blueprint:
    """``slam maze run``: walls as known to the robot, its path, the true walls faintly."""
    layout = rrb.Horizontal(
        rrb.Spatial2DView(
            name="maze",
            origin="/",
            contents=["+ /maze/**"],
            overrides=history("maze/path/run0", "maze/path/run1", timelines=("step",)),
        ),
        rrb.TimeSeriesView(name="known sides", origin="/metrics", axis_x=whole_run()),
        column_shares=[3, 2],
    )
    return rrb.Blueprint(layout, *_panels("step"))

"""Maze robots: what they know of the walls, how they explore in run 0 and race in run 1.

Every robot here keeps a :class:`WallKnowledge` built from its (perfect) sensor readings, only
ever moves over sides it knows to be open (so it always knows where it is: a silent stop at a
wall cannot happen), and races run 1 on a step-optimal plan over known-open sides.

* ``explore-all`` (report baseline): flood fill, one cell per step, to the goal; then visits
  every cell it can still reach before resetting; run 1 is optimal on what it mapped.
* ``block-out`` (report baseline): flood fill, one cell per step, to the goal, resets at once,
  and plans run 1 through the cells it visited only (unvisited cells blocked out).
* ``bounded`` (ours): treats unknown sides as open, reaches the goal with moves of up to three
  cells, then keeps two bounds on run 1: the best *known* plan P (unknown sides closed) and the
  optimistic optimum O (unknown sides open). Only unknown sides on an optimistic path shorter
  than P are worth looking at; the robot goes to the pose whose sensors reveal the most valuable
  one, where value = run-1 steps it could save × 30 × ``payoff`` − steps to get there, and
  resets when no pose has positive value (or P = O): exploration that cannot pay stops. After
  the goal, sides the contest rules close (:func:`contest_walls`) do not count as possibly open.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from slam.errors import UsageError
from slam.maze import ROBOT_NAMES
from slam.maze.formats import DX, DY
from slam.maze.kernels import bfs_cells_unknown, edge_gain, observation_gain, reveal_count
from slam.maze.planner import (
    MAX_MOVE,
    Plan,
    Pose,
    apply_action,
    path_to,
    plan_run,
    pose_search,
    step_distances,
)
from slam.maze.referee import EXPLORATION_WEIGHT, RESET, Action, MazeInfo

UNKNOWN, WALL, OPEN = -1, 0, 1


class WallKnowledge:
    """What a robot knows about every cell side, and the step at which it learnt it.

    ``state[x, y, d]`` is -1 unknown, 0 wall, 1 open; both faces of a wall are kept in step.
    ``known_open`` and ``unknown`` are the same facts as bit masks (bit ``d`` per cell) for the
    kernels; the outer border is known (a wall) before the first step (step 0).
    """

    def __init__(self, width: int, height: int) -> None:
        self.width = width
        self.height = height
        self.state = np.full((width, height, 4), UNKNOWN, dtype=np.int8)
        self.known_at = np.full((width, height, 4), -1, dtype=np.int32)
        self.known_open = np.zeros((width, height), dtype=np.uint8)
        self.unknown = np.full((width, height), 15, dtype=np.uint8)
        for x in range(width):
            self.learn(x, 0, 2, False, 0)
            self.learn(x, height - 1, 0, False, 0)
        for y in range(height):
            self.learn(0, y, 3, False, 0)
            self.learn(width - 1, y, 1, False, 0)

    def learn(self, x: int, y: int, d: int, is_open: bool, step: int) -> None:
        """Record side ``d`` of ``(x, y)`` (and the neighbour's facing side) as open or wall."""
        if self.state[x, y, d] != UNKNOWN:
            return
        value = OPEN if is_open else WALL
        nx, ny, back = x + DX[d], y + DY[d], (d + 2) % 4
        faces = [(x, y, d)]
        if 0 <= nx < self.width and 0 <= ny < self.height:
            faces.append((nx, ny, back))
        for cx, cy, side in faces:
            self.state[cx, cy, side] = value
            self.known_at[cx, cy, side] = step
            self.unknown[cx, cy] &= np.uint8(~(1 << side) & 15)
            if is_open:
                self.known_open[cx, cy] |= np.uint8(1 << side)

    def integrate(self, pose: Pose, sensors: tuple[int, int, int], step: int) -> None:
        """Add the three readings taken at ``pose``: open cells up to a wall along each ray."""
        x0, y0, heading = pose
        for rel, reading in zip((-1, 0, 1), sensors, strict=True):
            d = (heading + rel) % 4
            x, y = x0, y0
            for _ in range(int(reading)):
                self.learn(x, y, d, True, step)
                x += DX[d]
                y += DY[d]
            self.learn(x, y, d, False, step)

    def optimistic(self) -> NDArray[np.uint8]:
        """Open mask with every unknown side assumed open."""
        return self.known_open | self.unknown

    def known_at_edges(self) -> dict[str, NDArray[np.int32]]:
        """Step at which each wall line became known: ``vertical`` and ``horizontal`` arrays.

        ``vertical[x, y]`` is the west side of column ``x`` (``x = width``: the east border),
        ``horizontal[x, y]`` the south side of row ``y`` (``y = height``: the north border).
        """
        vertical = np.full((self.width + 1, self.height), -1, dtype=np.int32)
        horizontal = np.full((self.width, self.height + 1), -1, dtype=np.int32)
        vertical[:-1, :] = self.known_at[:, :, 3]
        vertical[-1, :] = self.known_at[-1, :, 1]
        horizontal[:, :-1] = self.known_at[:, :, 2]
        horizontal[:, -1] = self.known_at[:, -1, 0]
        return {"vertical": vertical, "horizontal": horizontal}


class ExplorerRobot:
    """Common machinery: sensing, pose keeping, the reset, and the run-1 race on known sides."""

    name = "explorer"

    def __init__(self, info: MazeInfo) -> None:
        self.info = info
        self.knowledge = WallKnowledge(info.width, info.height)
        self.goal_mask = np.zeros((info.width, info.height), dtype=np.bool_)
        for x, y in info.goal:
            self.goal_mask[x, y] = True
        self.start_mask = np.zeros_like(self.goal_mask)
        self.start_mask[info.start] = True
        self.start_pose: Pose = (info.start[0], info.start[1], 0)
        self.pose: Pose = self.start_pose
        self.visited = self.start_mask.copy()
        self.run = 0
        self.step = 0
        self.hit_goal = False
        self.race: list[tuple[int, int]] = []

    # -- the tester interface
    def next_move(self, sensors: tuple[int, int, int]) -> Action:
        """Integrate the readings, then explore (run 0) or follow the race plan (run 1)."""
        self.step += 1
        self.knowledge.integrate(self.pose, sensors, self.step)
        if self.run == 0:
            action = self.explore()
            if action == RESET:
                self.run = 1
                self.pose = self.start_pose
                self.race = list(self.race_plan().actions)
                return RESET
        else:
            if not self.race:  # cannot happen with known-open plans; replan to stay safe
                plan = plan_run(self.knowledge.known_open, self.pose, self.goal_mask)
                self.race = list(plan.actions) if plan else [(90, 0)]
            action = self.race.pop(0)
        self.pose = apply_action(self.pose, *action)
        x, y, _ = self.pose
        self.visited[x, y] = True
        if self.goal_mask[x, y]:
            self.hit_goal = True
        return action

    # -- hooks
    def explore(self) -> Action:
        """The run-0 action for the current knowledge and pose (or :data:`RESET`)."""
        raise NotImplementedError

    def race_mask(self) -> NDArray[np.uint8]:
        """Open mask the run-1 plan may use (default: every side known to be open)."""
        return self.knowledge.known_open

    def race_plan(self) -> Plan:
        """Step-optimal run-1 plan from the start on :meth:`race_mask`."""
        plan = plan_run(self.race_mask(), self.start_pose, self.goal_mask)
        if plan is None:  # the robot reached the goal over known-open sides, so a plan exists
            raise RuntimeError("no known path from the start to the goal after reaching it")
        return plan

    # -- helpers
    def known_best(self) -> int:
        """Run-1 steps of the best plan on known-open sides (a large number if none)."""
        dist = step_distances(self.race_mask(), self.goal_mask)
        value = int(dist[self.info.start])
        return value if value >= 0 else 10**6

    def out_of_budget(self, best_known: int) -> bool:
        """Whether one more exploration step could leave too few steps for run 1."""
        return self.step + 1 + best_known > self.info.max_steps

    def safe(self, pose: Pose, direction: int, cells: int) -> bool:
        """Whether ``cells`` moves from ``pose`` along ``direction`` cross known-open sides only."""
        x, y, _ = pose
        for _ in range(cells):
            if not self.knowledge.known_open[x, y] >> direction & 1:
                return False
            x += DX[direction]
            y += DY[direction]
        return True


def contest_walls(
    known_open: NDArray[np.uint8],
    unknown: NDArray[np.uint8],
    goal: NDArray[np.bool_],
    goal_rim: NDArray[np.uint8],
    posts: bool = True,
) -> tuple[NDArray[np.uint8], bool]:
    """Unknown sides that the contest rules still allow to be open, and whether posts obey.

    Two rules of micromouse contests (most classic mazes are contest mazes):

    * *every post touches at least one wall* (the post in the middle of the goal excepted): at an
      inner post whose other three wall lines are known open, the fourth, unknown, is a wall;
    * *the goal has one entrance*: once a side between a goal cell and a non-goal cell
      (``goal_rim``, bit masks like ``unknown``) is known open, the unknown ones are walls.

    The second value is ``False`` when a post with four known-open lines is in sight: this maze
    breaks the post rule, and no wall is inferred from posts (nor with ``posts=False``).
    """
    out = unknown
    if (known_open & goal_rim).any():
        out = out & ~goal_rim
    if not posts:
        return out, True
    ko = known_open.astype(np.int16)
    un = out.astype(np.int16)
    # the four lines at inner post (i, j), arrays indexed [i - 1, j - 1]: west side of
    # (i, j - 1), west side of (i, j), south side of (i - 1, j), south side of (i, j)
    lines = ((1, 0, 3), (1, 1, 3), (0, 1, 2), (1, 1, 2))
    w, h = known_open.shape
    opens = [ko[sx : w - 1 + sx, sy : h - 1 + sy] >> b & 1 for sx, sy, b in lines]
    unks = [un[sx : w - 1 + sx, sy : h - 1 + sy] >> b & 1 for sx, sy, b in lines]
    centre = goal[:-1, :-1] & goal[1:, :-1] & goal[:-1, 1:] & goal[1:, 1:]
    n_open = sum(opens)
    if ((n_open == 4) & ~centre).any():
        return out, False
    hit = (n_open == 3) & (sum(unks) == 1) & ~centre
    if hit.any():
        out = out.copy()
        for (sx, sy, d), u in zip(lines, unks, strict=True):
            for i, j in np.argwhere(hit & (u == 1)):
                x, y = int(i) + sx, int(j) + sy
                out[x, y] &= np.uint8(~(1 << d) & 15)
                out[x + DX[d], y + DY[d]] &= np.uint8(~(1 << ((d + 2) % 4)) & 15)
    return out, True


def _actions(stride: int) -> list[tuple[int, int]]:
    """Candidate actions: moves of 1..stride cells forwards/backwards after each turn, and turns."""
    out = []
    for rotation in (0, 90, -90):
        for k in range(1, stride + 1):
            out.append((rotation, k))
            out.append((rotation, -k))
    out.extend([(90, 0), (-90, 0)])
    return out


class FloodFillRobot(ExplorerRobot):
    """The report's flood fill: one cell per step towards the lowest flood value."""

    def __init__(self, info: MazeInfo, explore_all: bool) -> None:
        super().__init__(info)
        self.explore_all = explore_all
        self.name = "explore-all" if explore_all else "block-out"

    def explore(self) -> Action:
        """Flood towards the goal; after it, towards unvisited cells (explore-all) or reset."""
        if not self.hit_goal:
            targets = self.goal_mask
        else:
            if not self.explore_all or self.out_of_budget(self.known_best()):
                return RESET
            targets = ~self.visited
        dist = step_distances(self.knowledge.optimistic(), targets, max_move=1)
        x, y, h = self.pose
        if dist[x, y] < 0:  # nothing left that can be reached
            return RESET
        best: tuple[int, int, int, int] | None = None
        # forward, right, left, back: ties keep the earlier (straight on first)
        for rel, rotation, movement in ((0, 0, 1), (1, 90, 1), (-1, -90, 1), (2, 0, -1)):
            d = (h + rel) % 4
            if self.knowledge.state[x, y, d] == WALL:
                continue
            value = int(dist[x + DX[d], y + DY[d]])
            if value >= 0 and (best is None or value < best[0]):
                best = (value, d, rotation, movement)
        assert best is not None  # dist[x, y] >= 0 implies an open or unknown side leads on
        _, d, rotation, movement = best
        if self.knowledge.state[x, y, d] == OPEN:
            return rotation, movement
        return 90, 0  # the side behind is unknown: turn to look at it

    def race_mask(self) -> NDArray[np.uint8]:
        """Block-out: only sides between two visited cells; explore-all: all known-open sides."""
        known = self.knowledge.known_open
        if self.explore_all:
            return known
        v = self.visited
        mask = np.zeros_like(known)
        w, h = v.shape
        both = np.zeros((w, h, 4), dtype=np.bool_)
        both[:, :-1, 0] = v[:, :-1] & v[:, 1:]
        both[:-1, :, 1] = v[:-1, :] & v[1:, :]
        both[:, 1:, 2] = v[:, 1:] & v[:, :-1]
        both[1:, :, 3] = v[1:, :] & v[:-1, :]
        for d in range(4):
            mask |= ((known >> d & 1).astype(np.bool_) & both[:, :, d]).astype(np.uint8) << d
        return mask


@dataclass(frozen=True)
class BoundedConfig:
    """Tunables of the ``bounded`` explorer (``payoff``, ``p_open`` tuned on the 521 classic mazes)."""

    exploration_weight: float = EXPLORATION_WEIGHT
    """Score of one run-0 step in run-1 steps (the tester's 1/30)."""
    payoff: float = 0.3
    """Fraction of a look's expected run-1 saving that may be spent, in steps × weight, on it."""
    p_open: float = 0.9
    """Chance that an uncertain move on a shortcut (other than the one looked at) is open."""
    stride: int = MAX_MOVE
    """Most cells moved in one exploration step (fewer cells see more side walls)."""
    contest_rules: bool = True
    """After the goal, take sides the contest rules close (:func:`contest_walls`) as walls."""

    def __post_init__(self) -> None:
        if not 0 < self.exploration_weight <= 1:
            raise UsageError(f"exploration_weight must be in (0, 1], got {self.exploration_weight}")
        if self.payoff < 0:
            raise UsageError(f"payoff must be >= 0, got {self.payoff}")
        if not 0 < self.p_open <= 1:
            raise UsageError(f"p_open must be in (0, 1], got {self.p_open}")
        if self.stride not in (1, 2, 3):
            raise UsageError(f"stride must be 1, 2 or 3, got {self.stride}")


class BoundedRobot(ExplorerRobot):
    """Ours: optimistic flood to the goal, then exploration only where it can still pay.

    Before the goal: the safe move (over known-open sides) that lowers the optimistic steps to
    the goal, preferring cells on short optimistic start-goal routes (what run 1 will need), then
    poses whose sensors see more unknown sides. After the goal, each step: P = best known run 1
    (unknown sides closed), O = optimistic optimum (unknown sides open); reset when P = O.
    Otherwise every unknown side gets the expected run-1 saving of the best shortcut through it
    (:func:`~slam.maze.kernels.edge_gain`), every reachable pose the best saving among the sides
    its sensors would reveal; a pose is worth visiting when saving × payoff / weight ≥ its
    distance in steps, and the robot heads for the worthwhile pose with the most saving per
    step. No worthwhile pose left: reset. After the goal, unknown sides that the contest rules
    close (:func:`contest_walls`) are left out of O and of the savings.
    """

    name = "bounded"

    def __init__(self, info: MazeInfo, config: BoundedConfig | None = None) -> None:
        super().__init__(info)
        self.config = config or BoundedConfig()
        self.candidates = _actions(self.config.stride)
        self.posts_rule = bool(self.config.contest_rules)  # until a post without walls is seen
        w, h = info.width, info.height
        self.goal_rim = np.zeros((w, h), dtype=np.uint8)
        for x, y in info.goal:
            for d in range(4):
                nx, ny = x + DX[d], y + DY[d]
                if 0 <= nx < w and 0 <= ny < h and not self.goal_mask[nx, ny]:
                    self.goal_rim[x, y] |= np.uint8(1 << d)
                    self.goal_rim[nx, ny] |= np.uint8(1 << ((d + 2) % 4))

    def explore(self) -> Action:
        """Head for the goal; once there, weigh each possible look against its detour."""
        kn = self.knowledge
        cfg = self.config
        if not self.hit_goal:
            optimistic = kn.optimistic()
            to_goal = step_distances(optimistic, self.goal_mask)
            through = step_distances(optimistic, self.start_mask) + to_goal
            # progress is counted in the robot's own steps, so a shorter stride still advances
            return self._towards(step_distances(optimistic, self.goal_mask, cfg.stride), through)
        unknown = self._possible()
        to_goal = step_distances(kn.known_open | unknown, self.goal_mask)
        best_known = self.known_best()
        optimum = int(to_goal[self.info.start])
        if best_known <= optimum or self.out_of_budget(best_known):
            return RESET
        from_start, unk_start = bfs_cells_unknown(kn.known_open, unknown, self.start_mask, MAX_MOVE)
        _, unk_goal = bfs_cells_unknown(kn.known_open, unknown, self.goal_mask, MAX_MOVE)
        gain = edge_gain(
            kn.known_open,
            unknown,
            from_start,
            unk_start,
            to_goal,
            unk_goal,
            best_known,
            MAX_MOVE,
            cfg.p_open,
        )
        look = observation_gain(kn.known_open, unknown, gain)
        dist, parent, action, _ = pose_search(kn.known_open, self.pose, max_move=cfg.stride)
        worth = (dist > 0) & (look > 0) & (look * (cfg.payoff / cfg.exploration_weight) >= dist)
        if not worth.any():
            return RESET
        rate = np.where(worth, look / np.maximum(dist, 1), -np.inf)
        ties = np.argwhere(rate == rate.max())
        target = min((int(dist[tuple(t)]), tuple(int(v) for v in t)) for t in ties)[1]
        return path_to(parent, action, target, self.info.height, cfg.stride).actions[0]

    def _possible(self) -> NDArray[np.uint8]:
        """Unknown sides that may still be open: all, or those the contest rules leave open.

        The post rule is dropped for good once the robot sees a post without walls.
        """
        kn = self.knowledge
        if not self.config.contest_rules:
            return kn.unknown
        args = (kn.known_open, kn.unknown, self.goal_mask, self.goal_rim)
        possible, posts_ok = contest_walls(*args, posts=self.posts_rule)
        if not posts_ok:
            self.posts_rule = False
            possible, _ = contest_walls(*args, posts=False)
        return possible

    def _towards(self, to_goal: NDArray[np.int32], through: NDArray[np.int32]) -> Action:
        """Safe move that lowers ``to_goal``; ties: smaller ``through``, then more to see.

        When no move over known-open sides makes progress (the side the optimistic plan needs
        is behind the robot, unseen), it turns on the spot to look.
        """
        kn = self.knowledge
        reveal = reveal_count(kn.known_open, kn.unknown)
        x, y, h = self.pose
        here = int(to_goal[x, y])
        best_key: tuple[int, int, int, int] | None = None
        best_action: tuple[int, int] | None = None
        for rotation, movement in self.candidates:
            nh = (h + rotation // 90) % 4
            nx, ny, _ = apply_action(self.pose, rotation, movement)
            if movement == 0:
                remaining, corridor = here, 0  # a turn makes no progress, it only looks
            else:
                d = nh if movement > 0 else (nh + 2) % 4
                if not self.safe(self.pose, d, abs(movement)):
                    continue
                remaining, corridor = int(to_goal[nx, ny]), int(through[nx, ny])
                if remaining < 0 or remaining >= here:
                    continue
            key = (remaining, corridor, -int(reveal[nx, ny, nh]), abs(movement))
            if best_key is None or key < best_key:
                best_key, best_action = key, (rotation, movement)
        assert best_action is not None  # the two turns are always candidates
        return best_action


ROBOTS: dict[str, Callable[[MazeInfo], ExplorerRobot]] = dict(
    zip(
        ROBOT_NAMES,  # "bounded", "explore-all", "block-out"
        (
            BoundedRobot,
            lambda info: FloodFillRobot(info, explore_all=True),
            lambda info: FloodFillRobot(info, explore_all=False),
        ),
        strict=True,
    )
)


def make_robot(name: str, info: MazeInfo, **options: float) -> ExplorerRobot:
    """A robot by name (see :data:`ROBOTS`); ``options`` set :class:`BoundedConfig` fields."""
    if name not in ROBOTS:
        raise UsageError(f"unknown maze robot {name!r}; expected one of {', '.join(ROBOTS)}")
    if options:
        if name != "bounded":
            raise UsageError(f"robot {name!r} takes no options, got {', '.join(options)}")
        known = {f.name for f in fields(BoundedConfig)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise UsageError(
                f"unknown option(s) {', '.join(unknown)} for robot 'bounded'; "
                f"expected {', '.join(sorted(known))}"
            )
        return BoundedRobot(info, BoundedConfig(**options))  # type: ignore[arg-type]
    return ROBOTS[name](info)

"""numba kernels of the maze planners: breadth-first searches and the exploration bookkeeping.

Mazes arrive as ``(width, height)`` uint8 open masks (bit ``d`` set when side ``d`` is open:
0 north, 1 east, 2 south, 3 west). A *step* is one Udacity action: turn by -90, 0 or +90 degrees,
then move up to ``max_move`` cells straight ahead (positive) or straight back (negative). Kernels
own the loops only; allocation of inputs, choice among results and all I/O stay in Python.

Pose states are indexed ``(x * height + y) * 4 + heading``; actions are coded
``(rotation_index) * (2 * max_move + 1) + (movement + max_move)`` with rotation index 0, 1, 2 for
-90, 0, +90 degrees.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_DX = np.array([0, 1, 0, -1], dtype=np.int64)
_DY = np.array([1, 0, -1, 0], dtype=np.int64)


@njit(cache=True)
def _seed_sources(source_mask):  # pragma: no cover - numba
    """Start of a multi-source cell search: ``(dist, queue, tail)`` with the sources at 0.

    ``dist`` is -1 elsewhere; the queue holds the ``tail`` source cells (``x * height + y``) in
    x-major order, with room for every cell.
    """
    width, height = source_mask.shape
    dist = np.full((width, height), -1, dtype=np.int32)
    queue = np.empty(width * height, dtype=np.int64)
    tail = 0
    for x in range(width):
        for y in range(height):
            if source_mask[x, y]:
                dist[x, y] = 0
                queue[tail] = x * height + y
                tail += 1
    return dist, queue, tail


@njit(cache=True)
def _ray_end(open_mask, x, y, d):  # pragma: no cover - numba
    """``(cx, cy, n)``: the cell where a ray from ``(x, y)`` along ``d`` over open sides of
    ``open_mask`` stops, and the number ``n`` of sides it crossed."""
    n = 0
    while (open_mask[x, y] >> d) & 1:
        x += _DX[d]
        y += _DY[d]
        n += 1
    return x, y, n


@njit(cache=True)
def bfs_cells(open_mask, source_mask, max_move):  # pragma: no cover - numba
    """Steps from the nearest source cell to every cell (-1: unreachable).

    A step moves 1..``max_move`` cells in a straight line in any of the four directions; heading
    never limits this (a turn and a move fit in one step, and backwards moves need no turn), and
    moves are reversible, so the same array is also the number of steps *to* the sources.
    """
    height = open_mask.shape[1]
    dist, queue, tail = _seed_sources(source_mask)
    head = 0
    while head < tail:
        cell = queue[head]
        head += 1
        x = cell // height
        y = cell % height
        d0 = dist[x, y]
        for d in range(4):
            cx = x
            cy = y
            for _ in range(max_move):
                if not (open_mask[cx, cy] >> d) & 1:
                    break
                cx += _DX[d]
                cy += _DY[d]
                if dist[cx, cy] < 0:
                    dist[cx, cy] = d0 + 1
                    queue[tail] = cx * height + cy
                    tail += 1
    return dist


@njit(cache=True)
def bfs_poses(open_mask, x0, y0, h0, max_move, stop_mask, early_stop):  # pragma: no cover
    """Breadth-first search over (cell, heading) from one pose with the Udacity actions.

    Returns ``(dist, parent, action, found)``: steps to every pose (-1 unreachable), the parent
    pose index and the action code that reached it, and the first pose whose cell is in
    ``stop_mask`` (-1 if none). With ``early_stop`` the search ends at that pose.
    """
    width, height = open_mask.shape
    n_states = width * height * 4
    span = 2 * max_move + 1
    dist = np.full(n_states, -1, dtype=np.int32)
    parent = np.full(n_states, -1, dtype=np.int64)
    action = np.full(n_states, -1, dtype=np.int32)
    queue = np.empty(n_states, dtype=np.int64)
    start = (x0 * height + y0) * 4 + h0
    dist[start] = 0
    queue[0] = start
    head = 0
    tail = 1
    found = -1
    if stop_mask[x0, y0]:
        return dist, parent, action, start
    while head < tail:
        state = queue[head]
        head += 1
        h = state % 4
        cell = state // 4
        x = cell // height
        y = cell % height
        d0 = dist[state]
        for ri in (1, 0, 2):  # no turn first: ties prefer going straight
            nh = (h + ri - 1) % 4
            if ri != 1:
                nstate = (x * height + y) * 4 + nh
                if dist[nstate] < 0:
                    dist[nstate] = d0 + 1
                    parent[nstate] = state
                    action[nstate] = ri * span + max_move
                    queue[tail] = nstate
                    tail += 1
                    if stop_mask[x, y] and found < 0:
                        found = nstate
            for sign in (1, -1):
                d = nh if sign > 0 else (nh + 2) % 4
                cx = x
                cy = y
                for k in range(1, max_move + 1):
                    if not (open_mask[cx, cy] >> d) & 1:
                        break
                    cx += _DX[d]
                    cy += _DY[d]
                    nstate = (cx * height + cy) * 4 + nh
                    if dist[nstate] < 0:
                        dist[nstate] = d0 + 1
                        parent[nstate] = state
                        action[nstate] = ri * span + max_move + sign * k
                        queue[tail] = nstate
                        tail += 1
                        if stop_mask[cx, cy] and found < 0:
                            found = nstate
            if early_stop and found >= 0:
                return dist, parent, action, found
    return dist, parent, action, found


@njit(cache=True)
def bfs_cells_unknown(open_mask, unknown_mask, source_mask, max_move):  # pragma: no cover
    """:func:`bfs_cells` on ``open_mask | unknown_mask``, plus the uncertain moves on the way.

    Returns ``(dist, uncertain)``: fewest steps from the sources and, among fewest-step paths,
    the fewest moves that cross at least one unknown side (one look along a move settles all
    its sides when they are open, so moves, not sides, are the units of doubt). Breadth-first
    search settles a level before expanding the next, so improving the count of a cell found
    on the current level is exact.
    """
    height = open_mask.shape[1]
    dist, queue, tail = _seed_sources(source_mask)
    unk = np.zeros(dist.shape, dtype=np.int32)
    head = 0
    while head < tail:
        cell = queue[head]
        head += 1
        x = cell // height
        y = cell % height
        d0 = dist[x, y]
        for d in range(4):
            cx = x
            cy = y
            u = unk[x, y]
            seen = False
            for _ in range(max_move):
                m = open_mask[cx, cy] | unknown_mask[cx, cy]
                if not (m >> d) & 1:
                    break
                if (unknown_mask[cx, cy] >> d) & 1 and not seen:
                    u += 1
                    seen = True
                cx += _DX[d]
                cy += _DY[d]
                if dist[cx, cy] < 0:
                    dist[cx, cy] = d0 + 1
                    unk[cx, cy] = u
                    queue[tail] = cx * height + cy
                    tail += 1
                elif dist[cx, cy] == d0 + 1 and u < unk[cx, cy]:
                    unk[cx, cy] = u
    return dist, unk


@njit(cache=True)
def edge_gain(
    open_mask, unknown_mask, from_start, unk_start, to_goal, unk_goal, best_known, max_move, p_open
):  # pragma: no cover - numba
    """Expected run-1 steps that learning each unknown side could save: ``(w, h, 4)`` float64.

    A straight move a -> b over open or unknown sides lies on a run-1 path of
    ``from_start[a] + 1 + to_goal[b]`` steps with ``u`` uncertain moves (fewest to a, this move,
    fewest from b; see :func:`bfs_cells_unknown`). Each unknown side of the move could save
    ``best_known`` minus that length, if the path is open: this move is the one being looked
    at, the other ``u - 1`` are each taken open with probability ``p_open``. A side keeps its
    best value; zero means it cannot shorten the best known run 1.
    """
    width, height = open_mask.shape
    gain = np.zeros((width, height, 4), dtype=np.float64)
    for x in range(width):
        for y in range(height):
            fa = from_start[x, y]
            if fa < 0:
                continue
            for d in range(4):
                cx = x
                cy = y
                u_move = 0
                for k in range(1, max_move + 1):
                    m = open_mask[cx, cy] | unknown_mask[cx, cy]
                    if not (m >> d) & 1:
                        break
                    if (unknown_mask[cx, cy] >> d) & 1:
                        u_move = 1
                    cx += _DX[d]
                    cy += _DY[d]
                    gb = to_goal[cx, cy]
                    if gb < 0 or u_move == 0:
                        continue
                    saving = best_known - (fa + 1 + gb)
                    if saving <= 0:
                        continue
                    u = unk_start[x, y] + u_move + unk_goal[cx, cy]
                    value = saving * p_open ** (u - 1)
                    px = x
                    py = y
                    for _ in range(k):
                        if (unknown_mask[px, py] >> d) & 1:
                            if gain[px, py, d] < value:
                                gain[px, py, d] = value
                            qx = px + _DX[d]
                            qy = py + _DY[d]
                            back = (d + 2) % 4
                            if gain[qx, qy, back] < value:
                                gain[qx, qy, back] = value
                        px += _DX[d]
                        py += _DY[d]
    return gain


@njit(cache=True)
def observation_gain(known_open_mask, unknown_mask, gain):  # pragma: no cover - numba
    """For every pose, the largest ``gain`` of an unknown side its three sensors would reveal.

    The left, front and right rays of pose (x, y, h) run over known-open sides; the first side
    that is not known open is revealed, and counts when it is unknown. ``(width, height, 4)``.
    """
    width, height = known_open_mask.shape
    value = np.zeros((width, height, 4), dtype=np.float64)
    for x in range(width):
        for y in range(height):
            for h in range(4):
                best = 0.0
                for rel in (-1, 0, 1):
                    d = (h + rel) % 4
                    cx, cy, _ = _ray_end(known_open_mask, x, y, d)
                    if (unknown_mask[cx, cy] >> d) & 1 and gain[cx, cy, d] > best:
                        best = gain[cx, cy, d]
                value[x, y, h] = best
    return value


@njit(cache=True)
def ray_lengths(open_mask):  # pragma: no cover - numba
    """Open cells from every cell to the nearest wall in each direction: ``(width, height, 4)``."""
    width, height = open_mask.shape
    out = np.zeros((width, height, 4), dtype=np.int32)
    for x in range(width):
        for y in range(height):
            for d in range(4):
                out[x, y, d] = _ray_end(open_mask, x, y, d)[2]
    return out


@njit(cache=True)
def reveal_count(known_open_mask, unknown_mask):  # pragma: no cover - numba
    """For every pose, how many of its three sensor rays would reveal an unknown side (0..3)."""
    width, height = known_open_mask.shape
    count = np.zeros((width, height, 4), dtype=np.int32)
    for x in range(width):
        for y in range(height):
            for h in range(4):
                n = 0
                for rel in (-1, 0, 1):
                    d = (h + rel) % 4
                    cx, cy, _ = _ray_end(known_open_mask, x, y, d)
                    if (unknown_mask[cx, cy] >> d) & 1:
                        n += 1
                count[x, y, h] = n
    return count

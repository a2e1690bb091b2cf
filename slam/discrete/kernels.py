"""numba kernels of the discrete filter: the (cell, heading) prediction in one pass.

The vectorised numpy prediction of :class:`~slam.discrete.motion.HeadingMotion` makes several
temporaries per heading (mask, shifted copy, sums); on a 1000×1000 world with 4 headings (32 MB
per belief) that traffic dominates. These kernels compute each output cell once, *gathering* from
its source cells, write into a caller-owned buffer and return the total in the same pass, so the
filter renormalises without another read. With ``weighted`` the kernels also multiply by the
likelihood ``p(z | cell)`` as they go: a whole predict + update cycle in one pass over the belief
(:meth:`~slam.discrete.filter.HistogramFilter.step`). No Python objects, no I/O, no randomness.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_DR = np.array([-1, 0, 1, 0], dtype=np.int64)
_DC = np.array([0, 1, 0, -1], dtype=np.int64)


@njit(cache=True)
def _finish_row(row: np.ndarray, likelihood_row: np.ndarray, weighted: bool) -> float:
    """Multiply a finished output row by its likelihoods (if ``weighted``); return its sum.

    Four partial sums break the dependency chain of one running total (a 25 % speed-up on a
    1000×1000×4 belief) and keep the result deterministic.
    """
    cols = row.shape[0]
    if weighted:
        for c in range(cols):
            row[c] *= likelihood_row[c]
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    c = 0
    while c + 4 <= cols:
        a0 += row[c]
        a1 += row[c + 1]
        a2 += row[c + 2]
        a3 += row[c + 3]
        c += 4
    while c < cols:
        a0 += row[c]
        c += 1
    return (a0 + a1) + (a2 + a3)


@njit(cache=True)
def heading_forward(
    belief: np.ndarray,
    can_move: np.ndarray,
    p_move: float,
    cyclic: bool,
    likelihood: np.ndarray,
    weighted: bool,
    out: np.ndarray,
) -> float:
    """``out[h] = (1 − p)·bel[h] + p·step(bel[h], h)``, bounce-back; return ``Σ out``.

    ``can_move[h, r, c]``: the neighbour of ``(r, c)`` in direction ``h`` is open. A cell keeps
    ``(1 − p)`` of its mass, plus ``p`` when it cannot move, and receives ``p`` of its source cell
    ``(r − dr, c − dc)`` when that one can move. With ``weighted``, every output cell is also
    multiplied by ``likelihood[r, c]``.
    """
    heads, rows, cols = belief.shape
    total = 0.0
    for h in range(heads):
        dr = _DR[h]
        dc = _DC[h]
        for r in range(rows):
            row = out[h, r]
            here = belief[h, r]
            here_moves = can_move[h, r]
            for c in range(cols):
                row[c] = here[c] - p_move * here_moves[c] * here[c]
            sr = r - dr
            if cyclic:
                sr = sr % rows
            if 0 <= sr < rows:
                src = belief[h, sr]
                src_moves = can_move[h, sr]
                for c in range(max(0, dc), cols + min(0, dc)):
                    row[c] += p_move * src_moves[c - dc] * src[c - dc]
                if cyclic and dc != 0:
                    c = 0 if dc > 0 else cols - 1
                    sc = (c - dc) % cols
                    row[c] += p_move * src_moves[sc] * src[sc]
            total += _finish_row(row, likelihood[r % likelihood.shape[0]], weighted)
    return total


@njit(cache=True)
def heading_turn(
    belief: np.ndarray,
    p_turn: float,
    turn: int,
    likelihood: np.ndarray,
    weighted: bool,
    out: np.ndarray,
) -> float:
    """``out[h] = (1 − p)·bel[h] + p·bel[h − turn]`` (turn −1: left, +1: right); return ``Σ out``.

    With ``weighted``, every output cell is also multiplied by ``likelihood[r, c]``.
    """
    heads, rows, cols = belief.shape
    stay = 1.0 - p_turn
    total = 0.0
    for h in range(heads):
        src = (h - turn) % heads
        for r in range(rows):
            row = out[h, r]
            here = belief[h, r]
            there = belief[src, r]
            for c in range(cols):
                row[c] = stay * here[c] + p_turn * there[c]
            total += _finish_row(row, likelihood[r % likelihood.shape[0]], weighted)
    return total

"""numba kernels of the simulator: grid ray casting, Kinect rendering and the path follower.

Kernels take arrays and scalars and return arrays; they draw no random numbers (sensor noise comes
in as arrays drawn by the Python layer from one seeded generator) and do no I/O, so a seed fixes
every output bit for any thread count.

Grids are ``labels[row, col]`` with row = y index and column = x index; cell ``(r, c)`` covers
``[ox + c·res, ox + (c+1)·res) × [oy + r·res, oy + (r+1)·res)``; label 0 is free floor, anything
else an obstacle (walls, furniture, pillars) extruded vertically from the floor to a common height.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_FAST = {"contract", "arcp", "afn", "reassoc"}
"""fastmath flags of the render kernels: fused multiply-adds and reciprocals, but infinities and
NaNs keep their IEEE meaning (the kernels use ``inf`` for "no hit")."""

# ------------------------------------------------------------------------------------ ray casting


@njit(cache=True, _nrt=False)
def first_hit(labels, gx, gy, dx, dy, max_cells):
    """Amanatides–Woo grid traversal from grid point ``(gx, gy)`` along the unit ``(dx, dy)``.

    Returns ``(distance in cells, side, label)`` of the first obstacle cell entered: ``side`` is 0
    when the ray enters it through a face of constant x, 1 through a face of constant y, -1 when it
    starts inside it; ``distance`` is ``inf`` (label 0) when nothing is hit within ``max_cells`` or
    the ray leaves the grid.
    """
    rows, cols = labels.shape
    ix = int(math.floor(gx))
    iy = int(math.floor(gy))
    if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
        return math.inf, -1, 0
    if labels[iy, ix] != 0:
        return 0.0, -1, int(labels[iy, ix])
    if dx > 0.0:
        step_x = 1
        t_max_x = (ix + 1.0 - gx) / dx
        t_delta_x = 1.0 / dx
    elif dx < 0.0:
        step_x = -1
        t_max_x = (gx - ix) / -dx
        t_delta_x = -1.0 / dx
    else:
        step_x = 0
        t_max_x = math.inf
        t_delta_x = math.inf
    if dy > 0.0:
        step_y = 1
        t_max_y = (iy + 1.0 - gy) / dy
        t_delta_y = 1.0 / dy
    elif dy < 0.0:
        step_y = -1
        t_max_y = (gy - iy) / -dy
        t_delta_y = -1.0 / dy
    else:
        step_y = 0
        t_max_y = math.inf
        t_delta_y = math.inf
    while True:
        if t_max_x < t_max_y:
            t = t_max_x
            ix += step_x
            t_max_x += t_delta_x
            side = 0
        else:
            t = t_max_y
            iy += step_y
            t_max_y += t_delta_y
            side = 1
        if t > max_cells or ix < 0 or iy < 0 or ix >= cols or iy >= rows:
            return math.inf, -1, 0
        lab = int(labels[iy, ix])
        if lab != 0:
            return t, side, lab


@njit(cache=True, parallel=True)
def cast_scans(labels, origin_x, origin_y, resolution, poses, angles, max_range):
    """Distances (m) from each sensor pose ``(N, 3)`` along each beam angle ``(B,)`` to the grid.

    Returns ``(ranges (N, B) float64, cos_incidence (N, B) float32)``: ``inf`` where no obstacle
    lies within ``max_range``; ``cos_incidence`` is |cos| of the angle between beam and surface
    normal (1 head-on, 0 grazing), 0 without a hit.
    """
    n = poses.shape[0]
    b = angles.shape[0]
    ranges = np.empty((n, b))
    incidence = np.zeros((n, b), dtype=np.float32)
    max_cells = max_range / resolution
    for k in prange(n):
        gx = (poses[k, 0] - origin_x) / resolution
        gy = (poses[k, 1] - origin_y) / resolution
        for m in range(b):
            a = poses[k, 2] + angles[m]
            dx = math.cos(a)
            dy = math.sin(a)
            dist, side, _lab = first_hit(labels, gx, gy, dx, dy, max_cells)
            ranges[k, m] = dist * resolution
            if side == 0:
                incidence[k, m] = abs(dx)
            elif side == 1:
                incidence[k, m] = abs(dy)
    return ranges, incidence


# ------------------------------------------------------------------------------ Kinect rendering


@njit(cache=True)
def _azimuth_table(labels, origin_x, origin_y, resolution, cam, ref, perp, t_min, t_step, n):
    """First obstacle along ``n`` horizontal directions ``ref + t·perp`` from the camera.

    Returns horizontal distances (m, ``inf`` for none), hit labels and sides.
    """
    dist = np.empty(n)
    lab = np.empty(n, dtype=np.uint8)
    side = np.empty(n, dtype=np.int8)
    gx = (cam[0] - origin_x) / resolution
    gy = (cam[1] - origin_y) / resolution
    max_cells = 60.0 / resolution
    for k in range(n):
        t = t_min + k * t_step
        dx = ref[0] + t * perp[0]
        dy = ref[1] + t * perp[1]
        norm = math.sqrt(dx * dx + dy * dy)
        dx /= norm
        dy /= norm
        d, s, lb = first_hit(labels, gx, gy, dx, dy, max_cells)
        dist[k] = d * resolution
        lab[k] = lb
        side[k] = s
    return dist, lab, side


@njit(cache=True, fastmath=_FAST, _nrt=False)
def _cast_ray(rx, ry, rz, cam, ref, perp, t_min, inv_step, dist, lab, side, height, near2):
    """Where the camera ray ``(rx, ry, rz)`` (world frame, optical z component 1) ends.

    ``near2`` is the squared distance of the nearest obstacle anywhere in this ray's azimuth
    range: a floor hit closer than that needs no table lookup. Returns ``(s, kind, side, label)``:
    ``s`` is the depth (optical z) of the hit, ``kind`` 0 for the floor, 1 for an obstacle face,
    -1 for nothing within range (``s`` = inf).
    """
    if rz < 0.0:
        s_floor = cam[2] / -rz
        if (rx * rx + ry * ry) * s_floor * s_floor < near2:
            return s_floor, 0, -1, 0
    along = rx * ref[0] + ry * ref[1]
    wall = math.inf
    wlab = 0
    wside = -1
    if along > 0.0:
        f = (rx * perp[0] + ry * perp[1]) / along
        f = (f - t_min) * inv_step
        n = dist.shape[0]
        if f < 0.0:
            f = 0.0
        if f > n - 1.0:
            f = n - 1.0
        k = int(f)
        if k >= n - 1:
            k = n - 2
        w = f - k
        d0 = dist[k]
        d1 = dist[k + 1]
        if lab[k] == lab[k + 1] and side[k] == side[k + 1] and abs(d1 - d0) < 0.25:
            wall = d0 + w * (d1 - d0)
            wlab = int(lab[k])
            wside = int(side[k])
        elif w < 0.5:
            wall = d0
            wlab = int(lab[k])
            wside = int(side[k])
        else:
            wall = d1
            wlab = int(lab[k + 1])
            wside = int(side[k + 1])
    rho = math.sqrt(rx * rx + ry * ry)
    # Floor first when the ray goes down and meets z = 0 before the obstacle's distance.
    if rz < 0.0 and cam[2] * rho <= wall * -rz:
        return cam[2] / -rz, 0, -1, 0
    if wall < math.inf and rho > 1e-12:
        s_wall = wall / rho
        if cam[2] + s_wall * rz <= height:
            return s_wall, 1, wside, wlab
    return math.inf, -1, -1, 0


@njit(cache=True, _nrt=False)
def _column_near2(bx, by, ux, uy, i_lo, i_hi, cy, fy, ref, perp, t_min, inv_step, dist):
    """Squared distance of the nearest table obstacle over a pixel column's azimuth range.

    The column's rays are ``(bx, by) + yn · (ux, uy)`` horizontally, ``yn = (i − cy)/fy`` for
    ``i`` in ``[i_lo, i_hi]``; their table index is monotonic in ``yn``, so the two ends bound it.
    """
    n = dist.shape[0]
    k_lo = n
    k_hi = -1
    for i in (i_lo, i_hi):
        yn = (i - cy) / fy
        rx = bx + ux * yn
        ry = by + uy * yn
        along = rx * ref[0] + ry * ref[1]
        if along <= 0.0:
            return 0.0
        f = ((rx * perp[0] + ry * perp[1]) / along - t_min) * inv_step
        k = int(f)
        k_lo = min(k_lo, k - 1)
        k_hi = max(k_hi, k + 2)
    k_lo = max(k_lo, 0)
    k_hi = min(k_hi, n - 1)
    near = math.inf
    for k in range(k_lo, k_hi + 1):
        near = min(near, dist[k])
    return near * near


@njit(cache=True)
def _camera_table(labels, origin_x, origin_y, resolution, rot, cam, fx, fy, cx, cy, i_lo, i_hi,
                  j_lo, j_hi, n):  # fmt: skip
    """Horizontal reference frame and azimuth table covering pixels ``[i_lo, i_hi] × [j_lo, j_hi]``.

    Directions are spaced uniformly in ``t = tan(azimuth − azimuth of the optical axis)``, so a
    pixel finds its entry with one division and no trigonometry.
    """
    ax = rot[0, 2]
    ay = rot[1, 2]
    na = math.sqrt(ax * ax + ay * ay)
    ref = np.array([ax / na, ay / na])
    perp = np.array([-ref[1], ref[0]])
    t_lo = math.inf
    t_hi = -math.inf
    steps = 16
    for e in range(4 * steps + 1):
        # Walk the border of the pixel rectangle.
        q = e / steps
        if q <= 1.0:
            i = i_lo
            j = j_lo + q * (j_hi - j_lo)
        elif q <= 2.0:
            i = i_lo + (q - 1.0) * (i_hi - i_lo)
            j = j_hi
        elif q <= 3.0:
            i = i_hi
            j = j_hi - (q - 2.0) * (j_hi - j_lo)
        else:
            i = i_hi - (q - 3.0) * (i_hi - i_lo)
            j = j_lo
        xn = (j - cx) / fx
        yn = (i - cy) / fy
        rx = rot[0, 0] * xn + rot[0, 1] * yn + rot[0, 2]
        ry = rot[1, 0] * xn + rot[1, 1] * yn + rot[1, 2]
        along = rx * ref[0] + ry * ref[1]
        if along > 1e-6:
            t = (rx * perp[0] + ry * perp[1]) / along
            t_lo = min(t_lo, t)
            t_hi = max(t_hi, t)
    margin = 0.01 * (t_hi - t_lo) + 1e-6
    t_lo -= margin
    t_hi += margin
    t_step = (t_hi - t_lo) / (n - 1)
    dist, lab, side = _azimuth_table(
        labels, origin_x, origin_y, resolution, cam, ref, perp, t_lo, t_step, n
    )
    return ref, perp, t_lo, 1.0 / t_step, dist, lab, side


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def render_disparity(labels, origin_x, origin_y, resolution, rot, cam, intr, disp, height, n_az,
                     noise, noise_offset, noise_sigma, holes, hole_offset, hole_prob):  # fmt: skip
    """Render one uint16 disparity image ``(H, W)`` from a camera pose.

    ``rot`` (3×3) maps optical-frame rays to the world, ``cam`` is the camera position (z above the
    floor). ``intr`` = ``(fx, fy, cx, cy, H, W)``; ``disp`` = ``(scale, offset, numerator, min
    depth, max depth, invalid value)``. Continuous disparity gets ``noise_sigma · noise[...]``
    (standard normals read from ``noise_offset`` on; the table must hold ``H·W`` values past it)
    before rounding; a pixel becomes a hole when ``holes[hole_offset + ...]`` (uniforms) is below
    ``hole_prob``. Returns ``(disparity uint16 (H, W), depth float64 (H, W) before coding,
    kind int8 (H, W))`` with kind 0 floor, 1 obstacle, -1 nothing.
    """
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    h = int(intr[4])
    w = int(intr[5])
    ref, perp, t_min, inv_step, dist, lab, side = _camera_table(
        labels, origin_x, origin_y, resolution, rot, cam, fx, fy, cx, cy, 0.0, h - 1.0, 0.0,
        w - 1.0, n_az,
    )  # fmt: skip
    # Ray = column part + row part (+ optical axis): precomputed once per column and per row.
    col_x = np.empty(w)
    col_y = np.empty(w)
    col_z = np.empty(w)
    col_near2 = np.empty(w)
    for j in range(w):
        xn = (j - cx) / fx
        col_x[j] = rot[0, 0] * xn + rot[0, 2]
        col_y[j] = rot[1, 0] * xn + rot[1, 2]
        col_z[j] = rot[2, 0] * xn + rot[2, 2]
        col_near2[j] = _column_near2(
            col_x[j], col_y[j], rot[0, 1], rot[1, 1], 0.0, h - 1.0, cy, fy, ref, perp, t_min,
            inv_step, dist,
        )  # fmt: skip
    out = np.empty((h, w), dtype=np.uint16)
    depth = np.empty((h, w))
    kind = np.empty((h, w), dtype=np.int8)
    scale, offset, numer = disp[0], disp[1], disp[2]
    d_min, d_max, invalid = disp[3], disp[4], int(disp[5])
    use_noise = noise_sigma != 0.0
    use_holes = hole_prob > 0.0
    for i in prange(h):
        yn = (i - cy) / fy
        row_x = rot[0, 1] * yn
        row_y = rot[1, 1] * yn
        row_z = rot[2, 1] * yn
        for j in range(w):
            s, kd, _sd, _lb = _cast_ray(
                col_x[j] + row_x, col_y[j] + row_y, col_z[j] + row_z, cam, ref, perp, t_min,
                inv_step, dist, lab, side, height, col_near2[j],
            )  # fmt: skip
            depth[i, j] = s
            kind[i, j] = kd
            idx = i * w + j
            if kd < 0 or s < d_min or s > d_max:
                out[i, j] = invalid
                continue
            if use_holes and holes[hole_offset + idx] < hole_prob:
                out[i, j] = invalid
                continue
            d = (numer / s - offset) / scale
            if use_noise:
                d += noise_sigma * noise[noise_offset + idx]
            v = int(math.floor(d + 0.5))
            if v < 0:
                v = 0
            out[i, j] = v
    return out, depth, kind


@njit(cache=True, nogil=True, parallel=True, fastmath=_FAST)
def render_rgb(labels, origin_x, origin_y, resolution, rot, cam, intr, align, texture, tex_origin_x,
               tex_origin_y, tex_resolution, outside_color, label_colors, height, n_az, gain,
               noise, noise_offset, noise_sigma):  # fmt: skip
    """Render one RGB image ``(H, W, 3)`` uint8 consistent with the course's RGB alignment.

    RGB pixel ``(ri, rj)`` shows the surface seen by depth-camera pixel ``(i, j)`` with
    ``rj = (g·j + c_j)/n`` and ``ri = (g·i + c_i − k·dd(i, j))/n`` (``align`` = ``(g, c_i, k, c_j,
    n, depth numerator)``); ``i`` solves that equation by fixed-point iteration down the depth
    column (a contraction: ``dd`` changes by < 0.01 per row on the floor). Floor points take the
    nearest texel of ``texture``; obstacle faces take ``label_colors[label]``, darker on faces of
    constant y. Colours are multiplied by ``gain`` and get ``noise_sigma · noise[...]`` (standard
    normals read from ``noise_offset`` on; the table must hold ``3·H·W`` values past it).

    Long because it is the per-pixel inner loop of the simulator's camera (about 300 000 pixels a
    frame): the fixed-point search for ``i``, the ray cast and the shading share the pixel's
    registers; the pieces that stand alone (:func:`_camera_table`, :func:`_cast_ray`) are
    already separate kernels.
    """
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    h = int(intr[4])
    w = int(intr[5])
    g, c_i, k_dd, c_j, nrm, numer = align[0], align[1], align[2], align[3], align[4], align[5]
    # Depth pixels needed: rows for dd in [0, 3] and the columns of the RGB image.
    i_lo = (-c_i) / g - 1.0
    i_hi = (nrm * (h - 1.0) - c_i + k_dd * 3.0) / g + 1.0
    j_lo = (-c_j) / g - 1.0
    j_hi = (nrm * (w - 1.0) - c_j) / g + 1.0
    ref, perp, t_min, inv_step, dist, lab, side = _camera_table(
        labels, origin_x, origin_y, resolution, rot, cam, fx, fy, cx, cy, i_lo, i_hi, j_lo,
        j_hi, n_az,
    )  # fmt: skip
    out = np.empty((h, w, 3), dtype=np.uint8)
    th, tw = texture.shape[0], texture.shape[1]
    inv_tex = 1.0 / tex_resolution
    use_noise = noise_sigma != 0.0
    for rj in prange(w):
        j = (nrm * rj - c_j) / g
        xn = (j - cx) / fx
        base_x = rot[0, 0] * xn + rot[0, 2]
        base_y = rot[1, 0] * xn + rot[1, 2]
        base_z = rot[2, 0] * xn + rot[2, 2]
        near2 = _column_near2(
            base_x, base_y, rot[0, 1], rot[1, 1], i_lo, i_hi, cy, fy, ref, perp, t_min, inv_step,
            dist,
        )  # fmt: skip
        dd = 0.5
        dd_prev = 0.5
        for ri in range(h):
            base = nrm * ri - c_i
            # Guess dd by extrapolating the two previous rows (smooth surfaces: one cast suffices).
            guess = 2.0 * dd - dd_prev
            if abs(dd - dd_prev) > 0.05 or guess <= 0.0:
                guess = dd
            dd_prev = dd
            i = (base + k_dd * guess) / g
            s = math.inf
            kd = -1
            sd = -1
            lb = 0
            rx = 0.0
            ry = 0.0
            for _it in range(6):
                yn = (i - cy) / fy
                rx = base_x + rot[0, 1] * yn
                ry = base_y + rot[1, 1] * yn
                rz = base_z + rot[2, 1] * yn
                s, kd, sd, lb = _cast_ray(
                    rx, ry, rz, cam, ref, perp, t_min, inv_step, dist, lab, side, height, near2
                )
                dd_new = numer / s if kd >= 0 else 0.0
                i_new = (base + k_dd * dd_new) / g
                step = abs(i_new - i)
                dd = dd_new
                if step < 0.02:
                    break
                i = i_new
            r = outside_color[0]
            gg = outside_color[1]
            b = outside_color[2]
            if kd == 0:
                tc = int(math.floor((cam[0] + s * rx - tex_origin_x) * inv_tex))
                tr = int(math.floor((cam[1] + s * ry - tex_origin_y) * inv_tex))
                if 0 <= tr < th and 0 <= tc < tw:
                    r = texture[tr, tc, 0]
                    gg = texture[tr, tc, 1]
                    b = texture[tr, tc, 2]
            elif kd == 1:
                shade = 0.82 if sd == 1 else 1.0
                r = label_colors[lb, 0] * shade
                gg = label_colors[lb, 1] * shade
                b = label_colors[lb, 2] * shade
            cr = r * gain
            cg = gg * gain
            cb = b * gain
            if use_noise:
                idx = noise_offset + 3 * (ri * w + rj)
                cr += noise_sigma * noise[idx]
                cg += noise_sigma * noise[idx + 1]
                cb += noise_sigma * noise[idx + 2]
            out[ri, rj, 0] = min(255, max(0, int(math.floor(cr + 0.5))))
            out[ri, rj, 1] = min(255, max(0, int(math.floor(cg + 0.5))))
            out[ri, rj, 2] = min(255, max(0, int(math.floor(cb + 0.5))))
    return out


# --------------------------------------------------------------------------------- path follower


@njit(cache=True)
def follow_path(path, arc, speed_ref, dt, steps, start_steps, lookahead0, lookahead_gain,
                max_omega, max_alpha, max_accel, max_decel, tau):  # fmt: skip
    """Drive a unicycle along the reference polyline ``path (M, 2)`` with pure pursuit.

    ``arc (M,)`` is the cumulative length along the path and ``speed_ref (M,)`` the speed allowed
    at each point (already limited by curvature and braking distance, 0 at the end). The robot
    starts on ``path[0]`` facing ``path[1]``, waits ``start_steps`` steps, then follows the path;
    the commands pass through first-order drive dynamics (time constant ``tau`` s, which keeps
    ``v`` and ``ω`` smooth: no chatter above the IMU's Nyquist rate) and rate limits
    (``max_accel``/``max_decel`` m/s², ``max_alpha`` rad/s²). The look-ahead point is interpolated
    along the path, so commands do not jump from one path sample to the next. Each step holds
    ``(v, ω)`` constant and integrates the exact arc.

    Returns ``(poses (steps+1, 3) with unwrapped heading, v (steps,), omega (steps,),
    progress (steps+1,) arc length of the closest path point)``.

    Long because it is one numba time loop whose state (pose, filtered and commanded ``v``/``ω``,
    the closest path index, the look-ahead point) carries from step to step: split into
    functions, each step would pass a dozen scalars back and forth.
    """
    m = path.shape[0]
    poses = np.zeros((steps + 1, 3))
    v_out = np.zeros(steps)
    w_out = np.zeros(steps)
    progress = np.zeros(steps + 1)
    x = path[0, 0]
    y = path[0, 1]
    th = math.atan2(path[1, 1] - path[0, 1], path[1, 0] - path[0, 0])
    poses[0, 0] = x
    poses[0, 1] = y
    poses[0, 2] = th
    v = 0.0
    w = 0.0
    v_f = 0.0
    w_f = 0.0
    gain = dt / (tau + dt) if tau > 0.0 else 1.0
    idx = 0
    done = False
    for k in range(steps):
        # Closest path point, searched forward from the last one (progress is monotone).
        best = idx
        bd = (path[idx, 0] - x) ** 2 + (path[idx, 1] - y) ** 2
        q = idx + 1
        while q < m and arc[q] - arc[idx] < 1.0:
            d2 = (path[q, 0] - x) ** 2 + (path[q, 1] - y) ** 2
            if d2 < bd:
                bd = d2
                best = q
            q += 1
        idx = best
        if k < start_steps or done:
            v_cmd = 0.0
            w_cmd = 0.0
        else:
            look = lookahead0 + lookahead_gain * v
            target = idx
            while target < m - 1 and arc[target] - arc[idx] < look:
                target += 1
            px = path[target, 0]
            py = path[target, 1]
            if target > idx and arc[target] - arc[idx] > look:
                # Interpolate between the two samples around the look-ahead distance.
                seg = arc[target] - arc[target - 1]
                u = (arc[target] - arc[idx] - look) / seg if seg > 0.0 else 0.0
                px = path[target, 0] - u * (path[target, 0] - path[target - 1, 0])
                py = path[target, 1] - u * (path[target, 1] - path[target - 1, 1])
            tx = px - x
            ty = py - y
            alpha = math.atan2(ty, tx) - th
            alpha = math.atan2(math.sin(alpha), math.cos(alpha))
            dist_t = math.sqrt(tx * tx + ty * ty)
            v_cmd = speed_ref[idx] * max(0.0, math.cos(alpha)) ** 2
            if idx >= m - 1 or (arc[m - 1] - arc[idx] < 0.01 and v < 0.05):
                done = True
                v_cmd = 0.0
            if dist_t > 1e-6:
                # Pure pursuit curvature 2 sin(α)/L at the current (not commanded) speed; a turn
                # in place when the target lies far off the heading.
                curv = 2.0 * math.sin(alpha) / max(dist_t, 1e-3)
                w_cmd = max(v, 0.15) * curv
            else:
                w_cmd = 0.0
            if done:
                w_cmd = 0.0
        # Drive dynamics (first-order lag), then rate limits: v and ω stay smooth.
        v_f += gain * (v_cmd - v_f)
        w_f += gain * (w_cmd - w_f)
        v_cmd = v_f
        w_cmd = w_f
        dv = v_cmd - v
        if dv > max_accel * dt:
            dv = max_accel * dt
        if dv < -max_decel * dt:
            dv = -max_decel * dt
        v += dv
        if w_cmd > max_omega:
            w_cmd = max_omega
        if w_cmd < -max_omega:
            w_cmd = -max_omega
        dw = w_cmd - w
        if dw > max_alpha * dt:
            dw = max_alpha * dt
        if dw < -max_alpha * dt:
            dw = -max_alpha * dt
        w += dw
        if v < 0.0:
            v = 0.0
        # Exact arc with constant (v, w) over dt.
        half = 0.5 * w * dt
        chord = v * dt * (math.sin(half) / half if abs(half) > 1e-12 else 1.0)
        x += chord * math.cos(th + half)
        y += chord * math.sin(th + half)
        th += w * dt
        v_out[k] = v
        w_out[k] = w
        poses[k + 1, 0] = x
        poses[k + 1, 1] = y
        poses[k + 1, 2] = th
        progress[k + 1] = arc[idx]
    return poses, v_out, w_out, progress

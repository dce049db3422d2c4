"""Numba kernels of the tracker's update (:meth:`~.tracker.Tracker.update`; the steps are
described in :mod:`.tracker`): the frames and measurements of every track–detection pair and their
gated costs, the assignment in two rounds, the correction and sizing of matched tracks, tracks
hidden behind others, and the confirmation and dropping of tracks.

They change the tracks' arrays in place. ``tracks`` is a :class:`~.tracker.TrackArrays` (a named
tuple of the tracker's arrays), ``det`` the scan's :class:`~.detection.Detections` (contiguous
arrays), ``prm`` the settings (:class:`~.tracker.TrackerParams`'s fields as a named tuple): named
tuples of plain arrays keep the signatures short; no kernel sees a class with behaviour."""

from __future__ import annotations

import math

import numpy as np

from ..._jit import inline_kernel, kernel
from ...geometry._kernels import wrap_angle_one
from . import _kernels as K
from .ekf import pose_innovation_one, update_one

TENTATIVE, CONFIRMED = 0, 1
#: Tracks shorter than this (m) are taken as round objects (people), longer ones as vehicles.
MIN_VEHICLE_LENGTH = 1.0
#: A line of returns at least this long (m) gives a direction.
MIN_FACE_LENGTH = 1.0
#: Durations (s) closer than this are equal: stamps of ROS time (about 1.7·10⁹ s) are float64s
#: 2.4·10⁻⁷ s apart, and a gap of three 0.1 s scans comes out as 0.3 ± 10⁻⁷ s.
STAMP_TOLERANCE = 1e-6


@inline_kernel
def _nearest_axis(box_heading, heading):
    """The direction among ``box_heading + k·π/2`` nearest to ``heading`` (radians)."""
    return box_heading + 0.5 * math.pi * np.rint((heading - box_heading) / (0.5 * math.pi))


@inline_kernel
def _directed(det, j):
    """Whether detection ``j``'s box has a direction: L-shaped, or a face at least
    :data:`MIN_FACE_LENGTH` long (its direction is the object's side or its end)."""
    return det.oriented[j] or det.length[j] >= MIN_FACE_LENGTH


@inline_kernel
def _occluded(det, j):
    """Whether an end of detection ``j`` is cut (its extent may be cut short)."""
    return det.cut[j, 0] or det.cut[j, 1]


@inline_kernel
def _bare_end(det, j, out):
    """Into ``out`` (2,): the bare end of detection ``j`` when its view is cut at its other end
    (the object's own edge, whatever hides the rest: :func:`~._kernels.measure_boxes` measures
    the centre from it), else NaN."""
    b0, b1 = det.bare[j, 0], det.bare[j, 1]
    if b0 != b1 and det.cut[j, 0] != det.cut[j, 1]:
        e = 0 if b0 else 1
        out[0], out[1] = det.ends[j, e, 0], det.ends[j, e, 1]
    else:
        out[0] = out[1] = np.nan


@inline_kernel
def _frame(axes, size, heading, length, width, cx, cy, sx, sy, box_heading, directed):
    """Into ``axes`` (2, 2) (rows) and ``size`` (2,): the axes in which a detection centred at
    ``(cx, cy)`` is measured for a track of ``heading`` and size ``(length, width)``, and the
    size along them. A vehicle (length ≥ :data:`MIN_VEHICLE_LENGTH`) is measured along its
    length and its side: the axes of a ``directed`` detection's box (``box_heading``, the one of
    its axes nearest to the track's heading), else the track's own (a track's heading must not
    place the centre that corrects the heading); a smaller object, taken as round, along the line
    of sight from the sensor at ``(sx, sy)`` and across it, its size the largest seen."""
    if length < MIN_VEHICLE_LENGTH:
        dx, dy = cx - sx, cy - sy
        r = max(np.hypot(dx, dy), 1e-9)
        ux, uy = dx / r, dy / r
        axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1] = ux, uy, -uy, ux
        size[0] = size[1] = max(length, width)
    else:
        along = _nearest_axis(box_heading, heading) if directed else heading
        c, s = np.cos(along), np.sin(along)
        axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1] = c, s, -s, c
        size[0], size[1] = length, width


@kernel
def next_scan(tracks):
    """A new scan: the hit bits and the whole views' centres of the last scans move back one."""
    for i in range(tracks.hit_bits.shape[0]):
        tracks.hit_bits[i] = tracks.hit_bits[i] << 1
        for k in range(tracks.centres.shape[1] - 1, 0, -1):
            tracks.centres[i, k] = tracks.centres[i, k - 1]
        tracks.centres[i, 0] = np.nan


@kernel
def measure_pairs(tracks, det, sx, sy, time, prm, centre, covariance, lever, cost):
    """Steps 2 and 3's gate for ``n`` tracks and ``m`` detections seen from ``(sx, sy)`` at
    ``time``: for pair ``p = i·m + j`` the centre ``centre[p]`` (2) detection ``j`` says track
    ``i`` has, its covariance ``covariance[p]`` (2, 2) and ``lever[p]`` (2)
    (:func:`~._kernels.measure_boxes`, in the frames of :func:`_frame`; the bare end of a cut
    view only for tracks moving at ``min_moving_speed`` or faster: slower ones may be walls that
    pose errors shift); ``cost`` (n, m) as :func:`~._kernels.gate_costs` gives it, a track seen
    once spread by a third of the way it may have gone since at ``max_speed`` (it has no
    velocity yet)."""
    n, m = cost.shape
    pairs = n * m
    corners = K.box_corners(det.x, det.y, det.heading, det.length, det.width, np.empty((m, 4, 2)))
    pair_corners = np.empty((pairs, 4, 2))
    axes = np.empty((pairs, 2, 2))
    size = np.empty((pairs, 2))
    occluded = np.empty(pairs, np.bool_)
    track = np.empty((pairs, 2))
    bare = np.empty((pairs, 2))
    for i in range(n):
        fast = tracks.state[i, 3] >= prm.min_moving_speed
        for j in range(m):
            p = i * m + j
            pair_corners[p] = corners[j]
            _frame(axes[p], size[p], tracks.state[i, 2], tracks.size[i, 0], tracks.size[i, 1], det.x[j], det.y[j],
                   sx, sy, det.heading[j], _directed(det, j))
            occluded[p] = _occluded(det, j)
            track[p, 0] = tracks.state[i, 0]
            track[p, 1] = tracks.state[i, 1]
            if fast:
                _bare_end(det, j, bare[p])
            else:
                bare[p, 0] = bare[p, 1] = np.nan
    K.measure_boxes(pair_corners, axes, size, sx, sy, occluded, track, bare, prm.position_sigma ** 2, centre,
                    covariance, np.empty((pairs, 2)), np.empty((pairs, 2)), lever)
    reach = np.zeros(n)
    for i in range(n):
        if tracks.updates[i] == 0:
            reach[i] = (prm.max_speed * (time - tracks.last_hit[i]) / 3.0) ** 2
    K.gate_costs(tracks.state, tracks.cov, reach, centre.reshape((n, m, 2)), covariance.reshape((n, m, 2, 2)),
                 prm.gate, cost)
    return cost


@kernel
def assign_rounds(cost, confirmed, rows, cols):
    """Step 3's assignment of the gated ``cost`` (n, m): the ``confirmed`` tracks (n,) choose
    first, the others share the detections left. Pairs into ``rows``, ``cols`` (room for
    ``min(n, m)``); returns their number."""
    n, m = cost.shape
    first = np.flatnonzero(confirmed)
    rest = np.flatnonzero(~confirmed)
    k = K.gated_assignment(cost[first], rows, cols)
    for q in range(k):
        rows[q] = first[rows[q]]
    taken = np.zeros(m, np.bool_)
    taken[cols[:k]] = True
    free = np.flatnonzero(~taken)
    sub = np.empty((rest.shape[0], free.shape[0]))
    for a in range(rest.shape[0]):
        for b in range(free.shape[0]):
            sub[a, b] = cost[rest[a], free[b]]
    k2 = K.gated_assignment(sub, rows[k:], cols[k:])
    for q in range(k, k + k2):
        rows[q] = rest[rows[q]]
        cols[q] = free[cols[q]]
    return k + k2


@kernel
def correct(tracks, det, rows, cols, centre, covariance, lever, time, prm, has_velocity):
    """Update the matched tracks ``rows`` with detections ``cols`` (their pairs' ``centre``,
    ``covariance`` and ``lever`` from :func:`measure_pairs`) at ``time``; ``has_velocity`` (k,):
    whether each track has a velocity now.

    A track without a velocity yet (seen once, or only since its last restart) waits for
    ``init_span`` seconds or ``init_distance`` metres of motion from the view it started from
    and takes its velocity from that displacement: of the box's centre between whole views
    (not cut: a cut box's centre moves with the occluder, not with the object); when a view is
    cut, of an end bare in both views (a point of the object, whatever hides the other) if it
    moved at ``min_moving_speed`` or faster — a vehicle coming out from behind something; a
    slower one may be a wall that pose errors shift. Any other view restarts the wait there; no
    velocity comes from views of one stamp (a log's stamps held where they went backwards). An
    L-shaped box knows the heading better than two noisy centres: its axis nearest to the
    displacement's direction is taken.

    A track with a velocity gets an EKF update (:func:`~.ekf.pose_innovation_one`): a vehicle
    seen without a direction of its own is measured in the track's axes, at the point of its box
    that placed the centre (an edge, a corner), so that the track's heading does not place the
    centre that corrects it (a directed box places it in its own axes; a round object's lever
    follows the line of sight, not its heading); a vehicle's directed box, from its third update
    on, measures its heading too (the box axis nearest to the track's)."""
    m = det.x.shape[0]
    var_p = prm.position_sigma ** 2
    z = np.empty(3)
    y2, H2, R2 = np.empty(2), np.empty((2, 5)), np.empty((2, 2))
    y3, H3, R3 = np.empty(3), np.empty((3, 5)), np.zeros((3, 3))
    R3[2, 2] = prm.heading_sigma ** 2
    for q in range(rows.shape[0]):
        r, c = rows[q], cols[q]
        p = r * m + c
        hx, hy = det.x[c], det.y[c]
        occluded = _occluded(det, c)
        waiting = False
        if tracks.updates[r] == 0:
            whole = not occluded and tracks.birth_whole[r]
            kept0 = det.bare[c, 0] and tracks.birth_bare[r, 0]  # ends bare in both views
            kept1 = det.bare[c, 1] and tracks.birth_bare[r, 1]
            end = 1 if kept1 and not kept0 else 0
            if whole:
                dx, dy = hx - tracks.birth[r, 0], hy - tracks.birth[r, 1]
            else:
                dx = det.ends[c, end, 0] - tracks.birth_ends[r, end, 0]
                dy = det.ends[c, end, 1] - tracks.birth_ends[r, end, 1]
            elapsed = time - tracks.born[r]
            dist = np.hypot(dx, dy)
            fast = dist >= prm.min_moving_speed * max(elapsed, 1e-9)
            restart = not (whole or ((kept0 or kept1) and fast))
            ready = (not restart and elapsed > STAMP_TOLERANCE
                     and (elapsed >= prm.init_span or dist >= prm.init_distance))
            waiting = not ready
            if waiting:
                tracks.state[r, 0], tracks.state[r, 1], tracks.state[r, 2] = hx, hy, det.heading[c]
                tracks.state[r, 3] = tracks.state[r, 4] = 0.0
                tracks.size[r, 0] = min(det.length[c], prm.max_size[0])
                tracks.size[r, 1] = min(det.width[c], prm.max_size[1])
            if restart:
                tracks.birth[r, 0], tracks.birth[r, 1] = hx, hy
                tracks.born[r] = time
                tracks.birth_ends[r] = det.ends[c]
                tracks.birth_bare[r] = det.bare[c]
                tracks.birth_whole[r] = not occluded
            if ready:
                heading = np.arctan2(dy, dx)
                oriented = det.oriented[c]
                tracks.state[r, 2] = wrap_angle_one(_nearest_axis(det.heading[c], heading)) if oriented else heading
                tracks.state[r, 0], tracks.state[r, 1] = hx, hy
                tracks.state[r, 3] = dist / elapsed
                tracks.state[r, 4] = 0.0
                P = tracks.cov[r]
                P[:, :] = 0.0
                P[0, 0] = P[1, 1] = var_p
                P[2, 2] = (prm.heading_sigma ** 2 if oriented
                           else min(2.0 * var_p / max(dist, 1e-9) ** 2, (math.pi / 2) ** 2))
                P[3, 3] = 2.0 * var_p / elapsed ** 2 + (prm.accel * elapsed) ** 2
                P[4, 4] = prm.initial_yaw_rate_sigma ** 2
        else:
            s = tracks.state[r]
            vehicle = tracks.size[r, 0] >= MIN_VEHICLE_LENGTH
            directed = _directed(det, c)
            lx = ly = 0.0
            if vehicle and s[3] >= prm.min_moving_speed and not directed:
                lx, ly = lever[p, 0], lever[p, 1]
            z[0], z[1] = centre[p, 0] + lx, centre[p, 1] + ly
            z[2] = _nearest_axis(det.heading[c], s[2])
            ct, st = np.cos(s[2]), np.sin(s[2])
            ox, oy = ct * lx + st * ly, -st * lx + ct * ly  # the lever in the object's frame
            if directed and tracks.updates[r] >= 2 and vehicle:
                pose_innovation_one(s, z, ox, oy, y3, H3)
                R3[:2, :2] = covariance[p]
                update_one(s, tracks.cov[r], y3, H3, R3)
            else:
                pose_innovation_one(s, z, ox, oy, y2, H2)
                R2[:, :] = covariance[p]
                update_one(s, tracks.cov[r], y2, H2, R2)
        has_velocity[q] = not waiting
        if not waiting:
            tracks.updates[r] += 1
        tracks.last_hit[r] = time
        tracks.hit_bits[r] |= 1
        if not occluded:
            tracks.centres[r, 0, 0], tracks.centres[r, 0, 1], tracks.centres[r, 0, 2] = hx, hy, time
        tracks.travel[r] = max(tracks.travel[r], np.hypot(tracks.state[r, 0] - tracks.birth[r, 0],
                                                          tracks.state[r, 1] - tracks.birth[r, 1]))
    return has_velocity


@kernel
def resize(tracks, det, rows, cols, sx, sy, prm):
    """After an update: sizes grow to the largest extent seen along the measuring axes of the
    updated heading (capped; a round object stays round; an object moving at
    ``min_moving_speed`` or faster — a vehicle, however little of it shows — is measured in its
    own axes and taken as at least ``vehicle_size`` until seen whole), and the face seen stays
    where it is: along an axis measured from one edge the centre moves away from it by half the
    growth. Sizes grow only from whole views (a box an occluder cuts may hold the occluder's
    returns), a vehicle's only in settled axes (heading sigma within
    ``settled_heading_sigma``: a box measured in a wrong heading looks wider). A track at its
    second detection has just got its heading: its size is what is seen now along it, its centre
    measured anew (a vehicle's from its bare end when the view is cut at the other: measured as
    a whole view, the cut end nearer to the sensor along that axis would be taken for the
    vehicle's; on the simulated street a car turning in beside parked cars, seen from behind,
    started 2.4 m ahead of itself, lost its speed and was dropped)."""
    k = rows.shape[0]
    corners = K.box_corners(det.x, det.y, det.heading, det.length, det.width, np.empty((det.x.shape[0], 4, 2)))
    pair_corners = np.empty((k, 4, 2))
    axes = np.empty((k, 2, 2))
    size = np.empty((k, 2))
    first = np.empty(k, np.bool_)
    car = np.empty(k, np.bool_)
    for q in range(k):
        r, c = rows[q], cols[q]
        first[q] = tracks.updates[r] == 1
        length, width = (0.0, 0.0) if first[q] else (tracks.size[r, 0], tracks.size[r, 1])
        car[q] = tracks.state[r, 3] >= prm.min_moving_speed  # measured in its own axes, at least a car's size
        if car[q]:
            length, width = max(length, prm.vehicle_size[0]), max(width, prm.vehicle_size[1])
        _frame(axes[q], size[q], tracks.state[r, 2], length, width, det.x[c], det.y[c], sx, sy, det.heading[c],
               _directed(det, c))
        pair_corners[q] = corners[c]
    none = np.empty((0, 2))
    seen, side = np.empty((k, 2)), np.empty((k, 2))
    K.measure_boxes(pair_corners, axes, size, sx, sy, np.zeros(k, np.bool_), none, none, prm.position_sigma ** 2,
                    np.empty((k, 2)), np.empty((k, 2, 2)), seen, side, np.empty((k, 2)))
    grown = np.empty((k, 2))
    for q in range(k):
        r, c = rows[q], cols[q]
        small = size[q, 0] < MIN_VEHICLE_LENGTH
        settled = not _occluded(det, c) and (small or (det.oriented[c] and tracks.cov[r, 2, 2]
                                                        <= prm.settled_heading_sigma ** 2))
        for a in range(2):
            grown[q, a] = max(size[q, a], seen[q, a]) if settled or first[q] else size[q, a]
        if small:
            grown[q, 0] = grown[q, 1] = max(grown[q, 0], grown[q, 1])
        for a in range(2):
            if car[q]:
                grown[q, a] = max(grown[q, a], prm.vehicle_size[a]) if settled else prm.vehicle_size[a]
            grown[q, a] = min(grown[q, a], prm.max_size[a])
        w0 = side[q, 0] * 0.5 * (grown[q, 0] - size[q, 0])
        w1 = side[q, 1] * 0.5 * (grown[q, 1] - size[q, 1])
        tracks.state[r, 0] += w0 * axes[q, 0, 0] + w1 * axes[q, 1, 0]
        tracks.state[r, 1] += w0 * axes[q, 0, 1] + w1 * axes[q, 1, 1]
        tracks.size[r, 0], tracks.size[r, 1] = grown[q, 0], grown[q, 1]
    anew = np.flatnonzero(first)
    if anew.shape[0]:
        bare = np.empty((anew.shape[0], 2))
        cut = np.empty(anew.shape[0], np.bool_)
        for a in range(anew.shape[0]):
            q = anew[a]
            if car[q]:
                _bare_end(det, cols[q], bare[a])
            else:
                bare[a, 0] = bare[a, 1] = np.nan
            cut[a] = np.isfinite(bare[a, 0])
        centre = np.empty((anew.shape[0], 2))
        K.measure_boxes(pair_corners[anew], axes[anew], grown[anew], sx, sy, cut, none, bare,
                        prm.position_sigma ** 2, centre, np.empty((anew.shape[0], 2, 2)), np.empty((anew.shape[0], 2)),
                        np.empty((anew.shape[0], 2)), np.empty((anew.shape[0], 2)))
        for a in range(anew.shape[0]):
            r = rows[anew[a]]
            tracks.state[r, 0], tracks.state[r, 1] = centre[a, 0], centre[a, 1]


@kernel
def count_hidden(tracks, missed, sx, sy):
    """Tracks ``missed`` (bool (n,)) by this scan whose centre lies behind a confirmed track's
    box (its corners span the centre's bearing, within a half-turn of it, and its centre is
    nearer), seen from ``(sx, sy)``, count the scan as a hit: a car hidden by another passing
    nearer is no evidence that it is not there. On the simulated street a car waited, its speed
    known, for new hits after three scans behind a nearer car. Tentative tracks hide nothing:
    wall fragments hiding each other confirmed more tracks (the raw Intel run at 0.05 m: 63
    instead of 61)."""
    n = missed.shape[0]
    if n < 2:
        return
    corners = np.empty((n, 4, 2))  # each box's corners and centre's range, from the sensor
    ranges = np.empty(n)
    for k in range(n):
        c, s = np.cos(tracks.state[k, 2]), np.sin(tracks.state[k, 2])
        for e in range(4):
            x, y = K.corner(tracks.state[k, 0], tracks.state[k, 1], c, s, tracks.size[k, 0], tracks.size[k, 1], e)
            corners[k, e, 0], corners[k, e, 1] = x - sx, y - sy
        ranges[k] = np.hypot(tracks.state[k, 0] - sx, tracks.state[k, 1] - sy)
    for i in range(n):
        if not missed[i]:
            continue
        dx, dy = tracks.state[i, 0] - sx, tracks.state[i, 1] - sy
        for k in range(n):
            if k == i or tracks.status[k] != CONFIRMED or not ranges[k] < ranges[i]:
                continue
            lo, hi, wide = np.inf, -np.inf, 0.0
            for e in range(4):  # bearings of the corners relative to the direction of the centre
                cx, cy = corners[k, e, 0], corners[k, e, 1]
                rel = np.arctan2(dy * cx - dx * cy, dx * cx + dy * cy)
                lo, hi, wide = min(lo, rel), max(hi, rel), max(wide, abs(rel))
            if lo < 0.0 < hi and wide < 0.5 * math.pi:
                tracks.hit_bits[i] |= 1
                break


@inline_kernel
def _measured_speed_known(tracks, i, prm):
    """Whether a round object's (a person's) own measurements say its velocity is known to
    ``confirm_speed_sigma`` (see :meth:`~.tracker.Tracker.update`'s confirmation). A straight
    line is fitted to the centres of its whole views (no end cut) in each of the last
    ``confirm_window`` scans; it says so when

    - the fitted velocity's standard error, from the fit's own residuals (m per axis, floored
      at ``centre_sigma_floor``), is within ``confirm_speed_sigma``;
    - the fitted velocity differs from the filter's by no more than that;
    - the motion is significant at the gate's confidence by both estimates (``|v|² ≥ gate ·
      se²`` for the fitted and the filter's speed), and both are at least ``walking_speed``
      (slow walking; on the raw Intel run a wall fragment that pose errors shift drifted at
      0.5 m/s, steadily enough for that test);
    - the filter's speed sigma, scaled by ``centre_sigma_floor / position_sigma`` (what it
      would be had it been fed these views at their own noise), is within it too.

    Measured on the simulated street, whole views' centres are off by 0.055 m (rms per axis,
    cars and people alike), cut views' by up to 0.36 m across: the filter's ``position_sigma``
    (0.15 m) is set for the worst, so its speed sigma reaches ``confirm_speed_sigma`` only
    after 5 – 7 updates however clean the views. Vehicles keep the filter's test: their
    early speed errors (1 – 3 m/s rms in their first 5 updates, a box seen end-on or cut) are
    larger than their covariance says, and the wait hides them."""
    views = tracks.centres[i]
    window = views.shape[0]
    if tracks.size[i, 0] >= MIN_VEHICLE_LENGTH:
        return False
    n = 0
    tm = xm = ym = 0.0
    for k in range(window):
        if np.isfinite(views[k, 0]):
            n += 1
            tm += views[k, 2]
            xm += views[k, 0]
            ym += views[k, 1]
    if n < window:
        return False
    tm, xm, ym = tm / n, xm / n, ym / n
    stt = sxt = syt = 0.0
    for k in range(window):
        dt = views[k, 2] - tm
        stt += dt * dt
        sxt += dt * (views[k, 0] - xm)
        syt += dt * (views[k, 1] - ym)
    fx, fy = sxt / max(stt, 1e-12), syt / max(stt, 1e-12)
    sq = 0.0
    for k in range(window):
        dt = views[k, 2] - tm
        ex = views[k, 0] - xm - dt * fx
        ey = views[k, 1] - ym - dt * fy
        sq += ex * ex + ey * ey
    var = max(sq / max(2 * (n - 2), 1), prm.centre_sigma_floor ** 2)
    se = np.sqrt(var / max(stt, 1e-12))
    v, heading = tracks.state[i, 3], tracks.state[i, 2]
    agree = np.hypot(v * np.cos(heading) - fx, v * np.sin(heading) - fy) <= prm.confirm_speed_sigma
    slower = min(fx * fx + fy * fy, v * v)
    moving = slower >= prm.gate * se * se and slower >= prm.walking_speed ** 2
    # the filter, fed these views at their own noise, would know the speed that much better
    filtered = (np.sqrt(tracks.cov[i, 3, 3]) * prm.centre_sigma_floor / prm.position_sigma
                <= prm.confirm_speed_sigma)
    return se <= prm.confirm_speed_sigma and agree and moving and filtered


@kernel
def confirm_and_drop(tracks, time, prm, lost):
    """Step 4's bookkeeping at ``time``: tentative tracks detected in ``confirm_hits`` of the last
    ``confirm_window`` scans, moved ``min_travel`` from where they started, updated twice, moving
    at ``confirm_speed`` or more with their speed known to ``confirm_speed_sigma`` (by the filter's
    covariance or, for a person, by :func:`_measured_speed_known`) are confirmed; ``lost`` (n,)
    marks the tracks to drop: not detected for ``max_coast`` seconds (``tentative_coast`` while
    tentative), or with a position standard deviation over ``max_position_sigma``. Returns how
    many were confirmed."""
    window = (1 << prm.confirm_window) - 1
    promoted = 0
    for i in range(lost.shape[0]):
        if tracks.status[i] == TENTATIVE:
            bits = tracks.hit_bits[i] & window
            hits = 0
            while bits:
                hits += bits & 1
                bits >>= 1
            if (hits >= prm.confirm_hits and tracks.travel[i] >= prm.min_travel and tracks.updates[i] >= 2
                    and tracks.state[i, 3] >= prm.confirm_speed
                    and (tracks.cov[i, 3, 3] <= prm.confirm_speed_sigma ** 2 or _measured_speed_known(tracks, i, prm))):
                tracks.status[i] = CONFIRMED
                promoted += 1
        limit = prm.max_coast if tracks.status[i] == CONFIRMED else prm.tentative_coast
        lost[i] = (time - tracks.last_hit[i] > limit + STAMP_TOLERANCE
                   or np.sqrt(tracks.cov[i, 0, 0] + tracks.cov[i, 1, 1]) > prm.max_position_sigma)
    return promoted

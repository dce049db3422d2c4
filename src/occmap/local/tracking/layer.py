"""The moving-object layer of a local map: which returns moving objects explain, their tracks, and
where they will be.

Per scan (:meth:`ObjectLayer.sort_returns`) a return is taken as *moving* when its cell and its
neighbours are known free in the static layer and no cell within ``open_margin`` of it known
occupied (something stands where the map has seen through, away from walls), when it falls on a
confirmed track's footprint predicted to the scan (grown by ``cover_margin``) with no cell within
``open_margin`` known occupied (a track explains its object, not the wall or door frame it passes),
when its cell has
never been seen and it lies within ``vacated_reach`` of a vacated cell or of the last scan's moving
returns in such cells (an object that stood when first seen walks on inside its own shadow: the
cells it stood on, first seen by a hit in the last ``vacated_within`` seconds, are then seen
through — the map knows something left them), or when it belongs to a small cluster of returns
mostly moving and its cell is not known occupied (the part of an object in cells not seen yet).
Moving returns do not mark the static layer — their rays still clear it up to them — so a moving
object leaves no trail; they are clustered into detections (:mod:`.detection`) that update the
tracks (:mod:`.tracker`). Returns in unknown cells away from tracks and vacated cells are static: a
parked car stays in the map.

Where objects will be (:meth:`ObjectLayer.occupancy`): every confirmed track (lost ones too, while
they coast) predicted with its covariance to the time asked; per cell the probability that its
centre lies under the object's footprint (:func:`~._kernels.footprint_probability`). Cells at
``threshold`` or above are obstacles of the costmap at that time (:meth:`ObjectLayer.lethal`), as
are the moving returns of the last scan that no confirmed track explains (they stay where they
were seen); cells an object may cover with less probability cost in proportion (below lethal).
"""

from __future__ import annotations

import math

import numpy as np

from ... import checks
from ...errors import ShapeError
from . import _kernels as K
from .detection import DETECTION_GAP, Detections, detect_objects
from .tracker import Tracker, TrackerParams

__all__ = ["ObjectLayer"]


class ObjectLayer:
    """Tracks of moving objects for a local map (see the module's description).

    Parameters
    ----------
    params : TrackerParams or None
        The tracker's settings.
    cover_margin : float
        Metres around a track's predicted footprint within which returns are the object's.
    threshold : float
        Probability from which a cell under a predicted object is an obstacle.
    open_margin : float
        Metres around a return's cell in which no cell may be known occupied for the return to be
        moving (walls that grazing rays clear, or that pose errors shift, are not).
    vacated_within : float
        Seconds for which a static return on a cell seen for the first time is watched for being
        vacated (0: never; objects present from the start stay static while in their shadow).
    vacated_reach : float
        Metres from a vacated cell within which returns in cells never seen are moving.
    """

    def __init__(self, params: TrackerParams | None = None, cover_margin: float = 0.2, threshold: float = 0.5,
                 open_margin: float = 0.2, vacated_within: float = 2.0, vacated_reach: float = 1.0):
        self.tracker = Tracker(params)
        self.cover_margin = checks.non_negative("cover_margin", cover_margin, "metres")
        self.open_margin = checks.non_negative("open_margin", open_margin, "metres")
        self.threshold = checks.probability("threshold", threshold)
        self.vacated_within = checks.non_negative("vacated_within", vacated_within, "seconds")
        self.vacated_reach = checks.positive("vacated_reach", vacated_reach, "metres")
        self.moving = np.empty((0, 2))
        self._hits = np.empty((0, 2))  # static returns on cells seen for the first time, and when
        self._hit_stamps = np.empty(0)
        self._shadowed = np.empty((0, 2))  # the last scan's moving returns in cells never seen
        self.stats = {"moving_returns": 0}
        self._grid = np.zeros((3, 0, 0), np.int32)  # promote_components' scratch, zero between scans

    def recent_hits(self, stamp: float) -> np.ndarray:
        """The static returns of the last ``vacated_within`` seconds before ``stamp`` whose cell had
        never been seen (``(M, 2)``, world): the cells a map should watch for being vacated."""
        keep = self._hit_stamps >= stamp - self.vacated_within
        self._hits, self._hit_stamps = self._hits[keep], self._hit_stamps[keep]
        return self._hits

    def sort_returns(self, ends: np.ndarray, kinds: np.ndarray, known_free: np.ndarray, known_occupied: np.ndarray,
                     sensor, stamp: float, max_range: float | None = None, grid=None, vacated=None,
                     unseen=None, walled=None, layers=None) -> None:
        """Take one scan: returns (``kinds == 1``) at ``ends`` (N, 2) that are moving become
        clearing rays (``kinds`` set to 2, in place); the tracks move to ``stamp``.
        ``known_free`` and ``known_occupied`` (N,) say which ends lie in cells the static layer
        holds free (and open around) or occupied, ``unseen`` (N,) which lie in cells never seen;
        ``vacated`` ``(M, 2)`` are the points of :meth:`recent_hits` whose cells the map has since
        seen through; ``grid`` ``(origin, resolution, (H, W))`` is the map's window, in which the
        returns are joined into objects; ``layers`` (N,) the elevation layers of a 3D scanner's
        returns (:func:`~.detection.elevation_layers`; None: a planar scan)."""
        hit = np.flatnonzero(kinds == 1)
        pts = ends.take(hit, axis=0)  # rows by take: NumPy's fancy indexing of rows costs 15x more
        moving = known_free[hit]
        blocked = np.ascontiguousarray(known_occupied[hit])
        if len(self.tracker) and len(pts):
            # a track explains the returns on its footprint, not those on or beside mapped structure
            # (within open_margin of a known occupied cell, as for open returns: a wall a person
            # passes, a cell off after a registration slip). Taken as the track's, they were cleared
            # instead of marked and held it confirmed on the wall with no return in open space:
            # Freiburg 079 (corrected and raw) and raw Intel confirmed tracks on walls, door frames
            # and cubicles that way (tests/local/test_tracking_structure.py)
            near_wall = blocked if walled is None else walled[hit]
            moving = moving | (self.tracker.covers(pts, stamp, self.cover_margin, confirmed_only=True) & ~near_wall)
        shadow = np.zeros(len(pts), bool) if unseen is None else unseen[hit]
        clear = shadow if walled is None else shadow & ~walled[hit]
        # an object standing when first seen, then walking on inside its own shadow: its returns
        # lie in cells never seen, but just past cells an earlier scan hit and later scans saw
        # through (vacated: something moved off them), or, away from occupied cells, near the last
        # scan's moving returns in such cells (the object walks on; it marks no cells to vacate)
        for seeds, where in ((vacated, shadow), (self._shadowed, clear)):
            if seeds is not None and len(seeds) and len(pts):
                near = np.empty(len(pts), np.bool_)
                K.near_any(pts, np.ascontiguousarray(seeds, dtype=np.float64), self.vacated_reach, near)
                moving = moving | (near & where)
        if moving.any() and grid is not None:
            # an object moving into cells the map has not seen free yet (away from the sensor,
            # out of its own shadow) is one object, not a moving part and a static one; returns
            # in cells known occupied (a wall a person passes) stay static
            origin, resolution, (H, W) = grid
            if self._grid.shape != (3, H, W):
                self._grid = np.zeros((3, H, W), np.int32)
            promoted = np.empty(len(pts), np.bool_)
            K.promote_components(pts, moving, blocked, float(origin[0]), float(origin[1]), float(resolution),
                                 int(math.ceil(0.5 * DETECTION_GAP / resolution - 1e-9)),
                                 float(np.hypot(*self.tracker.params.max_size)), self._grid, promoted)
            moving |= promoted
        new = pts.compress(~moving & shadow, axis=0)  # static returns on cells seen for the first time: watch them
        if len(new) and grid is not None:  # one per cell (a cloud puts many in one)
            cell = np.floor((new - grid[0]) / grid[1]).astype(np.int64)
            new = new[np.unique(cell[:, 1] * grid[2][1] + cell[:, 0], return_index=True)[1]]
        self._hits = np.concatenate([self._hits, new])
        self._hit_stamps = np.concatenate([self._hit_stamps, np.full(len(new), float(stamp))])
        kinds[hit[moving]] = 2
        self.moving = pts.compress(moving, axis=0)
        self._shadowed = pts.compress(moving & shadow, axis=0)
        self.stats["moving_returns"] += int(moving.sum())
        sensor = np.asarray(sensor, dtype=np.float64)[:2]
        hit_layers = None if layers is None else np.asarray(layers).take(hit)
        self.tracker.update(stamp, detect_objects(self.moving, sensor=sensor, scene=pts, max_range=max_range,
                                                  layers=None if layers is None else hit_layers.compress(moving),
                                                  scene_layers=hit_layers), sensor)

    def pass_over(self, stamp: float, sensor) -> None:
        """Take a scan in which nothing can be told to move (its pose does not fit the static
        layer): no return is moving, the tracks move to ``stamp`` without detections."""
        self.moving = np.empty((0, 2))
        self._shadowed = np.empty((0, 2))
        self.tracker.update(stamp, Detections.empty(), np.asarray(sensor, dtype=np.float64)[:2])

    def counts(self) -> dict:
        """Running counts: returns taken as moving, tracks started, confirmed and dropped."""
        t = self.tracker.stats
        return {"moving_returns": self.stats["moving_returns"], "tracks_started": t["tracks_started"],
                "tracks_confirmed": t["tracks_confirmed"], "tracks_dropped": t["tracks_dropped"]}

    def occupancy(self, at: float, origin, resolution: float, shape) -> np.ndarray:
        """Probability (float32 (H, W), row 0 at ``origin``) that each cell's centre lies under a
        confirmed object at time ``at`` (seconds, not before the last scan)."""
        _, states, covs, sizes = self.tracker.predicted(at)
        out = np.zeros(shape, dtype=np.float64)
        if len(states):
            K.footprint_probability(states, covs, sizes, 0.0, float(origin[0]), float(origin[1]), float(resolution),
                                    out)
        return out.astype(np.float32)

    def lethal(self, at: float | None, origin, resolution: float, shape):
        """``(lethal, cost)`` of moving objects at time ``at``: obstacle cells (bool (H, W)) where
        the predicted occupancy reaches ``threshold`` and where the last scan's moving returns no
        confirmed track explains lie; and Nav2 costs (uint8 (H, W)) below lethal for the cells an
        object may cover, ``252 · p / threshold`` for occupancy ``p`` from 0.05 up (none for
        ``at=None``: the returns alone)."""
        if at is None:
            out, cost = np.zeros(shape, bool), np.zeros(shape, np.uint8)
        else:
            out, cost = np.empty(shape, bool), np.empty(shape, np.uint8)
            K.occupancy_costs(self.occupancy(at, origin, resolution, shape), self.threshold, out, cost)
        pts = self.moving
        if len(pts):
            ids, states, covs, sizes = self.tracker.predicted(self.tracker.time)
            if len(ids):
                inside = np.zeros(len(pts))
                K.point_probability(pts, np.zeros(len(pts), np.int64), states[None], covs[None], sizes,
                                    self.cover_margin, inside)
                pts = pts.compress(inside < 0.5, axis=0)
            cells = np.floor((pts - np.asarray(origin)) / resolution).astype(np.int64)
            H, W = shape
            ok = (cells[:, 0] >= 0) & (cells[:, 0] < W) & (cells[:, 1] >= 0) & (cells[:, 1] < H)
            out[cells[ok, 1], cells[ok, 0]] = True
        return out, cost

    def path_probability(self, points, stamps, radius: float) -> np.ndarray:
        """Probability (N,) that a disc of ``radius`` m at each world point ``(N, 2)`` meets a
        confirmed object at the point's time ``stamps`` (N,) (seconds, not before the last scan)."""
        p = np.ascontiguousarray(points, dtype=np.float64)
        t = np.asarray(stamps, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2 or t.shape != (p.shape[0],):
            raise ShapeError(f"points (N, 2) and stamps (N,) must match, got {p.shape} and {t.shape}")
        _, states, covs, sizes = self.tracker.predicted(t)
        out = np.zeros(len(p))
        if sizes.shape[0]:
            K.point_probability(p, np.arange(len(p)), np.ascontiguousarray(states), np.ascontiguousarray(covs), sizes,
                                checks.non_negative("radius", radius, "metres"), out)
        return out

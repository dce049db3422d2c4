"""A 2D mapping run recorded scan by scan, to watch the map grow in the viewer
(``occmap map2d LOG -o MAP.yaml --record run.npz``, then ``occmap view run.npz``).

A recording holds, per scan: its stamp and the sensor pose ``(x, y, theta)`` it was inserted at
(metres, radians, map frame); and the grid as it grew, in deltas: every ``every`` scans (and after
the last one), the cells whose nav_msgs value (int8: −1 unknown, 0 free … 100 occupied) changed
since the previous delta, as flat indices into the final map (row-major, row 0 along the lowest
y) with their new values. Applying every delta to an all-unknown final map gives the map
``occmap map2d`` writes, value for value. Its size is the changes (5 bytes each while recording):
the Freiburg 079 log (4,791 scans, 5 cm, 3863 × 3485 cells, 480 states) makes 31.6 M changes and
a 57.0 MB file; Intel (910 scans) 6.5 M and 11.3 MB (docs/viewer.md).

On disk it is a recording file (:mod:`occmap._recordings`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _recordings, checks
from ._recording_kernels import changed_log_odds
from .errors import FormatError, InvalidArgumentError
from .grid2d.grid import beam_points, scan_arrays
from .logodds import occupancy_values

#: The ``format`` entry of a mapping recording file, and its version.
FORMAT = "occmap mapping recording"
VERSION = 1
#: Scans between two deltas by default.
EVERY = 10
#: Deltas between two states :meth:`MappingRecording.occupancy_at` keeps (scrubbing to any step
#: applies at most this many deltas to a kept state; each kept state is a byte a cell: 200 MB for
#: Freiburg 079's 480 deltas).
KEY_EVERY = 32


@dataclass
class MappingRecording(_recordings.Recording):
    """A mapping run (see the module docstring). ``delta_steps[j]`` is the scan after which delta
    ``j`` holds; its cells are ``delta_cells[delta_offsets[j]:delta_offsets[j + 1]]`` (flat
    indices into the final ``shape``) and their values the same slice of ``delta_values``.
    ``origin`` is the world position of the outer corner of the final map's cell (0, 0)."""

    stamps: np.ndarray  # (N,) float64, seconds
    poses: np.ndarray  # (N, 3) float64, the sensor's
    delta_steps: np.ndarray  # (M,) int64, non-decreasing, < N
    delta_offsets: np.ndarray  # (M + 1,) int64
    delta_cells: np.ndarray  # (K,) int32 (int64 for maps of 2³¹ cells or more)
    delta_values: np.ndarray  # (K,) int8
    shape: tuple[int, int]  # (H, W) of the final map
    resolution: float
    origin: np.ndarray  # (2,)
    _keys: list = field(default_factory=list, init=False, repr=False, compare=False)
    _last: tuple = field(default=(0, None), init=False, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.stamps)

    def deltas_at(self, step: int) -> int:
        """How many deltas hold after scan ``step``."""
        return int(np.searchsorted(self.delta_steps, step, side="right"))

    def occupancy_at(self, step: int) -> np.ndarray:
        """The map (H, W) int8 after scan ``step`` (read-only), in the final map's frame: a kept
        state every :data:`KEY_EVERY` deltas, or the last state asked for when it is nearer, plus
        the deltas since."""
        m = self.deltas_at(step)
        k = m // KEY_EVERY
        while len(self._keys) <= k:
            n = len(self._keys)
            state = self._blank() if n == 0 else self._apply(self._keys[-1].copy(), (n - 1) * KEY_EVERY,
                                                              n * KEY_EVERY)
            state.flags.writeable = False
            self._keys.append(state)
        last_m, last = self._last
        if last is not None and k * KEY_EVERY <= last_m <= m:
            state = self._apply(last.copy(), last_m, m) if m > last_m else last
        else:
            state = self._apply(self._keys[k].copy(), k * KEY_EVERY, m)
        state.flags.writeable = False
        self._last = (m, state)
        return state

    def _blank(self) -> np.ndarray:
        return np.full(self.shape, -1, np.int8)

    def _apply(self, state: np.ndarray, start: int, stop: int) -> np.ndarray:
        flat = state.reshape(-1)
        for j in range(start, stop):  # in order: a later delta overwrites an earlier one's cells
            a, b = self.delta_offsets[j], self.delta_offsets[j + 1]
            flat[self.delta_cells[a:b]] = self.delta_values[a:b]
        return state

    def save(self, path) -> Path:
        """Write the recording (atomically); returns the path."""
        return _recordings.save(path, FORMAT, VERSION, stamps=self.stamps, poses=self.poses,
                                delta_steps=self.delta_steps, delta_offsets=self.delta_offsets,
                                delta_cells=self.delta_cells, delta_values=self.delta_values,
                                shape=np.array(self.shape, np.int64), resolution=np.array(self.resolution),
                                origin=self.origin)

    @classmethod
    def of_entries(cls, e: _recordings.Entries) -> MappingRecording:
        """The recording in a file's entries (:func:`occmap._recordings.read`), checked."""
        e.check(FORMAT, VERSION, "mapping")
        stamps = e.stamps()
        n = len(stamps)
        poses = e.get("poses", 2, (3,), np.float64)
        e.same_length(n, "stamps", poses=poses)
        steps = e.get("delta_steps", 1, kinds="iu").astype(np.int64)
        if len(steps) and (steps[0] < 0 or steps[-1] >= n or (np.diff(steps) < 0).any()):
            raise FormatError(e.path, f"entry 'delta_steps' must rise within 0 .. {n - 1} (the steps)")
        cells = e.get("delta_cells", 1, kinds="iu")
        values = e.get("delta_values", 1, dtype=np.int8)
        e.same_length(len(cells), "delta_cells", delta_values=values)
        offsets = e.offsets("delta_offsets", len(steps), len(cells), "delta_cells")
        shape = e.get("shape", 1, (2,), kinds="iu").astype(np.int64)
        if (shape < 0).any():
            raise FormatError(e.path, f"entry 'shape' is {shape.tolist()}, expected two sizes ≥ 0")
        if len(cells) and (cells.min() < 0 or cells.max() >= shape[0] * shape[1]):
            raise FormatError(e.path, f"entry 'delta_cells' holds cells outside the {shape[1]} × {shape[0]} map")
        if len(values) and (values.min() < -1 or values.max() > 100):
            raise FormatError(e.path, "entry 'delta_values' holds values outside −1 … 100 (nav_msgs)")
        origin = e.get("origin", 1, (2,), np.float64)
        e.finite(origin=origin)
        return cls(stamps, poses, steps, offsets, cells, values, (int(shape[0]), int(shape[1])), e.resolution(),
                   origin)


class MappingRecorder:
    """Records a mapping run as it goes: :meth:`add` after each batch of scans is in the grid
    (``every`` scans a batch, the last one shorter; :func:`occmap.mapping2d.map_scans` batches
    so), :meth:`finish` once the run is done. Holds the map's last recorded state and the deltas:
    its memory is the changed cells, 5 bytes each (a map of up to 2³² cells), and the map's last
    state, 5 bytes a cell."""

    def __init__(self, every: int = EVERY):
        self.every = checks.count("every", every, minimum=1)
        # per batch: stamps, poses, its last scan, the changed cells (flat indices into the map as
        # it was then, whose corner and width are the batch's frame) and their values
        self._stamps, self._poses, self._steps, self._cells, self._frames, self._values = [], [], [], [], [], []
        self._ref = None  # the world centre of the first map's cell (0, 0): it keeps its lattice cell
        # the last recorded map (nav_msgs values and log-odds), and its corner's lattice cell
        # relative to _ref's
        self._state = self._log_odds = None
        self._corner = np.zeros(2, np.int64)

    def add(self, grid, poses: np.ndarray, ranges: np.ndarray, angles: np.ndarray, max_range: float,
            stamps: np.ndarray) -> None:
        """The batch of scans just inserted in ``grid`` (an :class:`~occmap.grid2d.OccupancyGrid2D`
        that grows) as it was given to :meth:`~occmap.grid2d.OccupancyGrid2D.insert_scans`: sensor
        poses (n, 3), ranges (n, m), angles, ``max_range``; and their stamps (n,). Only the box the
        batch's beams reach is compared with the last state: a batch costs its box, not the map."""
        self._stamps.append(np.asarray(stamps, np.float64))
        self._poses.append(np.asarray(poses, np.float64))
        if grid.origin is None:  # nothing in the map yet
            return
        if self._ref is None:
            self._ref = grid.cell_to_world(np.zeros(2, np.int64))
        corner = -grid.world_to_cell(self._ref).astype(np.int64)  # (row, col) of cell (0, 0), lattice
        if self._state is None or self._state.shape != grid.shape or (corner != self._corner).any():
            # the map grew: the last state in its new frame
            state, log_odds = np.full(grid.shape, -1, np.int8), np.full(grid.shape, np.nan, np.float32)
            if self._state is not None:
                r, c = self._corner - corner
                h, w = self._state.shape
                state[r:r + h, c:c + w], log_odds[r:r + h, c:c + w] = self._state, self._log_odds
            self._state, self._log_odds, self._corner = state, log_odds, corner
        P, R, A, limit = scan_arrays(poses, ranges, angles, max_range)
        x, y = beam_points(P, R, A, limit)
        res = grid.resolution
        lo, hi = (np.nanmin(x) - res, np.nanmin(y) - res), (np.nanmax(x) + res, np.nanmax(y) + res)
        window, at = grid.log_odds_in(lo, hi)
        r0, c0 = np.rint((at - grid.origin) / res).astype(np.int64)[::-1]
        box = slice(r0, r0 + window.shape[0]), slice(c0, c0 + window.shape[1])
        # a cell's value can change only where its log-odds did: the nav_msgs values, dearer, are
        # worked out for those cells alone
        flat = np.empty(window.size, np.int64)
        flat = flat[:changed_log_odds(window, self._log_odds[box], flat)]
        now = occupancy_values(window.reshape(-1)[flat])
        rows, cols = np.divmod(flat, window.shape[1])
        before = self._state[box]
        changed = now != before[rows, cols]
        rows, cols, now = rows[changed], cols[changed], now[changed]
        index = np.uint32 if self._state.size <= 2**32 else np.int64
        self._cells.append(((rows + r0) * self._state.shape[1] + cols + c0).astype(index))
        self._frames.append((*corner, self._state.shape[1]))
        self._values.append(now)
        self._steps.append(sum(len(s) for s in self._stamps) - 1)
        before[rows, cols] = now

    def finish(self, grid) -> MappingRecording:
        """The recording, in the frame of ``grid`` (the same one, done)."""
        if not self._stamps:
            raise InvalidArgumentError("nothing recorded: no scan was added")
        stamps, poses = np.concatenate(self._stamps), np.concatenate(self._poses)
        if grid.origin is None:
            shape, origin, corner = (0, 0), np.zeros(2), np.zeros(2, np.int64)
        else:
            shape, origin, corner = grid.shape, np.asarray(grid.origin, np.float64), self._corner
        offsets = np.concatenate([[0], np.cumsum([len(c) for c in self._cells], dtype=np.int64)]).astype(np.int64)
        flat = np.empty(offsets[-1], np.int32 if shape[0] * shape[1] < 2**31 else np.int64)
        for j, (cells, (row, col, width)) in enumerate(zip(self._cells, self._frames)):
            r, c = np.divmod(cells.astype(np.int64), width)
            flat[offsets[j]:offsets[j + 1]] = (r + row - corner[0]) * shape[1] + c + col - corner[1]
        values = np.concatenate(self._values) if self._values else np.zeros(0, np.int8)
        return MappingRecording(stamps, poses, np.array(self._steps, np.int64), offsets, flat, values, shape,
                                float(grid.resolution), origin)

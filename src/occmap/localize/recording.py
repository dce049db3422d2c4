"""A localization run recorded step by step, to be scrubbed through in the viewer
(``occmap localize ... --record run.npz``, then ``occmap view run.npz``).

A recording holds, per scan of the run: its stamp, the estimated sensor pose, a subsample of the
particles (sensor poses, at most ``max_particles`` a step, float32, NaN rows pad a step that kept
fewer) and the reference pose where one is known (NaN rows elsewhere); and once, the map the run
was localized in (nav_msgs values, int8). Memory is bounded: 12 bytes a kept particle a step, so
13,631 Intel scans with 100 particles each take 16 MB.

On disk it is a recording file (:mod:`occmap._recordings`: a compressed ``.npz`` with a ``format``
entry naming it and a ``version``); :meth:`LocalizationRecording.load` checks both and every
array's shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import _recordings
from ..errors import InvalidArgumentError

#: The ``format`` entry of a recording file, and its version.
FORMAT = "occmap localization recording"
VERSION = 1
#: Particles kept a step by default (an even subsample of the filter's cloud).
MAX_PARTICLES = 200


def subsample(particles: np.ndarray, k: int) -> np.ndarray:
    """At most ``k`` rows of ``particles`` spread evenly over it (after a resampling the cloud is
    in the order of the particles it copied, so this is a systematic sample of it)."""
    n = len(particles)
    if n <= k:
        return particles
    return particles[np.linspace(0, n - 1, k).round().astype(np.int64)]


@dataclass
class LocalizationRecording(_recordings.Recording):
    """A localization run, one row per scan (see the module docstring). Poses are ``(x, y,
    theta)`` of the sensor in the map frame, metres and radians; ``origin`` is the world position
    of the outer corner of map cell (0, 0), whose row 0 lies along the lowest y."""

    stamps: np.ndarray  # (N,) float64, seconds
    estimates: np.ndarray  # (N, 3) float64
    particles: np.ndarray  # (N, K, 3) float32, NaN rows unused
    reference: np.ndarray  # (N, 3) float64, NaN rows where no reference
    occupancy: np.ndarray  # (H, W) int8: -1 unknown, 0 free ... 100 occupied
    resolution: float
    origin: np.ndarray  # (2,)

    def __len__(self) -> int:
        return len(self.stamps)

    @classmethod
    def of_replay(cls, result, grid, reference=None) -> LocalizationRecording:
        """The recording of a :func:`~occmap.localize.replay.replay` run made with
        ``keep_particles`` in the map ``grid`` (an :class:`~occmap.grid2d.OccupancyGrid2D`);
        ``reference`` (N, 3) with NaN rows where none."""
        n = len(result)
        ref = np.full((n, 3), np.nan) if reference is None else np.asarray(reference, np.float64)
        if result.particles is None:
            raise InvalidArgumentError("the replay kept no particles: run it with keep_particles > 0")
        return cls(result.stamps.copy(), result.poses.copy(), result.particles, ref, grid.occupancy(),
                   float(grid.resolution), np.asarray(grid.origin, np.float64))

    def save(self, path) -> Path:
        """Write the recording (atomically); returns the path."""
        return _recordings.save(path, FORMAT, VERSION, stamps=self.stamps, estimates=self.estimates,
                                particles=self.particles, reference=self.reference, occupancy=self.occupancy,
                                resolution=np.array(self.resolution), origin=self.origin)

    @classmethod
    def of_entries(cls, e: _recordings.Entries) -> LocalizationRecording:
        """The recording in a file's entries (:func:`occmap._recordings.read`), checked."""
        e.check(FORMAT, VERSION, "localization")
        stamps = e.stamps()
        out = cls(stamps, e.get("estimates", 2, (3,), np.float64), e.get("particles", 3, (3,), np.float32),
                  e.get("reference", 2, (3,), np.float64), e.get("occupancy", 2, dtype=np.int8),
                  e.resolution(), e.get("origin", 1, (2,), np.float64))
        e.same_length(len(stamps), "stamps", estimates=out.estimates, particles=out.particles,
                      reference=out.reference)
        e.finite(estimates=out.estimates, origin=out.origin)
        return out

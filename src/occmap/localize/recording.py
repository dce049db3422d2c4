"""A localization run recorded step by step, to be scrubbed through in the viewer
(``occmap localize ... --record run.npz``, then ``occmap view run.npz``).

A recording holds, per scan of the run: its stamp, the estimated sensor pose, a subsample of the
particles (sensor poses, at most ``max_particles`` a step, float32, NaN rows pad a step that kept
fewer) and the reference pose where one is known (NaN rows elsewhere); and once, the map the run
was localized in (nav_msgs values, int8). Memory is bounded: 12 bytes a kept particle a step, so
13,631 Intel scans with 100 particles each take 16 MB.

On disk it is a NumPy ``.npz`` (compressed, no pickled objects) with a ``format`` entry naming it
and a ``version``; :meth:`LocalizationRecording.load` checks both and every array's shape.
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._files import write_atomic
from ..errors import FormatError, InvalidArgumentError, MissingFileError

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
class LocalizationRecording:
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
        buf = io.BytesIO()
        np.savez_compressed(buf, format=np.array(FORMAT), version=np.array(VERSION), stamps=self.stamps,
                            estimates=self.estimates, particles=self.particles, reference=self.reference,
                            occupancy=self.occupancy, resolution=np.array(self.resolution), origin=self.origin)
        return write_atomic(path, buf.getvalue())

    @classmethod
    def load(cls, path) -> LocalizationRecording:
        """Read a recording; :class:`~occmap.errors.FormatError` names the file and the entry that
        is missing or of the wrong shape."""
        path = Path(path)
        if not path.is_file():
            raise MissingFileError(path, "no such file")
        try:
            with np.load(path, allow_pickle=False) as z:
                entries = {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:  # not a zip, a cut one, a pickle
            raise FormatError(path, f"not a NumPy .npz file ({e})") from None
        fmt = entries.get("format")
        if fmt is None or str(fmt) != FORMAT:
            raise FormatError(path, f"not an occmap localization recording (format entry {fmt!r})")
        version = entries.get("version")
        if version is None or version.shape != () or version.dtype.kind not in "iu" or int(version) != VERSION:
            raise FormatError(path, f"recording version {version!r}, this occmap reads {VERSION}")

        def entry(name, ndim, trailing=()):
            a = entries.get(name)
            if a is None:
                raise FormatError(path, f"entry {name!r} missing")
            if a.dtype.kind not in "iuf":
                raise FormatError(path, f"entry {name!r} holds {a.dtype}, expected numbers")
            if a.ndim != ndim or a.shape[ndim - len(trailing):] != trailing:
                raise FormatError(path, f"entry {name!r} has shape {a.shape}, expected {ndim} axes ending in "
                                        f"{trailing}")
            return a

        stamps = entry("stamps", 1)
        n = len(stamps)
        out = cls(stamps.astype(np.float64), entry("estimates", 2, (3,)).astype(np.float64),
                  entry("particles", 3, (3,)).astype(np.float32), entry("reference", 2, (3,)).astype(np.float64),
                  entry("occupancy", 2), float(entry("resolution", 0)),
                  entry("origin", 1, (2,)).astype(np.float64))
        for name in ("estimates", "particles", "reference"):
            if len(getattr(out, name)) != n:
                raise FormatError(path, f"entry {name!r} has {len(getattr(out, name))} steps, 'stamps' {n}")
        if not n:
            raise FormatError(path, "the recording has no step")
        if not (np.isfinite(out.resolution) and out.resolution > 0):
            raise FormatError(path, f"entry 'resolution' is {out.resolution}, expected a positive number of metres")
        if out.occupancy.dtype != np.int8:
            raise FormatError(path, f"entry 'occupancy' is {out.occupancy.dtype}, expected int8 (nav_msgs values)")
        for name in ("estimates", "origin"):
            if not np.isfinite(getattr(out, name)).all():
                raise FormatError(path, f"entry {name!r} holds NaN or infinite values")
        return out

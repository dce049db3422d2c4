"""A local-map replay recorded step by step, to watch the costmap follow the robot in the viewer
(``occmap local LOG -o local.gif --record run.npz``, then ``occmap view run.npz``).

A recording holds, per step (a frame of the animation): its stamp, the robot's (sensor's) pose
``(x, y, theta)``, the window's origin (the world position of the outer corner of its cell
(0, 0)) and the costmap (Nav2 costs, uint8 (H, W), row 0 along the lowest y: the values the
animation draws); and the tracks at that step (with ``--tracking``) as one ragged set: flat arrays
``id``, ``x``, ``y``, ``heading``, ``length``, ``width``, ``confirmed`` and per-step offsets.
Every raster is kept, so memory is H × W bytes a step (40 kB for the default 20 m window at
0.1 m: 300 steps take 12 MB), compressed on disk (a costmap is mostly runs of one value).

On disk it is a recording file (:mod:`occmap._recordings`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import _recordings
from ..errors import InvalidArgumentError

#: The ``format`` entry of a local-map recording file, and its version.
FORMAT = "occmap local map recording"
VERSION = 1
#: The per-track arrays of the ragged set, and their types.
TRACK_FIELDS = {"id": np.int64, "x": np.float64, "y": np.float64, "heading": np.float64, "length": np.float64,
                "width": np.float64, "confirmed": np.bool_}


@dataclass
class LocalMapRecording(_recordings.Recording):
    """A local-map replay (see the module docstring): step ``i``'s tracks are rows
    ``track_offsets[i]:track_offsets[i + 1]`` of the ``track_*`` arrays (metres, radians)."""

    stamps: np.ndarray  # (N,) float64, seconds
    poses: np.ndarray  # (N, 3) float64
    origins: np.ndarray  # (N, 2) float64
    costs: np.ndarray  # (N, H, W) uint8
    resolution: float
    track_offsets: np.ndarray  # (N + 1,) int64
    track_id: np.ndarray
    track_x: np.ndarray
    track_y: np.ndarray
    track_heading: np.ndarray
    track_length: np.ndarray
    track_width: np.ndarray
    track_confirmed: np.ndarray

    def __len__(self) -> int:
        return len(self.stamps)

    def tracks_at(self, step: int) -> dict[str, np.ndarray]:
        """Step ``step``'s tracks: a dict of the :data:`TRACK_FIELDS` arrays."""
        a, b = self.track_offsets[step], self.track_offsets[step + 1]
        return {name: getattr(self, f"track_{name}")[a:b] for name in TRACK_FIELDS}

    def save(self, path) -> Path:
        """Write the recording (atomically); returns the path."""
        return _recordings.save(path, FORMAT, VERSION, stamps=self.stamps, poses=self.poses, origins=self.origins,
                                costs=self.costs, resolution=np.array(self.resolution),
                                track_offsets=self.track_offsets,
                                **{f"track_{name}": getattr(self, f"track_{name}") for name in TRACK_FIELDS})

    @classmethod
    def of_entries(cls, e: _recordings.Entries) -> LocalMapRecording:
        """The recording in a file's entries (:func:`occmap._recordings.read`), checked."""
        e.check(FORMAT, VERSION, "local map")
        stamps = e.stamps()
        n = len(stamps)
        poses, origins = e.get("poses", 2, (3,), np.float64), e.get("origins", 2, (2,), np.float64)
        costs = e.get("costs", 3, dtype=np.uint8)
        e.same_length(n, "stamps", poses=poses, origins=origins, costs=costs)
        e.finite(poses=poses, origins=origins)
        tracks = {}
        for name, dtype in TRACK_FIELDS.items():
            tracks[name] = e.get(f"track_{name}", 1, dtype=dtype, kinds="b" if dtype is np.bool_ else "iuf")
        count = len(tracks["id"])
        e.same_length(count, "track_id", **{f"track_{k}": v for k, v in tracks.items()})
        offsets = e.offsets("track_offsets", n, count, "track_id")
        return cls(stamps, poses, origins, costs, e.resolution(), offsets,
                   *(tracks[name] for name in TRACK_FIELDS))


class LocalMapRecorder:
    """Records a local-map replay as it goes: :meth:`add` at each step, :meth:`finish` at the
    end."""

    def __init__(self):
        self._steps: list[tuple] = []
        self._tracks: list[dict[str, np.ndarray]] = []
        self.resolution = None

    def add(self, lm, stamp: float, pose, cost: np.ndarray) -> None:
        """Step at ``stamp`` of the :class:`~occmap.local.LocalMap` ``lm`` with the robot at ``pose``
        ``(x, y, theta)`` and ``cost`` its costmap now (the window's origin is ``lm``'s)."""
        self.resolution = float(lm.resolution)
        self._steps.append((float(stamp), np.asarray(pose, np.float64)[:3], np.asarray(lm.origin, np.float64),
                            np.asarray(cost, np.uint8)))
        if lm.objects is not None:
            t = lm.tracks()
            self._tracks.append({name: np.asarray(getattr(t, name), dtype) for name, dtype in TRACK_FIELDS.items()})
        else:
            self._tracks.append({name: np.zeros(0, dtype) for name, dtype in TRACK_FIELDS.items()})

    def finish(self) -> LocalMapRecording:
        if not self._steps:
            raise InvalidArgumentError("nothing recorded: no step was added")
        stamps, poses, origins, costs = (np.stack(a) for a in zip(*self._steps))
        offsets = np.concatenate([[0], np.cumsum([len(t["id"]) for t in self._tracks])]).astype(np.int64)
        return LocalMapRecording(stamps, poses, origins, costs, self.resolution, offsets,
                                 *(np.concatenate([t[name] for t in self._tracks]) for name in TRACK_FIELDS))

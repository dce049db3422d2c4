"""A ring of sonars with poses, as in the shared ``sonar/`` data set (Udacity's mapping exercise).

``measurement.txt``: ``timestamp s_1 … s_k``, ranges in millimetres; ``poses.txt``:
``timestamp x y theta`` with x, y in millimetres and theta in tenths of a degree; one line each
per ring reading, timestamps matching. Converted here to metres and radians; headings are kept
as given (0…2π for this data set), not wrapped, since the exercise's unwrapped angle comparison
(``SonarModel(wrap_angles=False)``) depends on them. The tests' ``tests/grid2d/sonar_reference.py`` maps the set as
the exercise does and compares the result with its ``Map_reference.png``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FormatError
from ._compression import read_bytes
from ._text import Table

#: Transducer directions of the shared data set, relative to the heading (degrees).
RING_BEARINGS_DEG = (-90.0, -37.5, -22.5, -7.5, 7.5, 22.5, 37.5, 90.0)
#: The data set's "no echo" reading, in millimetres.
NO_ECHO_MM = 5110.0


@dataclass(frozen=True, eq=False)
class SonarLog:
    stamps: np.ndarray  # (N,)
    poses: np.ndarray  # (N, 3) metres, radians
    ranges: np.ndarray  # (N, k) metres
    bearings: np.ndarray  # (k,) radians
    max_range: float  # metres: readings at or beyond it had no echo


def _table(path: Path, columns: int | None) -> np.ndarray:
    """The file's rows of numbers, ``columns`` each (default: as many as the first row has)."""
    table = Table(path, read_bytes(path), 1, comments=True)
    if not len(table):
        return np.zeros((0, columns or 0))
    columns = int(table.counts[0]) if columns is None else columns
    table.require(path, exactly=columns, what="numbers per line")
    return table.columns(range(columns))


def read_sonar_ring(folder, bearings_deg=RING_BEARINGS_DEG, no_echo_mm: float = NO_ECHO_MM) -> SonarLog:
    """Read ``measurement.txt`` and ``poses.txt`` from ``folder``; pairs rows by timestamp."""
    folder = Path(folder)
    meas = _table(folder / "measurement.txt", None)
    poses = _table(folder / "poses.txt", 4)
    if meas.shape[1] != len(bearings_deg) + 1:
        raise FormatError(folder / "measurement.txt", f"expected a timestamp and {len(bearings_deg)} ranges per line")
    if meas.shape[0] != poses.shape[0] or not np.array_equal(meas[:, 0], poses[:, 0]):
        raise FormatError(folder / "poses.txt", "timestamps do not match measurement.txt line for line")
    P = np.column_stack([poses[:, 1] / 1000.0, poses[:, 2] / 1000.0, np.radians(poses[:, 3] / 10.0)])
    return SonarLog(meas[:, 0], P, meas[:, 1:] / 1000.0, np.radians(np.asarray(bearings_deg, dtype=np.float64)),
                    no_echo_mm / 1000.0)

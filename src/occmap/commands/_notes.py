"""What a command assumed where its input was silent, said on stderr beside the results: the
user sees it without it mixing with the figures on stdout."""

from __future__ import annotations

import sys


def note(command: str, text: str) -> None:
    """One line ``occmap COMMAND: note: TEXT`` on stderr."""
    print(f"occmap {command}: note: {text}", file=sys.stderr)


def carmen_assumptions(command: str, stats, max_range_option: bool = True) -> None:
    """The defaults a CARMEN log made the reader take (:class:`occmap.io.carmen.CarmenStats`)."""
    from ..io.carmen import DEFAULT_MAX_RANGE

    if stats.assumed_max_range:
        note(command, f"{stats.assumed_max_range:,} FLASER/RLASER scans have no maximum range in the log (no PARAM "
                      f"robot_front_laser_max or the like): {DEFAULT_MAX_RANGE:g} m assumed, readings at or beyond it "
                      "taken as no return" + ("; --max-range sets it" if max_range_option else ""))
    if stats.guessed_angles:
        note(command, f"{stats.guessed_angles:,} FLASER/RLASER scans have a beam count that does not give their "
                      "angular step: a closed 180° fan assumed, as CARMEN does")


def _names(names: list[str]) -> str:
    return ", ".join(names[:3]) + (f" and {len(names) - 3:,} more" if len(names) > 3 else "")


def identity_poses(command: str, no_pose: list[str], total: int) -> None:
    """Clouds inserted at the identity pose, sensor at the origin, because their files hold no
    pose (PLY, XYZ, KITTI ``.bin``, or a PCD whose ``VIEWPOINT`` is absent or PCL's default
    ``0 0 0 1 0 0 0``, which PCL writes when it knows none)."""
    if no_pose:
        note(command, f"{len(no_pose):,} of {total:,} point clouds carry no sensor pose ({_names(no_pose)}): the "
                      "identity pose assumed, points taken as world coordinates seen from the origin")

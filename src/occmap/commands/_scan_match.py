"""``--scan-match``: poses from the ranges, for logs and bags whose scans have none (or only
drifting odometry), shared by the commands that map planar scans."""

from __future__ import annotations

import sys


def add_option(p) -> None:
    p.add_argument("--scan-match", action="store_true",
                   help="replace the scans' poses by scan-matched ones (incremental scan-to-map matching, "
                   "occmap.slam; the first scan defines the frame; odometry, where the log has it, is the prior)")


def scan_matched(scans) -> list:
    """The scans (:class:`~occmap.scan.LaserScan`) with scan-matched poses; says how the matching
    went on stdout and draws its progress on stderr when that is a terminal."""
    from ..scan import with_poses
    from ..slam import match_scans

    scans = list(scans)
    track = match_scans(scans, progress=sys.stderr.isatty())
    print(track.summary())
    return with_poses(scans, track.poses)


def with_prior(source, scan):
    """``scan`` with the pose its source gave it as the matcher's prior: a bag's tf, odometry or
    pose file (its odometry then); a CARMEN scan keeps its own odometry."""
    from dataclasses import replace

    placed = getattr(source, "fixed_frame", None) or getattr(source, "pose_track", None)
    return replace(scan, odom=scan.pose) if placed else scan

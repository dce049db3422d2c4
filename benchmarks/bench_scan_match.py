"""Scan matching where there are no poses: accuracy on the Intel run, speed, and the shared bag.

1. Intel Research Lab. The raw run ``intel-raw.clf.bz2`` (13,631 scans, about 5 a second, wheel
   odometry) is scan-matched (:func:`occmap.slam.match_scans`) with its poses withheld: from the
   ranges alone (constant-velocity prior), and with the raw odometry as the prior. Its scans pair
   with the 910 of ``intel-corrected.log.gz`` by logger timestamp and identical ranges
   (:func:`occmap.localize.replay.pair_scans`), so the corrected poses are the reference: the
   relative pose error over 1 m segments (Kümmerle et al. 2009, :func:`occmap.slam.relative_pose_error`)
   of each trajectory, beside that of the raw odometry. The same for the 910 corrected scans alone
   (ranges only; then with their raw twins' odometry): they are 0.67 m and 22° apart (median), far
   beyond what a constant-velocity prior predicts.
2. Time per scan (``ScanMatcher.add``, everything included: matching, inserting, rebuilding the
   local fields), against the log's own rate. No 2D scan matcher is pip-installable here to
   compare with (Hector and laser_scan_matcher are ROS nodes).
3. ``laser_scan_matcher_demo.bag`` (360 LaserScan, no tf, no odometry): scan-matched, mapped at
   2.5 cm; the picture beside the map of the same scans at the pose they carry (none: all at the
   origin) goes to docs/images/scan_match_bag.png.

Run: ``.venv/bin/python benchmarks/bench_scan_match.py [--quick]`` (``--quick``: the first 3,000
raw scans). Writes the ``scan_match`` section of BENCHMARKS.md.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, grids_side_by_side, shared_data, write_section  # noqa: E402

from occmap.io.bags import decode_laser_scan, open_bag  # noqa: E402
from occmap.io.carmen import read_carmen  # noqa: E402
from occmap.localize.replay import pair_scans  # noqa: E402
from occmap.mapping2d import map_scans  # noqa: E402
from occmap.scan import stack_scans, with_poses  # noqa: E402
from occmap.slam import ScanMatcher, relative_pose_error  # noqa: E402

IMAGE = ROOT / "docs" / "images" / "scan_match_bag.png"


def timed_run(scans):
    """Poses (N, 3), seconds per scan (N,) and the matcher's counts, one ``add`` at a time."""
    matcher = ScanMatcher()
    poses = np.empty((len(scans), 3))
    secs = np.empty(len(scans))
    for i, s in enumerate(scans):
        t0 = time.perf_counter()
        poses[i] = matcher.add(s)
        secs[i] = time.perf_counter() - t0
    return poses, secs, dict(matcher.stats)


def rpe_cells(poses, reference) -> str:
    s = relative_pose_error(poses, reference).summary()
    return (f"{s['translation_mean']:.3f} ± {s['translation_std']:.3f} | {s['translation_max']:.2f} | "
            f"{s['rotation_deg_mean']:.2f} ± {s['rotation_deg_std']:.2f} | {s['rotation_deg_max']:.1f}")


def counts(stats) -> str:
    return (f"{stats['matched']:,} / {stats['failed']:,} / {stats['rejected']:,} / {stats['degenerate']:,}")


def intel(data: Path, quick: bool) -> list[str]:
    ref = read_carmen(data / "carmen" / "intel-corrected.log.gz").scans
    raw = read_carmen(data / "carmen" / "intel-raw.clf.bz2").scans
    pairs = pair_scans(raw, ref)
    if quick:
        raw = raw[:3000]
    keep = (pairs >= 0) & (pairs < len(raw))
    reference = np.array([s.pose for s in ref])[keep]
    at = pairs[keep]
    stamps = np.array([s.stamp for s in raw])
    seconds_of_log = float(stamps.max() - stamps.min())
    odometry = np.array([raw[j].odom for j in at])
    rows = [f"| raw wheel odometry | — | {rpe_cells(odometry, reference)} | — | — |"]
    figures = {}
    runs = [
        (f"every raw scan ({len(raw):,}), ranges only", [replace(s, odom=None) for s in raw], at, True),
        (f"every raw scan ({len(raw):,}), raw odometry as the prior", raw, at, True),
    ]
    if not quick:
        runs += [
            ("the 910 corrected scans alone, ranges only", [replace(s, odom=None) for s in ref], np.flatnonzero(keep), False),
            ("their 910 raw twins, raw odometry as the prior", [raw[j] for j in at], None, False),
        ]
    for label, scans, index, realtime in runs:
        t0 = time.perf_counter()
        poses, secs, stats = timed_run(scans)
        wall = time.perf_counter() - t0
        est = poses if index is None else poses[index]
        rate = f"{seconds_of_log / wall:.1f}× real time" if realtime else "—"
        rows.append(f"| {label} | {counts(stats)} | {rpe_cells(est, reference)} | "
                    f"{1e3 * np.median(secs):.1f} / {1e3 * np.percentile(secs, 95):.1f} ms | {rate} |")
        figures[label] = relative_pose_error(est, reference).summary()
        print(rows[-1], flush=True)
    return [
        f"Relative pose error over 1 m segments against the corrected poses ({int(keep.sum())} reference poses, "
        f"{len(relative_pose_error(odometry, reference).start)} segments); translation in m, heading in degrees "
        "(mean ± std, max). Counts: matched / failed / rejected (both left at the prior) / degenerate.",
        "",
        "| poses from | counts | translation | max | heading | max | time per scan (median / p95) | speed |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
    ]


def bag(data: Path) -> list[str]:
    path = data / "rosbag" / "laser_scan_matcher_demo.bag"
    with open_bag(path) as b:
        scans = [decode_laser_scan(m.raw, m.encoding).scan for m in b.messages("/scan")]
    poses, secs, stats = timed_run(scans)
    matched = map_scans(stack_scans(with_poses(scans, poses)), 0.025)
    as_recorded = map_scans(stack_scans(scans), 0.025)
    grids_side_by_side(IMAGE, (("every scan at the pose it carries (the origin)", as_recorded.grid),
                               ("scan-matched", matched.grid)))
    steps = np.diff(poses, axis=0)
    path_length = float(np.hypot(steps[:, 0], steps[:, 1]).sum())
    turned = math.degrees(float(np.abs(np.diff(np.unwrap(poses[:, 2]))).sum()))
    print(f"bag: {counts(stats)}; {1e3 * np.median(secs):.1f} ms/scan; path {path_length:.1f} m, turned {turned:.0f}°")
    return [
        f"`laser_scan_matcher_demo.bag`: {len(scans)} scans, {counts(stats)} (matched / failed / rejected / "
        f"degenerate), {stats['inserted']} inserted into the matcher's map; {1e3 * np.median(secs):.1f} ms per scan "
        f"(median), {sum(secs):.1f} s in all for {scans[-1].stamp - scans[0].stamp:.0f} s of recording. The matched "
        f"path is {path_length:.1f} m long and turns {turned:.0f}° in all. Map at 2.5 cm: "
        f"`docs/images/scan_match_bag.png` (left: every scan at the pose it carries, the origin; right: scan-matched).",
    ]


def main() -> None:
    quick = "--quick" in sys.argv
    data = shared_data()
    if data is None:
        return
    body = [
        "Incremental scan-to-map matching (`occmap.slam.match_scans`, default `ScanMatchParams`: 5 cm map, three "
        "distance-field levels, correlative search ±0.4 m / ±0.5 rad, no loop closure) with the recorded poses "
        "withheld. `benchmarks/bench_scan_match.py`" + (" --quick (the first 3,000 raw scans)" if quick else "") + ".",
        "",
        *intel(data, quick),
        "",
        *bag(data),
    ]
    write_section("scan_match", "## Scan matching (poses from the ranges)\n\n" + "\n".join(body))


if __name__ == "__main__":
    main()

"""Radar mapping on the simulated street: how close to the truth, against a lidar on the same robot.

The street (:class:`occmap.sim.street.Street`, 20 s: cars passing, turning and crossing, people, parked
cars, building fronts) seen by the robot's radar alone at 10 Hz — detections with range, azimuth,
Doppler and cross-section, false alarms, missed detections and multipath ghosts — and mapped
with :meth:`occmap.OccupancyGrid2D.insert_radar` (:class:`occmap.grid2d.RadarModel` defaults) at
0.2 m; beside it the robot's lidar (720 beams, 30 m, 10 Hz) mapped with ``insert_scan``. Scores
(:meth:`Street.map_scores`): precision of the occupied cells (p ≥ 0.65, a saved map's) against
the static truth, and recall of the static cells a sensor at the robot sees first within 30 m,
each against the other dilated by one cell. Seeds 0–4; the radar's azimuth noise (1σ) 0.5° (the
default: a 77 GHz radar near boresight) and 1° (its edges, or an older sensor). Time per sweep:
``insert_radar`` against ``insert_scan`` of the lidar scan taken at the same moment.

Run: ``.venv/bin/python benchmarks/bench_radar.py [--seeds N]``. Writes the ``radar`` section of
BENCHMARKS.md and docs/images/radar_street.png (left: radar, right: lidar; seed 0, 0.5°; both drawn over
the lidar map's mapped part).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, grids_side_by_side, write_section  # noqa: E402

from occmap import OccupancyGrid2D  # noqa: E402
from occmap.sim.street import Street  # noqa: E402

IMAGE = ROOT / "docs" / "images" / "radar_street.png"
RES = 0.2
RATE = 10.0


def run(street: Street, seed: int, sigma_azimuth_deg: float):
    """Radar and lidar maps of one run; per-sweep insertion times."""
    x0, y0, x1, y1 = street.bounds
    size, origin = (x1 - x0, y1 - y0), (x0, y0)
    radar, lidar = OccupancyGrid2D(RES, size=size, origin=origin), OccupancyGrid2D(RES, size=size, origin=origin)
    rng = np.random.default_rng(seed)
    stamps = np.arange(0.0, street.duration + 1e-9, 1.0 / RATE)
    t_radar, t_lidar, detections = [], [], 0
    for t in stamps:
        sweep = street.radar(float(t), rng=rng, sigma_azimuth=math.radians(sigma_azimuth_deg))
        scan = street.lidar(float(t), rng=rng)
        t0 = time.perf_counter()
        radar.insert_radar(sweep.pose, sweep.range, sweep.azimuth, 60.0, radial_velocity=sweep.radial_velocity,
                           ego_velocity=sweep.ego_velocity)
        t1 = time.perf_counter()
        lidar.insert_scan(scan.pose, scan.ranges, scan.angles, max_range=30.0)
        t2 = time.perf_counter()
        t_radar.append(t1 - t0)
        t_lidar.append(t2 - t1)
        detections += sweep.range.size
    shape = (int(round(size[1] / RES)), int(round(size[0] / RES)))
    scores = [street.map_scores((g.probability() >= 0.65)[:shape[0], :shape[1]], RES, origin, stamps)
              for g in (radar, lidar)]
    return radar, lidar, scores, t_radar, t_lidar, detections / len(stamps)


def street_box(lidar: OccupancyGrid2D):
    """The part of the street both pictures show: the lidar map's mapped part (the radar's clutter
    and false alarms reach far past the buildings and would set its frame otherwise)."""
    from occmap.viz.maps import mapped_box

    return mapped_box(lidar.probability(), lidar.observed, lidar.origin, lidar.resolution)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    street = Street.default()
    rows = []
    times_r, times_l = [], []
    lidar_scores = []
    per_sweep = 0.0
    for sigma in (0.5, 1.0):
        radar_scores = []
        for seed in range(args.seeds):
            radar, lidar, (rs, ls), tr, tl, per_sweep = run(street, seed, sigma)
            radar_scores.append(rs)
            if sigma == 0.5:
                lidar_scores.append(ls)
                times_r += tr
                times_l += tl
                if seed == 0:
                    grids_side_by_side(IMAGE, (("street, radar alone", radar), ("street, lidar alone", lidar)),
                                       crop=street_box(lidar))
            print(f"azimuth σ {sigma}°, seed {seed}: radar precision {rs[0]:.3f} recall {rs[1]:.3f}; "
                  f"lidar {ls[0]:.3f} / {ls[1]:.3f}")
        p, r = np.array(radar_scores).T
        rows.append(f"| radar, azimuth σ {sigma}° | {p.min():.3f} – {p.max():.3f} | {r.min():.3f} – {r.max():.3f} | "
                    f"≥ 0.9 / ≥ 0.8 |")
    p, r = np.array(lidar_scores).T
    rows.append(f"| lidar (720 beams, σ 2 cm, 30 m) | {p.min():.3f} – {p.max():.3f} | {r.min():.3f} – {r.max():.3f} | – |")
    mr, ml = 1e3 * float(np.median(times_r)), 1e3 * float(np.median(times_l))
    print(f"per sweep: radar {mr:.2f} ms ({per_sweep:.0f} detections), lidar scan {ml:.2f} ms")
    body = "\n".join([
        "## Radar mapping (simulated street)",
        "",
        f"`python benchmarks/bench_radar.py`: the street's radar alone at 10 Hz for 20 s, mapped at {RES} m with the "
        f"`RadarModel` defaults, beside the lidar of the same robot; seeds 0–{args.seeds - 1} (range over seeds).",
        "",
        "| sensor | precision | recall | target |",
        "|---|---:|---:|---:|",
        *rows,
        "",
        f"Per sweep (median, seeds at 0.5°): `insert_radar` {mr:.2f} ms for about {per_sweep:.0f} detections; "
        f"`insert_scan` of the 720-beam lidar scan {ml:.2f} ms. Picture: `docs/images/radar_street.png` (left: "
        f"radar, right: lidar; seed 0).",
    ])
    write_section("radar", body)


if __name__ == "__main__":
    main()

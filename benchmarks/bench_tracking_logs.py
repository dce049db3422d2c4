"""Tracking on real logs: where the confirmed tracks lie, on the structure the log's own map shows
or in its free space.

Each CARMEN log is replayed as ``occmap local LOG --tracking --register --resolution 0.05`` replays
it (a 20 m window at 0.05 m, half-life 30 s, each scan registered to the map and inserted where it
fits, stamps going backwards held) and every confirmed track's centre is kept at
every scan it is confirmed in, carried from the map's frame into the log's by the map's
correction. The map of the corrected log (``map_scans`` at
0.05 m) tells the two apart: a track is **on structure** when the map calls its centre occupied
(probability over 0.5 within 0.1 m) at half its samples or more — a wall, a door frame, furniture
that pose errors or a cut view made look moving — and **in free space** otherwise: where the map,
built from every scan, saw through (people walking, doors swinging). A raw-odometry run's tracks
lie in its odometry frame: each centre is carried into the corrected log's frame by the correction
(corrected pose ⊖ raw pose) of the paired scan nearest in the run (:func:`occmap.localize.replay.pair_scans`).
The raw run's own map would not do: its drifting odometry smears the walls, and a wall fragment the
drift moved lies in what the rest of the run saw free. The issue's target is none on structure.

Run: ``.venv/bin/python benchmarks/bench_tracking_logs.py [--logs NAME ...] [--perturb SEED ...]``
(a replay takes 1–5 minutes). Counts this small are one draw of a chaotic replay: ``--perturb``
replays each log once more per seed with every pose moved by 10 – 20 µm and 1 – 3 µrad
(:func:`perturbed`), which changes which of the registration's steps a scan takes, and reports
those counts too. Writes the ``tracking-logs`` section of BENCHMARKS.md and, for each log with tracks in
free space, ``docs/images/tracks_<log>.png`` (the map, free-space tracks in green, the others red).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, publish, shared_data  # noqa: E402

from occmap.io.carmen import read_carmen  # noqa: E402
from occmap.geometry.se2 import compose_poses, relative_poses  # noqa: E402
from occmap.local import LocalMap  # noqa: E402
from occmap.localize.replay import pair_scans  # noqa: E402
from occmap.mapping2d import map_scans  # noqa: E402
from occmap.sources import CarmenScans  # noqa: E402

#: name: (log, its corrected twin for a raw run)
LOGS = {
    "intel-corrected": ("carmen/intel-corrected.log.gz", None),
    "csail-corrected": ("carmen/csail-corrected.log.gz", None),
    "freiburg-079-corrected": ("carmen/freiburg-079-corrected.log.gz", None),
    "intel-raw": ("carmen/intel-raw.clf.bz2", "carmen/intel-corrected.log.gz"),
    "fr079-raw": ("carmen/fr079-raw.clf.bz2", "carmen/freiburg-079-corrected.log.gz"),
}
RESOLUTION = 0.05
NEAR = 0.1  # m: a centre within this of an occupied cell is on it


def perturbed(pose, rng) -> np.ndarray:
    """``pose`` moved by 10 – 20 µm in a random direction and turned by 1 – 3 µrad either way: far
    below any sensor's precision, enough to change which of the registration's steps a scan takes."""
    r, phi = rng.uniform(10e-6, 20e-6), rng.uniform(0.0, 2.0 * math.pi)
    return np.asarray(pose, dtype=np.float64) + np.array([r * math.cos(phi), r * math.sin(phi),
                                                          rng.choice([-1, 1]) * rng.uniform(1e-6, 3e-6)])


def replay(path: Path, perturb: int | None = None) -> tuple[dict, int, int]:
    """Confirmed tracks' samples ``{id: (K, 5) of (stamp, x, y, speed, scan index)}``, scans, tracks
    started; with ``perturb`` (a seed) every pose moved by :func:`perturbed`."""
    lm = LocalMap((20.0, 20.0), RESOLUTION, half_life=30.0, tracking=True, register=True)
    rng = None if perturb is None else np.random.default_rng(perturb)
    samples: dict[int, list] = {}
    last, n = None, 0
    for scan in CarmenScans(path):
        stamp = float(scan.stamp)
        stamp = stamp if last is None or stamp >= last else last
        last = stamp
        pose = scan.pose if rng is None else perturbed(scan.pose, rng)
        lm.move_to(float(pose[0]), float(pose[1]))
        lm.insert_scan(pose, scan.ranges, scan.angles, stamp, max_range=scan.max_range)
        tr = lm.tracks()
        keep = np.flatnonzero(tr.confirmed)
        # the tracks lie in the map's frame: carried back into the log's by the map's correction
        at = relative_poses(lm.correction, np.c_[tr.x[keep], tr.y[keep], np.zeros(len(keep))])
        for k, i in enumerate(keep):
            samples.setdefault(int(tr.id[i]), []).append((stamp, at[k, 0], at[k, 1], math.hypot(tr.vx[i], tr.vy[i]), n))
        n += 1
    return {k: np.array(v) for k, v in samples.items()}, n, lm.stats["tracks_started"]


def corrected(raw, reference, samples: dict) -> dict:
    """``samples`` of a replay of the ``raw`` scans with their centres carried into the frame of
    the ``reference`` (the corrected log's scans)."""
    pairs = pair_scans(raw, reference)
    ok = np.flatnonzero(pairs >= 0)
    at = pairs[ok]
    order = np.argsort(at)
    at, ref = at[order], ok[order]
    fix_raw = np.array([raw[j].pose for j in at])
    fix_ref = np.array([reference[k].pose for k in ref])
    out = {}
    for tid, s in samples.items():
        i = np.clip(np.searchsorted(at, s[:, 4]), 1, len(at) - 1)
        i -= (s[:, 4] - at[i - 1]) < (at[i] - s[:, 4])  # the nearer of the two
        body = relative_poses(fix_raw[i], np.c_[s[:, 1:3], np.zeros(len(s))])
        moved = s.copy()
        moved[:, 1:3] = compose_poses(fix_ref[i], body)[:, :2]
        out[tid] = moved
    return out


def on_structure(grid, centres: np.ndarray) -> float:
    """Share of ``centres`` (K, 2) the map calls occupied within :data:`NEAR`."""
    offsets = [(0.0, 0.0), (NEAR, 0.0), (-NEAR, 0.0), (0.0, NEAR), (0.0, -NEAR)]
    occ = np.max([grid.occupancy_at(centres + np.array(o)) for o in offsets], axis=0)
    return float(np.mean(occ > 0.5))


def figure(name: str, grid, tracks: dict, structure: set) -> Path:
    """The log's map (:meth:`~occmap.grid2d.OccupancyGrid2D.figure`) with the confirmed tracks' paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = grid.figure(f"{name}: confirmed tracks in free space (green), on structure (red)")
    ax = fig.axes[0]
    for tid, s in tracks.items():
        ax.plot(s[:, 1], s[:, 2], "-", lw=1.5, color="tab:red" if tid in structure else "tab:green")
    out = ROOT / "docs" / "images" / f"tracks_{name}.png"
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", choices=sorted(LOGS), default=list(LOGS))
    parser.add_argument("--no-write", action="store_true", help="print the results only")
    parser.add_argument("--perturb", type=int, nargs="*", default=[], metavar="SEED",
                        help="also replay each log with every pose moved by 10 - 20 um and 1 - 3 urad (one run per "
                             "seed): how much of the count is one draw of a chaotic replay")
    args = parser.parse_args()
    data = shared_data()
    if data is None:
        return
    rows, shaken = [], []
    for name in args.logs:
        log, twin = LOGS[name]
        path = data / log
        reference = read_carmen(data / (twin or log))
        grid = map_scans(reference.stack(), RESOLUTION).grid

        def judged(perturb=None):
            tracks, scans, started = replay(path, perturb)
            if twin:
                tracks = corrected(read_carmen(path).scans, reference.scans, tracks)
            return tracks, scans, started, {tid for tid, s in tracks.items() if on_structure(grid, s[:, 1:3]) >= 0.5}

        counts = []
        for seed in args.perturb:
            t, _, _, st = judged(seed)
            counts.append(f"{len(st)} of {len(t)}")
            print(f"{name}, poses perturbed (seed {seed}): {len(t)} confirmed, {len(st)} on structure", flush=True)
        if counts:
            shaken.append(f"| {name} | {', '.join(counts)} |")
        tracks, scans, started, structure = judged()
        free = [s for tid, s in tracks.items() if tid not in structure]
        seconds = sum(float(s[-1, 0] - s[0, 0]) for s in free)
        speed = float(np.median(np.concatenate([s[:, 3] for s in free]))) if free else math.nan
        print(f"{name}: {scans} scans, {started} tracks started, {len(tracks)} confirmed: {len(structure)} on "
              f"structure, {len(free)} in free space ({seconds:.0f} s, median speed {speed:.2f} m/s)", flush=True)
        if free and not args.no_write:
            print(f"  {figure(name, grid, tracks, structure)}")
        rows.append(f"| {name} | {scans:,} | {started:,} | {len(tracks)} | {len(structure)} | {len(free)} | "
                    f"{seconds:.0f} s | {f'{speed:.2f} m/s' if free else '–'} |")
    body = "\n".join([
        "## Tracking on real logs",
        "",
        "`python benchmarks/bench_tracking_logs.py`: each CARMEN log replayed as `occmap local LOG --tracking --register "
        f"--resolution {RESOLUTION}` does (20 m window, half-life 30 s, each scan registered to the map and inserted "
        "where it fits; track centres carried back into the log's frame by the map's correction); "
        "a confirmed track is on structure when the "
        f"map of the corrected log ({RESOLUTION} m) calls its centre occupied (within {NEAR} m) at half its samples or "
        "more, else in free space (people, doors); a raw run's centres carried into the corrected frame by the "
        "correction of the nearest paired scan. Target: none on structure.",
        "",
        "| log | scans | tracks started | confirmed | on structure | in free space | their time confirmed | "
        "their median speed |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
        *(["", f"With every pose moved by 10 – 20 µm and 1 – 3 µrad (`--perturb {' '.join(map(str, args.perturb))}`, "
            "one run per seed), on structure of confirmed:", "", "| log | perturbed runs |", "|---|---|", *shaken]
          if shaken else []),
    ])
    publish("tracking-logs", body, write=not args.no_write)


if __name__ == "__main__":
    main()

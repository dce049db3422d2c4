"""Monte Carlo localization: the speed of one filter update, and accuracy on two real runs.

1. One update (motion, measurement, resampling, estimate) with 2,000 particles and 60 beams,
   against the target of 10 ms on this machine; the measurement kernel alone, serial and parallel.
2. Two development runs, one set of defaults: Intel Research Lab and Freiburg building 079. For
   each, the map is built at 5 cm from the SLAM-corrected log (with the laser model of a map to
   localize in, :data:`~occmap.localize.replay.MAP_MODEL`), then the raw run (drifting wheel
   odometry) is localized in it. Raw scans pair with the corrected log's by logger timestamp and
   identical ranges (:func:`~occmap.localize.replay.pair_scans`), so the corrected poses are the
   reference. Tracking from the first corrected pose with plain AMCL and with each addition
   (the last, coasting: :mod:`occmap.localize.mcl`), the default also with other seeds;
   global localization from particles spread over the free space, for 10 seeds (on Intel also
   with each part of its coarse-to-fine schedule taken away in turn).
3. Kidnapping: on each run, from 10 reference poses spread over it, the robot is carried away
   unseen (:func:`~occmap.localize.replay.kidnapped`: scans skipped, odometry continuous) and the
   travel until the estimate is back within 0.2 m is measured, with and without the global search
   that a persistently lost estimate starts (``relocalize_after``).

The Freiburg 079 laser sits 0.04 m behind the robot's centre (``PARAM robot_frontlaser_offset``):
the filter tracks the robot with its odometry and the track is compared as the laser's. Where a
corrected pose does not fit its own map (median end-point distance above 0.1 m,
:func:`~occmap.localize.replay.reference_fit`) the reference itself is in doubt; the tables give
the error over all reference poses and over those that fit. How far the map places each reference
scan from its own pose (:func:`~occmap.localize.replay.reference_offset`) is the error an estimate
that follows the map shows against the reference while right about the map: a floor under it.

Run: ``.venv/bin/python benchmarks/bench_localize.py [--quick | --kidnap]`` (``--quick``: the first
3,000 scans of each run, three global seeds; ``--kidnap``: only the kidnapping tables, which replace
those of the section). Writes the ``localize`` section of BENCHMARKS.md and
docs/images/localize_intel.png, localize_fr079.png.
"""

from __future__ import annotations

import datetime
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import BENCHMARKS_MD, ROOT, median_times, shared_data, write_section  # noqa: E402

from occmap.io.carmen import read_carmen  # noqa: E402
from occmap.localize import _kernels as K  # noqa: E402
from occmap.localize.likelihood_field import LikelihoodField, beam_end_points  # noqa: E402
from occmap.localize.params import LocalizationParams  # noqa: E402
from occmap.localize.replay import (  # noqa: E402
    MAP_MODEL, convergence_distance, make_localizer, pair_scans, reference_fit, reference_offset, replay, replay_kidnapped,
    save_error_png, save_track_png, track_errors, travelled,
)
from occmap.mapping2d import map_scans  # noqa: E402

#: Reference poses whose scan's median end-point distance to the map exceeds this (m) are in doubt.
FIT = 0.1
INIT_COV = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(3) ** 2])


@dataclass
class Run:
    key: str
    title: str
    corrected: str
    raw: str
    credit: str


RUNS = (
    Run("intel", "Intel Research Lab", "intel-corrected.log.gz", "intel-raw.clf.bz2",
        "D. Hähnel; raw log from the Freiburg SLAM evaluation set"),
    Run("fr079", "Freiburg building 079", "freiburg-079-corrected.log.gz", "fr079-raw.clf.bz2",
        "University of Freiburg; raw log from the Freiburg SLAM evaluation set"),
)


@dataclass
class Loaded:
    run: Run
    raw: list
    grid: object
    pairs: np.ndarray
    ref_poses: np.ndarray
    offset: tuple
    fits: np.ndarray  # per reference pose: True where it fits its own map
    to_map: np.ndarray  # per reference pose: how far (m) the map places its scan from it (NaN: no match)


def load(carmen: Path, run: Run, quick: bool) -> Loaded:
    t0 = time.perf_counter()
    ref_log = read_carmen(carmen / run.corrected)
    raw_log = read_carmen(carmen / run.raw)
    grid = map_scans(ref_log.stack(), 0.05, model=MAP_MODEL).grid
    pairs = pair_scans(raw_log.scans, ref_log.scans)
    field = LikelihoodField(grid, LocalizationParams())
    fit = reference_fit(field, ref_log.scans)
    to_map, _ = reference_offset(field, ref_log.scans)
    raw = raw_log.scans[:3000] if quick else raw_log.scans
    print(f"{run.title}: read and mapped in {time.perf_counter() - t0:.1f} s; {int((pairs >= 0).sum())} of "
          f"{len(ref_log)} reference scans paired; {int((fit > FIT).sum())} do not fit their own map; the map places "
          f"them {np.nanmean(to_map):.4f} m (mean) / {np.nanmax(to_map):.3f} m (max) from their poses; laser offset "
          f"{raw_log.laser_offset()}", flush=True)
    return Loaded(run, raw, grid, pairs, np.array([s.pose for s in ref_log.scans]), raw_log.laser_offset(),
                  fit <= FIT, to_map)


def bench_update(d: Loaded) -> list[str]:
    loc = make_localizer(d.grid, particles=2000, beams=60, seed=1)
    loc.initialize(d.ref_poses[0], INIT_COV)
    scans = d.raw[:400]
    state = {"i": 0}

    def one_update():
        s = scans[state["i"] % len(scans)]
        state["i"] += 1
        loc._force = True  # a full filter step every call, whatever the odometry did
        loc.update(s.odom, s.ranges, s.angles, s.max_range)

    for s in scans[:50]:
        loc.update(s.odom, s.ranges, s.angles, s.max_range)
    s = scans[200]
    bx, by, _, _ = beam_end_points(s.ranges, s.angles, s.max_range, loc.params)
    field = loc.field
    table, outside = field.table(s.max_range, loc.params.sigma_hit)
    out = np.empty(len(loc.particles))
    args = (loc.particles, bx, by, table, outside, field.origin[0], field.origin[1], 1.0 / field.resolution, out)
    t_upd, t_ser, t_par = median_times(
        [one_update, lambda: K.score_particles(*args), lambda: K.score_particles_parallel(*args)], 20, 9)
    ok = "meets" if t_upd <= 0.010 else "misses"
    print(f"update 2000 × {bx.size}: {1e3 * t_upd:.2f} ms ({ok} the 10 ms target); kernel serial "
          f"{1e3 * t_ser:.3f} ms, parallel {1e3 * t_par:.3f} ms")
    return [
        "| step | time | target |",
        "|---|---:|---:|",
        f"| one filter update, 2,000 particles × {bx.size} beams (motion, measurement, resampling, estimate, "
        f"scan-match refinement) | {1e3 * t_upd:.2f} ms | ≤ 10 ms ({ok}) |",
        f"| measurement kernel alone, one thread | {1e3 * t_ser:.3f} ms | |",
        f"| measurement kernel alone, all threads | {1e3 * t_par:.3f} ms | |",
    ]


VARIANTS = [
    ("plain AMCL (filter every 0.2 m / 30°)", dict(plain=True)),
    ("plain AMCL, filter every 5 cm / 0.1 rad", dict(plain=True, update_min_d=0.05, update_min_a=0.1)),
    ("+ random term over the field's range", dict(plain=True, update_min_d=0.05, update_min_a=0.1,
                                                  z_rand_span="field")),
    ("+ tempering, scan-match refinement fed back to the cloud", dict(coast_fit=0.0)),
    ("+ coasting on odometry through scans the map does not explain (default)", dict()),
]


#: Seeds of the default filter's tracking runs (the first is every variant's).
TRACK_SEEDS = (7, 1, 2, 3)


def run_tracking(d: Loaded, label, seed=TRACK_SEEDS[0], **opts):
    plain = opts.pop("plain", False)
    loc = make_localizer(d.grid, seed=seed, plain=plain, sensor_offset=d.offset, **opts)
    t0 = time.perf_counter()
    res = replay(loc, d.raw, init=d.ref_poses[0], cov=INIT_COV)
    secs = time.perf_counter() - t0
    ok = (d.pairs >= 0) & (d.pairs < len(d.raw))
    pe, he = track_errors(res.poses[d.pairs[ok]], d.ref_poses[ok])
    good = d.fits[ok]
    row = (label, pe.mean(), np.percentile(pe, 95), pe.max(), math.degrees(he.mean()), math.degrees(he.max()),
           pe[good].mean(), pe[good].max(), 1e3 * np.median(res.seconds[res.updated]))
    print(f"{d.run.key} {label:55s} pos mean {row[1]:.4f} p95 {row[2]:.3f} max {row[3]:.3f} m; heading mean "
          f"{row[4]:.3f}° max {row[5]:.2f}°; where the reference fits: mean {row[6]:.4f} max {row[7]:.3f} m; "
          f"{row[8]:.2f} ms/update; {secs:.0f} s", flush=True)
    return row, pe, he, res, loc


#: Reference travel (m) a global localization is scored over.
GLOBAL_TRAVEL = 40.0
GLOBAL_SEEDS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10)
#: The coarse-to-fine schedule with one part taken away (Intel, 5 seeds each).
GLOBAL_ABLATIONS = [
    ("hit term 0.2 m throughout (no coarse phase)", dict(global_sigma_hit=0.2)),
    ("filter every 5 cm / 0.1 rad while global", dict(global_update_min_d=0.05, global_update_min_a=0.1)),
    ("5,000 particles while global", dict(global_particles=5000)),
]


def run_global(d: Loaded, seed, **opts):
    """Global localization over the first GLOBAL_TRAVEL metres of reference travel: (convergence
    distance, worst error after it, particles at the start, at the end, filter runs until converged)."""
    loc = make_localizer(d.grid, seed=seed, sensor_offset=d.offset, **opts)
    paired = np.flatnonzero(d.pairs >= 0)
    dist_all = travelled(d.ref_poses[paired])
    last = paired[min(int(np.searchsorted(dist_all, GLOBAL_TRAVEL)), len(paired) - 1)]
    stop = min(len(d.raw), int(d.pairs[last]) + 1)
    res = replay(loc, d.raw[:stop], global_localization=True)
    ok = (d.pairs >= 0) & (d.pairs < stop)
    pe, _ = track_errors(res.poses[d.pairs[ok]], d.ref_poses[ok])
    dist = travelled(d.ref_poses[ok])
    conv = convergence_distance(pe, dist, 0.2)
    worst = float(pe[dist >= conv].max()) if math.isfinite(conv) else math.inf
    return conv, worst, loc.params.global_particles, int(res.n_particles[-1]), loc.stats.converged_after


def _dist(c: float) -> str:
    return f"{c:.1f} m" if math.isfinite(c) else "never"


def tracking_section(d: Loaded, quick: bool) -> list[str]:
    rows, curves, best = [], {}, None
    for label, opts in VARIANTS:
        row, pe, he, res, loc = run_tracking(d, label, **dict(opts))
        rows.append(row)
        curves[label] = (pe, he)
        if label.endswith("(default)"):
            best = (pe, he, res, loc)
    for seed in TRACK_SEEDS[1:]:
        rows.append(run_tracking(d, f"default, seed {seed}", seed=seed)[0])
    ok = (d.pairs >= 0) & (d.pairs < len(d.raw))
    dist = travelled(d.ref_poses[ok])
    plain_pe, plain_he = curves[VARIANTS[0][0]]
    pe, he, res, loc = best
    image = ROOT / "docs" / "images" / f"localize_{d.run.key}.png"
    image.parent.mkdir(parents=True, exist_ok=True)
    save_error_png(image, dist, [("plain AMCL", plain_pe, plain_he), ("this filter", pe, he)],
                   f"{d.run.title}, raw odometry localized in the corrected map: error against the corrected poses")
    save_track_png(image.with_name(f"localize_{d.run.key}_track.png"), loc, res, reference=d.ref_poses[ok],
                   title=f"{d.run.title}: raw odometry localized in the corrected map")
    n_fit = int(d.fits[ok].sum())
    table = ["| filter | mean position error | p95 | max | mean heading error | max | where the reference fits: "
             "mean | max | update (median) |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, m, p95, mx, hm, hx, gm, gx, ms in rows:
        table.append(f"| {label} | {m:.4f} m | {p95:.3f} m | {mx:.3f} m | {hm:.3f}° | {hx:.2f}° | {gm:.4f} m | "
                     f"{gx:.3f} m | {ms:.2f} ms |")
    defaults = [r for r in rows if r[0].endswith("(default)") or r[0].startswith("default, seed")]
    m = defaults[0]
    meets = all(r[1] <= 0.04 and r[4] <= 0.8 and r[3] <= 0.3 for r in defaults)
    where = ""
    if (pe > 0.5).any():
        k = int(np.argmax(pe > 0.5))
        near = d.fits[ok][max(0, k - 20):k + 21]
        where = (f" The error first exceeds 0.5 m at reference pose {k:,} ({dist[k]:.0f} m of travel; mean "
                 f"{pe[:k].mean():.4f} m, max {pe[:k].max():.3f} m before it), where {int((~near).sum())} of the "
                 f"{near.size} reference poses around it do not fit their own map.")
    return [
        f"### {d.run.title}",
        "",
        f"{d.run.title} ({d.run.credit}): map built at 5 cm from `{d.run.corrected}` (a passing beam's evidence `prob_miss` = {MAP_MODEL.prob_miss}, `MAP_MODEL`), the raw run `{d.run.raw}` "
        f"({len(d.raw):,} scans{' (quick run)' if quick else ''}, raw wheel odometry; laser offset "
        f"{d.offset[0]:+.2f} m) localized in it with 2,000 particles and 60 beams; errors against the "
        f"{int(ok.sum()):,} corrected poses, {n_fit:,} of which fit their own map (median end-point distance ≤ "
        f"{FIT} m); tracking from the first corrected pose.",
        "",
        *table,
        "",
        f"Default filter (seed {TRACK_SEEDS[0]}): mean {m[1]:.4f} m / {m[4]:.3f}°, max {m[3]:.3f} m; seeds "
        f"{', '.join(map(str, TRACK_SEEDS))}: mean {min(r[1] for r in defaults):.4f}–"
        f"{max(r[1] for r in defaults):.4f} m, "
        f"max {min(r[3] for r in defaults):.3f}–{max(r[3] for r in defaults):.3f} m: "
        f"{'meets' if meets else 'misses'} the targets (mean ≤ 0.04 m, ≤ 0.8°, max ≤ 0.3 m, every seed).{where}",
        "",
        f"The map places the reference's own scans (scan match from each reference pose) "
        f"{np.nanmean(d.to_map[ok]):.4f} m from their poses on average, {np.nanpercentile(d.to_map[ok], 95):.3f} m "
        f"p95, {np.nanmax(d.to_map[ok]):.3f} m at most ({int((d.to_map[ok] > 0.3).sum())} beyond 0.3 m, "
        f"{int(np.isnan(d.to_map[ok]).sum())} unmatched; the max may be a match that slid to another place): an "
        "estimate that follows the map shows about that error against this reference while it is right about the map.",
        "",
        f"![error curves](docs/images/localize_{d.run.key}.png)",
        "",
    ]


def global_section(d: Loaded, seeds, ablate: bool) -> list[str]:
    glob = []
    for seed in seeds:
        g = run_global(d, seed)
        glob.append(g)
        print(f"{d.run.key} global localization seed {seed}: converged after {_dist(g[0])} of travel, worst error "
              f"after that {g[1]:.3f} m ({g[2]:,} → {g[3]:,} particles, converged after {g[4]} filter runs)",
              flush=True)
    out = [
        f"Global localization on {d.run.title}, scored over the first {GLOBAL_TRAVEL:.0f} m of reference travel:",
        "",
        "| seed | convergence distance | worst error after it | filter runs until converged | particles |",
        "|---:|---:|---:|---:|---:|",
        *[f"| {seed} | {_dist(c)} | {w:.3f} m | {runs} | {n0:,} → {n1:,} |"
          for seed, (c, w, n0, n1, runs) in zip(seeds, glob)],
        "",
        f"{sum(g[0] <= 30.0 for g in glob)} of {len(glob)} seeds converge within 30 m.",
        "",
    ]
    if ablate:
        rows = []
        for label, opts in GLOBAL_ABLATIONS:
            convs = [run_global(d, seed, **opts)[0] for seed in seeds[:5]]
            rows.append(f"| {label} | {', '.join(_dist(c) for c in convs)} |")
            print(f"{d.run.key} global localization, {label}: " + ", ".join(_dist(c) for c in convs), flush=True)
        out += [f"Each part of the schedule taken away (seeds {', '.join(map(str, seeds[:5]))}):", "",
                "| global phase | convergence distance per seed |", "|---|---|", *rows, ""]
    return out


#: Kidnappings per run: tracking from a reference pose, the robot carried away unseen KIDNAP_SETTLE
#: scans later past KIDNAP_SKIP scans (odometry continuous), scored over KIDNAP_TRAVEL m after that.
KIDNAPS = 10
KIDNAP_SETTLE = 150
KIDNAP_SKIP = 400
KIDNAP_TRAVEL = 25.0


def kidnap_section(d: Loaded, seed: int = 3) -> list[str]:
    pairs = np.where(d.pairs < len(d.raw), d.pairs, -1)
    paired = np.flatnonzero(pairs >= 0)
    room = paired[pairs[paired] + KIDNAP_SETTLE + KIDNAP_SKIP + 1000 < len(d.raw)]
    starts = room[np.linspace(0, len(room) - 1, KIDNAPS).astype(int)]
    rows, found = [], 0
    for start in starts:
        args = dict(start=int(start), at=int(pairs[start]) + KIDNAP_SETTLE, skip=KIDNAP_SKIP, travel=KIDNAP_TRAVEL,
                    cov=INIT_COV)
        loc = make_localizer(d.grid, seed=seed, sensor_offset=d.offset)
        k = replay_kidnapped(loc, d.raw, pairs, d.ref_poses, **args)
        off = replay_kidnapped(make_localizer(d.grid, seed=seed, sensor_offset=d.offset, relocalize_after=0), d.raw,
                               pairs, d.ref_poses, **args)
        # back for good, not merely once: a wrong track can cross the robot's path (Freiburg 079, ref 2,579:
        # 0.09 m at 7.5 m of travel while lost, 8 m off after it)
        ok = k.recovered <= 20.0 and k.lost_between
        found += ok
        worst = float(k.after[k.travel >= k.first].max()) if math.isfinite(k.first) else math.inf
        landed = paired[pairs[paired] >= args["at"] + KIDNAP_SKIP][: k.after.size]
        fits = float(d.fits[landed].mean())
        shown = f"{worst:.2f} m" if math.isfinite(worst) else "—"
        rows.append(f"| {start:,} | {k.jump:.1f} m | {'yes' if k.lost_between else 'no'} | {_dist(k.first)} | "
                    f"{_dist(k.recovered)} | {shown} | {loc.stats.searches} / {loc.stats.relocalized} | "
                    f"{_dist(off.first)} | {100 * fits:.0f} % |")
        print(f"{d.run.key} kidnapped from reference pose {start}: carried {k.jump:.1f} m, lost raised "
              f"{k.lost_between}, back within 0.2 m after {_dist(k.first)} (for good after {_dist(k.recovered)}, worst "
              f"after {shown}), {loc.stats.searches} searches, {loc.stats.relocalized} relocalized; without the "
              f"search {_dist(off.first)}; {100 * fits:.0f} % of the reference poses after it fit their own map",
              flush=True)
    return [
        f"Kidnapping on {d.run.title} (seed {seed}): tracking from a reference pose, {KIDNAP_SETTLE} scans later the "
        f"robot is carried past {KIDNAP_SKIP} scans unseen (its odometry continues without a jump: "
        "`replay.kidnapped`); distances are reference travel after the kidnapping, over "
        f"{KIDNAP_TRAVEL:.0f} m.",
        "",
        "| from reference pose | carried | lost raised | back within 0.2 m after | within 0.2 m to the end after | "
        "worst error after it is back | searches / relocalized | without the search: back after | reference poses "
        "after it that fit their own map |",
        "|---:|---:|:---:|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
        f"{found} of {len(starts)} kidnappings back within 0.2 m to the end of the stretch within 20 m of travel, "
        "with the lost flag raised in between.",
        "",
    ]


#: First words of the kidnapping part of the ``localize`` section (``--kidnap`` rewrites from there).
KIDNAP_HEAD = "Kidnapping on "


def write_part(name: str, head: str, body: str) -> None:
    """Replace the end of BENCHMARKS.md's section ``name``, from its first line starting with ``head``
    to the section's "Measured" line, by ``body`` with a line saying when it was measured."""
    text = BENCHMARKS_MD.read_text()
    start, end = text.index(f"<!-- {name}:start -->"), text.index(f"<!-- {name}:end -->")
    section = text[start:end]
    cut = section.index("\n" + head) + 1
    measured = section.rindex("\n_Measured ") + 1
    stamp = datetime.date.today().isoformat()
    part = f"{body}\n\n_Kidnapping tables measured {stamp} (`bench_localize.py --kidnap`)._\n\n"
    text = text[: start + cut] + part + text[start + measured:]
    BENCHMARKS_MD.write_text(text)


def main() -> None:
    quick = "--quick" in sys.argv
    data = shared_data()
    if data is None:
        return
    carmen = data / "carmen"
    loaded = [load(carmen, run, quick) for run in RUNS]
    if "--kidnap" in sys.argv:
        body = [line for d in loaded for line in kidnap_section(d)]
        write_part("localize", KIDNAP_HEAD, "\n".join(body).rstrip())
        return
    speed = bench_update(loaded[0])
    body = ["## Monte Carlo localization (`benchmarks/bench_localize.py`)", "", *speed, ""]
    if quick:
        body.insert(2, "_Quick run: the first 3,000 scans of each run, three global seeds, no ablations._\n")
    body += [
        "Both runs with one set of defaults (`occmap.localize.replay.DEFAULTS`). Targets: mean position error "
        "≤ 0.04 m, mean heading error ≤ 0.8°, max ≤ 0.3 m, no divergence; global localization converged within "
        "30 m of travel. Until its dominant mode holds 98 % of the weight a global localization runs coarse to "
        "fine: 20,000 particles over the free space, hit term σ = 1 m, a filter run every 0.2 m / 30° (AMCL's "
        "spacing), no scan-match refinement; then it tracks with the defaults and 2,000 particles. Convergence "
        "distance: the distance travelled to the first reference pose from which the estimate stays within "
        "0.2 m of the reference to the end of the stretch.",
        "",
    ]
    seeds = GLOBAL_SEEDS[:3] if quick else GLOBAL_SEEDS
    for d in loaded:
        body += tracking_section(d, quick)
    for d in loaded:
        body += global_section(d, seeds, ablate=d.run.key == "intel" and not quick)
    for d in loaded:
        body += kidnap_section(d)
    write_section("localize", "\n".join(body).rstrip())


if __name__ == "__main__":
    main()

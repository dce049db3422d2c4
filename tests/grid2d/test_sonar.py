"""SonarModel / insert_sonar: cone geometry, angular weighting, max-range readings, the nearest-
transducer sectors of Thrun's Table 9.2, real data, and the Udacity exercise's reference picture."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.grid2d import OccupancyGrid2D, SonarModel
from occmap.logodds import logit


def one_reading(r, max_range=5.0, model=SonarModel()):
    g = OccupancyGrid2D(0.05, size=(6.0, 6.0), origin=(-3.0, -3.0))
    counts = g.insert_sonar((0.0, 0.0, 0.0), [r], [0.0], max_range=max_range, model=model)
    return g, counts


def test_cone_is_free_before_the_arc_and_occupied_on_it():
    g, counts = one_reading(2.0)
    assert counts == {"scans": 1, "points": 1, "dropped": 0, "beyond_max_range": 0}
    v = lambda x, y: g.log_odds_at([[x, y]])[0]  # noqa: E731
    assert v(1.0125, 0.0125) < 0 and v(1.9875, 0.0125) > 0  # on the axis: free, then the arc
    assert math.isnan(v(2.5, 0.0))  # beyond the arc: untouched
    assert math.isnan(v(1.0, 0.3))  # 16.7° off the axis, outside the 15° cone
    # the axis speaks loudest: full weight on it, less towards the rim
    cx, cy = g.cell_to_world(g.world_to_cell([[1.0125, 0.0125]]))[0]  # the weight uses the cell centre
    assert v(1.0125, 0.0125) == pytest.approx(logit(0.4) * (1 - (math.atan2(cy, cx) / math.radians(7.5)) ** 2), rel=1e-5)
    assert 0 > v(1.0, 0.11) > v(1.0125, 0.0125)


def test_no_echo_clears_the_cone_up_to_max_range_and_marks_nothing():
    g, counts = one_reading(5.11, max_range=2.5)
    assert counts["beyond_max_range"] == 1
    lo = g.log_odds()[g.observed]
    assert (lo < 0).all() and lo.size > 100
    assert math.isnan(g.log_odds_at([[2.6, 0.0]])[0])


def test_an_echo_near_max_range_marks_nothing_beyond_it():
    g, counts = one_reading(2.45, max_range=2.5, model=SonarModel(arc=0.2))
    assert counts["beyond_max_range"] == 0
    assert g.log_odds_at([[2.4875, 0.0125]])[0] > 0  # on the arc, inside max range
    assert math.isnan(g.log_odds_at([[2.5125, 0.0125]])[0])  # the arc would reach 2.55 m: cut at 2.5


def test_ignore_max_range_skips_readings_beyond_it_and_clears_at_it():
    model = SonarModel(ignore_max_range=True)
    g, counts = one_reading(5.11, max_range=2.5, model=model)
    assert counts == {"scans": 1, "points": 0, "dropped": 0, "beyond_max_range": 1}
    assert not g.observed.any()
    g, counts = one_reading(2.5, max_range=2.5, model=model)  # exactly at max range: a no-echo
    assert counts["points"] == 1 and counts["beyond_max_range"] == 1
    lo = g.log_odds()[g.observed]
    assert (lo < 0).all() and lo.size > 100


def test_min_range_and_uniform_weighting():
    g, counts = one_reading(0.1, model=SonarModel(min_range=0.17))
    assert counts["dropped"] == 1 and not g.observed.any()
    g, _ = one_reading(2.0, model=SonarModel(weighting="uniform"))
    v = g.log_odds_at([[1.0, 0.11], [1.0125, 0.0125]])
    assert v == pytest.approx([logit(0.4)] * 2, rel=1e-6)  # the rim as loud as the axis


def test_nearest_sectors_give_each_direction_to_one_transducer():
    model = SonarModel(beam_width=math.inf, sectors="nearest", weighting="uniform")
    lo, hi = model.sector_bounds(np.radians([-90, -37.5, -22.5, -7.5, 7.5, 22.5, 37.5, 90]))
    assert np.degrees(lo) == pytest.approx([-90, -26.25, -7.5, -7.5, -7.5, -7.5, -7.5, -26.25])
    assert np.degrees(hi) == pytest.approx([26.25, 7.5, 7.5, 7.5, 7.5, 7.5, 26.25, 90])
    # unwrapped (the exercise): the outer transducers reach out to ±inf
    lo, hi = SonarModel(sectors="nearest", wrap_angles=False).sector_bounds(np.radians([-90.0, 0.0, 90.0]))
    assert lo[0] == -np.inf and hi[2] == np.inf and np.degrees(hi[0]) == pytest.approx(45)
    # a repeated bearing: the first transducer takes the sector
    lo, hi = model.sector_bounds([0.0, 0.0])
    assert (lo[0], hi[0]) == (-np.inf, np.inf) and lo[1] == hi[1] == 0.0  # a lone bearing: the whole circle
    # ahead (0.5 m) and left (2.0 m): sectors −135°…45° and 45°…135° around the circle
    g = OccupancyGrid2D(0.05, size=(6.0, 6.0), origin=(-3.0, -3.0))
    g.insert_sonar((0.0, 0.0, 0.0), [0.5, 2.0], [0.0, math.pi / 2], max_range=5.0, model=model)
    at = lambda deg, r=1.0: g.log_odds_at([[r * math.cos(math.radians(deg)), r * math.sin(math.radians(deg))]])[0]  # noqa: E731
    assert math.isnan(at(30))  # the ahead reading's, beyond its 0.5 m: untouched though inside the left cone
    assert at(30, 0.3) == pytest.approx(logit(0.4), rel=1e-6)
    assert at(60) == pytest.approx(logit(0.4), rel=1e-6)  # the left one's free space
    assert at(120) == pytest.approx(logit(0.4), rel=1e-6)  # behind-left: still the left one's
    assert math.isnan(at(-90))  # behind-right: the ahead one's, beyond 0.5 m


def test_unwrapped_angles_give_cells_to_the_exercises_transducer():
    """Heading π, transducers right (−90°, 1 m) and left (+90°, 2 m): the cell 1 m to the left,
    at world (0, −1), is the left one's free space; compared unwrapped (atan2 − θ = −270°) it is
    nearer −90° and lands on the right one's echo arc, as in the Udacity exercise."""
    kw = dict(beam_width=math.inf, sectors="nearest", weighting="uniform", arc=0.2)
    values = []
    for wrap in (True, False):
        g = OccupancyGrid2D(0.05, size=(6.0, 6.0), origin=(-3.0, -3.0))
        g.insert_sonar((0.0, 0.0, math.pi), [1.0, 2.0], [-math.pi / 2, math.pi / 2], max_range=5.0,
                          model=SonarModel(wrap_angles=wrap, **kw))
        values.append(g.log_odds_at([[0.0125, -0.9875]])[0])
    assert values[0] < 0 < values[1]


def test_invalid_readings_and_arguments():
    g = OccupancyGrid2D(0.1, size=(4.0, 4.0), origin=(-2.0, -2.0))
    counts = g.insert_sonar(np.zeros((1, 3)), [[np.nan, -1.0, 1.0]], [0.0, 1.0, 2.0], max_range=3.0)
    assert counts["dropped"] == 2 and counts["points"] == 1
    with pytest.raises(ShapeError):
        g.insert_sonar(np.zeros((1, 3)), [[1.0, 1.0]], [0.0], max_range=3.0)
    with pytest.raises(InvalidArgumentError):
        SonarModel(beam_width=0.0)
    with pytest.raises(InvalidArgumentError):
        SonarModel(beam_width=math.inf)  # only the nearest-transducer sectors may drop the cone
    with pytest.raises(InvalidArgumentError):
        SonarModel(sectors="widest")
    with pytest.raises(InvalidArgumentError):
        SonarModel(weighting="linear")
    with pytest.raises(InvalidArgumentError):
        SonarModel(min_range=-1.0)
    assert SonarModel(beam_width=math.inf, sectors="nearest").beam_width == math.inf


def test_shared_sonar_ring_maps_its_corridor(data_dir):
    """The shared 8-sonar data set: the robot drives a corridor; both corridor walls appear as
    occupied cells on either side of its path."""
    from occmap.io.sonar import read_sonar_ring

    log = read_sonar_ring(data_dir / "sonar")
    assert log.ranges.shape == (413, 8) and log.max_range == pytest.approx(5.11)
    g = OccupancyGrid2D(0.1, size=(30.0, 15.0), origin=(-6.0, -10.0))
    g.insert_sonar(log.poses, log.ranges, log.bearings, max_range=log.max_range,
                      model=SonarModel(beam_width=math.radians(20), arc=0.2))
    ml = g.maximum_likelihood()
    path = log.poses[(log.poses[:, 0] > 1.0) & (log.poses[:, 0] < 8.0)]  # the straight corridor part
    y = np.median(path[:, 1])
    column = ml[:, g.world_to_cell([[4.0, y]])[0, 1]]
    rows = np.flatnonzero(column == 1)
    centre = g.world_to_cell([[4.0, y]])[0, 0]
    assert (rows > centre).any() and (rows < centre).any()  # a wall on each side
    assert column[centre] == 0  # and free where the robot drove


def test_shared_sonar_ring_reproduces_the_exercise_reference(data_dir):
    """Issue 3: the shared sonar set mapped with the Udacity exercise's settings
    (:meth:`SonarModel.udacity_exercise`, Z_max 5 m, its grid and offsets, no clamping) agrees with
    the exercise's own picture, ``Map_reference.png``, cell by cell. Measured: 99.84 % of the
    44,506 readable cells alike, free IoU 0.9974, occupied IoU 0.966; all but one of the 69
    differing cells have exactly as much free as occupied evidence (l = 0 in exact arithmetic),
    where the exercise's colour is float64 rounding noise. occmap's own cone model gives the
    corridor but not the picture (about 82 % alike, free IoU 0.58)."""
    import sonar_reference as sd
    from occmap.io.sonar import read_sonar_ring

    log = read_sonar_ring(data_dir / "sonar")
    ref, box = sd.reference_cells(data_dir / "sonar" / "Map_reference.png")
    assert box == (100, 60, 720, 540)  # matplotlib's default axes in an 800 × 600 figure
    readable = ref != sd.UNREADABLE
    assert readable.mean() > 0.98
    assert 0.25 < (ref == sd.FREE).mean() < 0.28 and 0.03 < (ref == sd.OCCUPIED).mean() < 0.04

    g = sd.map_like_exercise(log)
    assert g.stats == {"scans": 413, "points": 2213, "dropped": 0, "beyond_max_range": 1093}  # 1091 beyond 5 m, 2 at it
    ours = sd.exercise_cells(g)
    fig = sd.agreement(ours, ref)
    assert fig["cells"] == readable.sum()
    assert fig["agree"] >= 0.995 and fig["free_iou"] >= 0.99 and fig["occupied_iou"] >= 0.93
    # what differs is (all but a handful) cells whose evidence cancels exactly
    L = np.asarray(g.log_odds(), dtype=np.float64)[::-1].T
    differ = (ours != ref) & readable
    assert (differ & (np.abs(L) > 0.2)).sum() <= 3

    # the reference needs the exercise's quirks: occmap's cone model is far from it
    cone = sd.agreement(sd.exercise_cells(sd.map_with_cone_model(log)), ref)
    assert cone["agree"] < 0.9 and cone["free_iou"] < 0.7

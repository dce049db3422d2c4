"""The relative pose error against hand-derived values and its invariances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.geometry.se2 import SE2
from occmap.slam import relative_pose_error


def _line(n=11, step=0.5):
    return np.column_stack([step * np.arange(n), np.zeros(n), np.zeros(n)])


def test_a_stretched_estimate_errs_by_the_stretch_of_each_one_metre_segment():
    ref = _line()  # every 0.5 m: a 1 m segment is two steps
    est = ref.copy()
    est[:, 0] *= 1.1
    e = relative_pose_error(est, ref)
    assert e.start.tolist() == list(range(9)) and e.end.tolist() == list(range(2, 11))
    np.testing.assert_allclose(e.translation, 0.1, atol=1e-12)
    np.testing.assert_allclose(e.rotation, 0.0, atol=1e-12)


def test_a_heading_error_at_one_pose_counts_in_the_segments_that_touch_it():
    ref = _line()
    est = ref.copy()
    est[4, 2] = 0.1  # the robot thought it faced 0.1 rad left at x = 2 m, nothing else changed
    e = relative_pose_error(est, ref)
    touched = (e.start == 4) | (e.end == 4)
    np.testing.assert_allclose(e.rotation[touched], 0.1, atol=1e-12)
    np.testing.assert_allclose(e.rotation[~touched], 0.0, atol=1e-12)
    # starting at pose 4 facing 0.1 rad, 1 m "ahead" lands at (cos 0.1, sin 0.1) in the reference's frame
    k = int(np.flatnonzero(e.start == 4)[0])
    assert e.translation[k] == pytest.approx(math.hypot(math.cos(0.1) - 1.0, math.sin(0.1)), abs=1e-12)


def test_the_error_does_not_depend_on_the_frame_of_either_trajectory(rng):
    ref = np.cumsum(rng.normal(0.0, 0.3, (60, 3)), axis=0)
    est = ref + rng.normal(0.0, 0.02, ref.shape)
    moved = (SE2(np.array([3.0, -2.0, 1.2])) @ SE2(est)).xytheta
    a, b = relative_pose_error(est, ref), relative_pose_error(moved, ref)
    np.testing.assert_allclose(a.translation, b.translation, atol=1e-9)
    np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-9)
    s = a.summary()
    assert s["segments"] == len(a.start) > 0
    assert s["translation_mean"] == pytest.approx(a.translation.mean())
    assert s["rotation_deg_max"] == pytest.approx(math.degrees(a.rotation.max()))


def test_non_finite_rows_take_part_in_no_segment_and_bad_input_is_named():
    ref = _line()
    est = ref.copy()
    est[3] = np.nan
    e = relative_pose_error(est, ref)
    assert 3 not in e.start and 3 not in e.end and len(e.start) > 0
    assert relative_pose_error(ref[:1], ref[:1]).summary()["segments"] == 0
    with pytest.raises(ShapeError, match="both be"):
        relative_pose_error(ref[:5], ref)
    with pytest.raises(InvalidArgumentError, match="distance"):
        relative_pose_error(ref, ref, distance=0.0)

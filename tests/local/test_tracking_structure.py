"""Confirmed tracks must not take structure for themselves: the causes of the tracks that real logs
confirmed on walls (issue 19, BENCHMARKS "Tracking on real logs"), each reproduced small."""

from __future__ import annotations

import math

import numpy as np

from occmap.local.tracking.layer import ObjectLayer

SENSOR = np.array([0.0, 0.0])


def _person(centre, n: int = 9, radius: float = 0.2) -> np.ndarray:
    """Returns of a person's near side (an arc facing the sensor at the origin)."""
    c = np.asarray(centre, dtype=float)
    facing = math.atan2(-c[1], -c[0])
    a = facing + np.linspace(-0.9, 0.9, n)
    return c + radius * np.stack([np.cos(a), np.sin(a)], -1)


def _scan(layer: ObjectLayer, pts: np.ndarray, stamp: float, free, occupied=None, walled=None) -> np.ndarray:
    """One scan of returns ``pts`` through ``layer``; the kinds after it (1 static, 2 moving)."""
    n = len(pts)
    kinds = np.ones(n, np.int8)
    flag = lambda v: np.broadcast_to(np.asarray(v, bool), (n,)).copy()  # noqa: E731
    layer.sort_returns(pts, kinds, flag(free), flag(False if occupied is None else occupied), SENSOR, stamp,
                       walled=None if walled is None else flag(walled))
    return kinds


def _walker(layer: ObjectLayer) -> float:
    """A person walking at 1 m/s along y = 3 through seen free space until confirmed; the last stamp."""
    for k in range(30):
        t = 0.1 * k
        _scan(layer, _person((-1.5 + t, 3.0)), t, free=True)
        if layer.tracker.tracks().confirmed.any():
            return t
    raise AssertionError("the walker was never confirmed")


def test_a_track_does_not_explain_returns_beside_known_occupied_cells():
    # Freiburg 079 (corrected and raw), raw Intel: a confirmed person's footprint reached a wall, a
    # door frame or a cubicle's side; the returns there lay a cell beside the wall's occupied cells
    # (the registration's slips of 1 - 2 degrees), were taken as the track's, kept it confirmed with
    # no return in open space and pulled it along the wall for metres
    layer = ObjectLayer()
    t = _walker(layer) + 0.1
    x = float(layer.tracker.tracks().x[0]) + 0.1
    wall = np.stack([np.full(9, x), np.linspace(2.8, 3.2, 9)], -1)  # on the footprint, beside the wall's cells
    kinds = _scan(layer, np.concatenate([_person((x, 3.0)), wall]), t, free=[True] * 9 + [False] * 9,
                  walled=[False] * 9 + [True] * 9)
    assert (kinds[:9] == 2).all()  # the person's own returns, in open space, still move
    assert (kinds[9:] == 1).all()  # the wall's stay static: they mark the map

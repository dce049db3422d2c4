"""The one 3D ray walk ends on rays with no direction: an end a hair from the origin (the float32
length underflows to 0), in the same or a neighbouring voxel, and ends so far apart that the
float32 length overflows (in the key range only at absurd resolutions, such as a .bt file's
``res 1e300``). OctoMap steps forever on both. Each case runs in a subprocess with a timeout: a
walk that never ends cannot be interrupted inside a kernel."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np

_PRELUDE = """
import json
import numpy as np
from occmap.io.octomap import decode_bt, encode_bt
from occmap.octree import OcTree
"""


def _run(code: str) -> dict:
    """Run ``code`` in a fresh interpreter (which prints one JSON object); fails (instead of
    hanging) when it takes longer than a cold compile of the kernels could."""
    r = subprocess.run([sys.executable, "-c", _PRELUDE + textwrap.dedent(code)], capture_output=True, text=True,
                       timeout=400)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_rays_a_hair_long_end_after_the_origin_voxel():
    """An end 1e-30 m from the origin, diagonally across a voxel corner: the origin's voxel is
    free and the end's occupied, whichever walk inserts it (insertRay; a small scan's block walk;
    a large scan's dense cube); an end 1e-30 m away in the origin's own voxel marks it occupied;
    a ray cast along such a direction has none."""
    out = _run("""
        probes = [[0.05, 0.05, 0.05], [-0.05, -0.05, 0.05], [-0.05, 0.05, 0.05], [0.05, -0.05, 0.05]]
        end = [[-1e-30, -1e-30, 0.0]]
        res = {}
        t = OcTree(0.1)
        t.insert_rays(np.zeros(3), end)
        res["insert_rays"] = t.occupancy_at(probes).tolist()
        for n in (10, 5000):
            t = OcTree(0.1)
            t.insert_point_cloud(np.repeat(end, n, axis=0), np.zeros(3))
            res[f"cloud{n}"] = t.occupancy_at(probes).tolist()
        t = OcTree(0.1)
        t.insert_point_cloud([[1e-30, 1e-30, 0.0]], np.zeros(3))
        res["same_voxel"] = t.occupancy_at(probes).tolist()
        hit, ends = OcTree(0.1).cast_ray(np.zeros(3), [[-1e-30, -1e-30, 0.0]], ignore_unknown=True)
        res["cast"] = [bool(hit[0]), bool(np.isnan(ends).all())]
        print(json.dumps(res))
    """)
    for name in ("insert_rays", "cloud10", "cloud5000"):
        assert out[name] == [0, 1, -1, -1], name
    assert out["same_voxel"] == [1, -1, -1, -1]
    assert out["cast"] == [False, True]


def test_rays_too_long_for_float32_at_an_absurd_resolution_are_dropped():
    """A .bt with ``res 1e300``: ends ±3e38 m (float32's largest values) lie in the key range, but
    their ray's float32 length overflows; inserting it drops the ray (counted) instead of walking
    forever, and a cast along such a direction ends."""
    out = _run("""
        small = OcTree(0.1)
        small.insert_point_cloud(np.random.default_rng(0).normal(size=(100, 3)), np.zeros(3))
        tree = decode_bt(encode_bt(small).replace(b"res 0.1\\n", b"res 1e300\\n"))
        res = {"resolution": tree.resolution}
        res["rays"] = tree.insert_rays([-3e38, 0.0, 0.0], [[3e38, 0.0, 0.0]])
        res["cloud"] = tree.insert_point_cloud([[3e38, 3e38, 0.0], [1.0, 0.0, 0.0]], np.zeros(3))
        hit, ends = tree.cast_ray([-3e38, 0.0, 0.0], [[3e38, 3e38, 0.0]], ignore_unknown=True)
        res["cast"] = bool(hit[0])
        print(json.dumps(res))
    """)
    assert out["resolution"] == 1e300
    assert out["rays"] == 0
    assert out["cloud"]["points"] == 1 and out["cloud"]["dropped"] == out["cloud"]["outside_key_range"] == 1
    assert out["cast"] is False


def test_walk_state_by_hand():
    """:mod:`raywalk` by hand: the float32 normalisation, and a ray from the corner of voxel
    32768 along (0.6, 0.8, 0) at 1 m: borders at t = 1/0.6 and 1/0.8, every 1/0.6 and 1/0.8 after,
    so the steps go y (1.25), x (1.67), y (2.5), x (3.33)."""
    from occmap.octree import raywalk

    f = np.float32
    length, ux, uy, uz = raywalk.direction(f(0.3), f(0.4), f(0.0))
    expected = f(np.sqrt(np.float64(f(0.3) * f(0.3) + f(0.4) * f(0.4))))
    assert length == np.float64(expected)
    assert (ux, uy, uz) == (f(0.3) / expected, f(0.4) / expected, 0.0)
    assert raywalk.direction(f(1e-30), f(-1e-30), f(0.0)) == (0.0, 0.0, 0.0, 0.0)  # no direction
    sx, sy, sz, tx, ty, tz, gx, gy, gz = raywalk.start(f(0.0), f(0.0), f(0.0), f(0.6), f(0.8), f(0.0),
                                                       32768, 32768, 32768, 1.0, True)
    assert (sx, sy, sz) == (1, 1, 0)
    d = 1 / np.float64(f(0.6)), 1 / np.float64(f(0.8))
    np.testing.assert_allclose([tx, ty, gx, gy], [*d, *d], rtol=1e-15)
    assert tz == gz == raywalk.BIG
    axes = []
    for _ in range(4):
        axis, tx, ty, tz = raywalk.step(tx, ty, tz, gx, gy, gz)
        axes.append(axis)
    assert axes == [1, 0, 1, 0]

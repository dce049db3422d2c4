"""OctoMap's .bt / .ot files: the real maps (counts, byte-identical rewrite), round trips, a scan
written by occmap and by octomap-python (same bytes, each reads the other's files), OctoMap's
prune quirk (it stops at the first depth where nothing collapses), and malformed files (truncated
at every offset, bad header fields, impossible bodies) raising FormatError with the offset."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

from occmap.errors import FormatError
from occmap.io import octomap as F
from occmap.octree import OcTree

RES = 0.1


# ------------------------------------------------------------------------------ helpers

def _octomap():
    """octomap-python, for a test that compares with OctoMap (skipped, saying so, without it)."""
    return pytest.importorskip("octomap", reason="compares with OctoMap itself: octomap-python is not installed")


def _arrays(tree):
    n = tree.nodes()
    return n.value.copy(), n.child.copy(), n.count


def _same_arrays(a, b):
    return (np.array_equal(a[0], b[0], equal_nan=True) and np.array_equal(a[1], b[1])
            and np.array_equal(a[2], b[2]))


def _leaf_table(depths, centers, values, res):
    """Leaves as rows (depth, 2x/res, 2y/res, 2z/res) — integers at every depth — sorted, and
    their values in that order."""
    keys = np.column_stack([depths, np.rint(2.0 * np.asarray(centers) / res)]).astype(np.int64)
    order = np.lexsort(keys.T[::-1])
    return keys[order], np.asarray(values, np.float64)[order]


def occmap_leaves(tree):
    lv = tree.leaves()
    return _leaf_table(lv.depths, lv.centers, lv.log_odds, tree.resolution)


def octomap_leaves(t):
    rows = [(leaf.getDepth(), *leaf.getCoordinate(), leaf.getValue()) for leaf in t.begin_leafs()]
    a = np.array(rows, np.float64).reshape(-1, 5)
    return _leaf_table(a[:, 0], a[:, 1:4], a[:, 4], t.getResolution())


def room_cloud(origin, n=5000, seed=7):
    """End points of ``n`` random rays from a sensor at ``origin`` inside a 7 x 5 x 2.6 m room
    (walls, floor, ceiling; some rays stop short), and the sensor's position."""
    rng = np.random.default_rng(seed)
    origin = np.asarray(origin, np.float64)
    lo, hi = np.array([-3.0, -2.4, -0.05]), np.array([4.0, 2.6, 2.55])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (hi - origin) / d, (lo - origin) / d)
    pts = origin + d * t.min(axis=1, keepdims=True) * rng.uniform(0.7, 1.0, size=(n, 1))
    return pts, origin


SCANS = [room_cloud([1.23, -0.61, 1.07], seed=7), room_cloud([-0.52, 0.87, 1.31], seed=8)]


def octomap_tree():
    t = _octomap().OcTree(RES)
    for pts, origin in SCANS:
        t.insertPointCloud(pts, origin)
    return t


@pytest.fixture(scope="module")
def scan_tree():
    """Two scans (5,000 points each) inserted into occmap (:func:`octomap_tree` does the same in
    OctoMap)."""
    ours = OcTree(RES)
    for pts, origin in SCANS:
        ours.insert_point_cloud(pts, origin)
    return ours


@pytest.fixture(scope="module")
def small_bt(scan_tree):
    return F.encode_bt(scan_tree)


@pytest.fixture(scope="module")
def small_ot(scan_tree):
    return F.encode_ot(scan_tree)


# ------------------------------------------------------------------------------ real maps

def _occupied_and_free(tree) -> tuple[int, int]:
    """Leaves at or above the occupied threshold, and the others."""
    log_odds = tree.leaves().log_odds
    occupied = int(np.count_nonzero(log_odds >= np.float32(tree.occupied_log_odds)))
    return occupied, len(log_odds) - occupied


def test_geb079_counts_and_byte_identical_rewrite(data_dir, tmp_path):
    path = data_dir / "octomap" / "geb079.bt"
    tree = F.read_bt(path)
    assert tree.resolution == 0.08
    assert tree.num_nodes() == 532_566
    assert _occupied_and_free(tree) == (143_729, 284_415)
    assert set(np.unique(tree.leaves().log_odds)) == set(np.float32(tree.clamping_log_odds))
    before = _arrays(tree)
    F.write_bt(tree, tmp_path / "geb.bt")
    assert (tmp_path / "geb.bt").read_bytes() == path.read_bytes()
    assert _same_arrays(before, _arrays(tree))
    # the same tree through .ot and back
    F.write_ot(tree, tmp_path / "geb.ot")
    again = F.read_ot(tmp_path / "geb.ot")
    assert _same_arrays(_arrays(again), before)
    assert F.read_octree(tmp_path / "geb.ot").num_nodes() == 532_566


def test_fr079_counts_and_speed(data_dir, tmp_path):
    octomap = _octomap()
    path = data_dir / "octomap" / "fr_079.bt"
    tree = F.read_bt(path)
    assert tree.resolution == 0.05
    assert tree.num_nodes() == 1_829_134
    assert _occupied_and_free(tree) == (372_904, 1_103_266)
    assert F.encode_bt(tree) == path.read_bytes()

    # timings, printed (pytest -s) and not asserted: best of 3, each side in this process
    def best(f):
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            f()
            times.append(time.perf_counter() - t0)
        return min(times)

    om = octomap.OcTree(0.05)
    spath, out = str(path).encode(), str(tmp_path / "om.bt").encode()
    t_read, t_om_read = best(lambda: F.read_bt(path)), best(lambda: om.readBinary(spath))
    t_write, t_om_write = best(lambda: F.write_bt(tree, tmp_path / "o.bt")), best(lambda: om.writeBinary(out))
    print(f"\nfr_079.bt read: occmap {t_read * 1e3:.1f} ms, octomap {t_om_read * 1e3:.1f} ms "
          f"({t_om_read / t_read:.1f}x); write: occmap {t_write * 1e3:.1f} ms, octomap "
          f"{t_om_write * 1e3:.1f} ms ({t_om_write / t_write:.1f}x)")


# ------------------------------------------------------------------------------ one scan, both libraries

def test_scan_bytes_equal_octomaps(scan_tree, tmp_path):
    ours, theirs = scan_tree, octomap_tree()
    assert ours.num_nodes() == theirs.size()
    before = _arrays(ours)
    # .ot first: OctoMap's writeBinary converts its own tree to maximum likelihood
    assert F.encode_ot(ours) == theirs.write()
    assert F.encode_bt(ours) == octomap_tree().writeBinary()
    assert _same_arrays(before, _arrays(ours)), "writing changed the tree"
    assert len(np.unique(ours.leaves().log_odds)) > 3  # far from maximum likelihood


def test_octomap_reads_our_files(scan_tree, tmp_path):
    octomap = _octomap()
    ours = scan_tree
    F.write_bt(ours, tmp_path / "ours.bt")
    F.write_ot(ours, tmp_path / "ours.ot")
    keys, values = occmap_leaves(ours)

    om_ot = octomap.OcTree.read(str(tmp_path / "ours.ot").encode())
    assert om_ot.size() == ours.num_nodes()
    k, v = octomap_leaves(om_ot)
    np.testing.assert_array_equal(k, keys)
    np.testing.assert_array_equal(v, values)  # float32 values, exactly

    om_bt = octomap.OcTree(str(tmp_path / "ours.bt").encode())
    ml = F.read_bt(tmp_path / "ours.bt")
    assert om_bt.size() == ml.num_nodes()
    k, v = octomap_leaves(om_bt)
    mk, mv = occmap_leaves(ml)
    np.testing.assert_array_equal(k, mk)
    np.testing.assert_array_equal(v, mv)
    # maximum likelihood keeps each voxel's class
    occ = ours.occupancy_at(ours.leaves().centers)
    np.testing.assert_array_equal(ml.occupancy_at(ours.leaves().centers), occ)


def test_we_read_octomaps_files(scan_tree, tmp_path):
    ours = scan_tree
    om = octomap_tree()
    om.write(str(tmp_path / "om.ot").encode())
    om.writeBinary(str(tmp_path / "om.bt").encode())  # (this converts om to maximum likelihood)

    full = F.read_octree(tmp_path / "om.ot")
    assert full.num_nodes() == ours.num_nodes()
    k, v = occmap_leaves(full)
    mk, mv = occmap_leaves(ours)
    np.testing.assert_array_equal(k, mk)
    np.testing.assert_array_equal(v, mv)

    ml = F.read_octree(tmp_path / "om.bt")
    assert ml.num_nodes() == om.size()
    k, v = occmap_leaves(ml)
    ok, ov = octomap_leaves(om)
    np.testing.assert_array_equal(k, ok)
    np.testing.assert_array_equal(v, ov)
    assert F.encode_bt(ml) == (tmp_path / "om.bt").read_bytes()


def test_tree_kwargs_set_the_leaf_values(small_bt, tmp_path):
    (tmp_path / "a.bt").write_bytes(small_bt)
    tree = F.read_bt(tmp_path / "a.bt", clamp=(0.2, 0.9))
    assert set(np.unique(tree.leaves().log_odds)) == {np.float32(np.log(0.25)), np.float32(np.log(9.0))}


# ------------------------------------------------------------------------------ OctoMap's prune quirk

def _updated_tree(cells):
    """An octomap-python tree whose depth-15 cells (2x2x2 voxels, by their lowest key) get, voxel
    by voxel, ``n`` hits (n > 0) or ``-n`` misses (n < 0); ``n`` one number or one per voxel."""
    octomap = _octomap()
    t = octomap.OcTree(RES)
    for (kx, ky, kz), counts in cells:
        counts = [counts] * 8 if np.isscalar(counts) else counts
        for i, n in enumerate(counts):
            key = np.array([kx + (i & 1), ky + ((i >> 1) & 1), kz + (i >> 2)]) - 32768
            for _ in range(abs(n)):
                t.updateNode((key + 0.5) * RES, bool(n > 0))
    return t


# the eight depth-15 cells of one depth-14 node, each pruned into a leaf when updated (all its
# voxels alike), all occupied but with different log-odds
CELLS = [((32768 + 2 * (i & 1), 32768 + 2 * ((i >> 1) & 1), 32768 + 2 * (i >> 2)), n)
         for i, n in enumerate([1, 2, 3, 4, 5, 1, 2, 3])]


@pytest.mark.parametrize("extra, removed", [
    # nothing collapses at depth 15, so OctoMap's prune stops there and keeps the depth-14 node
    ([], 0),
    # a depth-15 cell of occupied voxels with different log-odds collapses, so depth 14 is pruned
    ([((32800, 32800, 32800), [1, 2, 1, 2, 3, 1, 2, 1])], 16),
    # the same with free voxels
    ([((32768, 32800, 32768), [-1, -3, -1, -3, -2, -1, -1, -1])], 16),
])
def test_prune_stops_where_octomap_stops(extra, removed, tmp_path):
    om = _updated_tree(CELLS + extra)
    om.write(str(tmp_path / "q.ot").encode())
    ours = F.read_ot(tmp_path / "q.ot")
    assert ours.num_nodes() == om.size()
    before = _arrays(ours)
    got = F.encode_bt(ours)
    expected = om.writeBinary()
    assert got == expected
    assert int(got.split(b"\nsize ")[1].split(b"\n")[0]) == ours.num_nodes() - removed
    assert _same_arrays(before, _arrays(ours))


# ------------------------------------------------------------------------------ small cases

def test_empty_and_single_node_trees(tmp_path):
    octomap = _octomap()
    empty = OcTree(0.25)
    for name, write, read in (("e.bt", F.write_bt, F.read_bt), ("e.ot", F.write_ot, F.read_ot)):
        write(empty, tmp_path / name)
        assert b"\nsize 0\nres 0.25\ndata\n" in (tmp_path / name).read_bytes()
        assert (tmp_path / name).read_bytes().endswith(b"data\n")
        back = read(tmp_path / name)
        assert back.num_nodes() == 0 and back.resolution == 0.25
    assert octomap.OcTree(str(tmp_path / "e.bt").encode()).size() == 0

    one = F.decode_bt(F._header(F.BINARY_MAGIC, "OcTree", 1, 0.5) + b"\x00\x00")
    assert one.num_nodes() == 1 and one.num_leaves() == 1
    assert one.nodes().value[0] == np.float32(one.clamping_log_odds[1])  # OctoMap reads a lone root as occupied
    assert F.encode_bt(one).endswith(b"size 1\nres 0.5\ndata\n\x00\x00")
    assert F.decode_ot(F.encode_ot(one)).num_nodes() == 1


def test_root_is_the_max_of_its_children(tmp_path):
    """A map with only free leaves: OctoMap's readBinary leaves the root at the upper clamp;
    occmap gives it the maximum of its children (documented difference), the leaves agree."""
    octomap = _octomap()
    om = octomap.OcTree(RES)
    for x in (0.05, 0.15, -0.35):
        om.updateNode(np.array([x, 0.05, 0.05]), False)
    om.writeBinary(str(tmp_path / "free.bt").encode())
    ours = F.read_bt(tmp_path / "free.bt")
    back = octomap.OcTree(str(tmp_path / "free.bt").encode())
    assert back.getRoot().getValue() == pytest.approx(ours.clamping_log_odds[1])
    assert ours.nodes().value[0] == np.float32(ours.clamping_log_odds[0])
    k, v = octomap_leaves(back)
    mk, mv = occmap_leaves(ours)
    np.testing.assert_array_equal(k, mk)
    np.testing.assert_array_equal(v, mv)
    assert F.encode_bt(ours) == (tmp_path / "free.bt").read_bytes()


def test_header_variants_accepted():
    body = b"\x00\x00"
    text = (b"# Octomap OcTree binary file   with words after\n# comment\n\n  # another\r\n"
            b"res   0.2e0\nid 1\nsize\n1\ndata   trailing words\n" + body)
    tree = F.decode_bt(text)
    assert tree.resolution == 0.2 and tree.num_nodes() == 1
    with pytest.warns(UserWarning, match="unknown keyword"):
        F.decode_bt(b"# Octomap OcTree binary file\nfoo bar\nid OcTree\nsize 1\nres 0.1\ndata\n" + body)
    # legacy binary header: int32 3, float64 res, uint32 size
    legacy = np.array([3], "<i4").tobytes() + np.array([0.3], "<f8").tobytes() + np.array([1], "<u4").tobytes()
    assert F.decode_bt(legacy + body).resolution == 0.3


def test_load_by_extension_or_first_line(small_bt, small_ot, tmp_path):
    (tmp_path / "x.bin").write_bytes(small_bt)
    (tmp_path / "y.data").write_bytes(small_ot)
    (tmp_path / "z.txt").write_bytes(b"hello\n")
    assert F.read_octree(tmp_path / "x.bin").num_nodes() == F.decode_bt(small_bt).num_nodes()
    assert F.read_octree(tmp_path / "y.data").num_nodes() == F.decode_ot(small_ot).num_nodes()
    with pytest.raises(FormatError, match="not an OctoMap file"):
        F.read_octree(tmp_path / "z.txt")
    (tmp_path / "swapped.bt").write_bytes(small_ot)
    with pytest.raises(FormatError, match="first line"):
        F.read_octree(tmp_path / "swapped.bt")


# ------------------------------------------------------------------------------ malformed files

def _data_at(buf):
    return buf.index(b"\ndata\n") + 6


@pytest.mark.parametrize("fmt", ["bt", "ot"])
def test_truncated_at_every_offset(fmt, small_bt, small_ot, tmp_path):
    buf = small_bt if fmt == "bt" else small_ot
    decode = F.decode_bt if fmt == "bt" else F.decode_ot
    start = _data_at(buf)
    cuts = list(range(0, start + 1)) + list(range(start + 1, len(buf), max(1, (len(buf) - start) // 300)))
    t0 = time.perf_counter()
    for cut in cuts:
        with warnings.catch_warnings(), pytest.raises(FormatError) as err:
            warnings.simplefilter("ignore")  # a cut keyword is an unknown one
            decode(buf[:cut], "cut")
        assert err.value.offset is not None and 0 <= err.value.offset <= cut, (cut, str(err.value))
        if cut > start:
            assert "truncated" in str(err.value)
    assert time.perf_counter() - t0 < 5
    # through a file: the message names the path and the byte
    (tmp_path / "cut.bt").write_bytes(small_bt[: start + 7])
    with pytest.raises(FormatError, match=r"cut\.bt, byte \d+: the data ends inside a node"):
        F.read_bt(tmp_path / "cut.bt")


def _replace(buf, old, new):
    assert old in buf
    return buf.replace(old, new, 1)


@pytest.mark.parametrize("change, match", [
    ((b"id OcTree", b"id ColorOcTreeX"), "is not an occupancy octree"),
    ((b"id OcTree", b"idx OcTree"), "sets no 'id'"),
    ((b"res 0.1", b"res abc"), "res must be a number"),
    ((b"res 0.1", b"res -0.1"), "positive"),
    ((b"res 0.1", b"res 0"), "positive"),
    ((b"res 0.1", b"res nan"), "res must be a number"),
    ((b"res 0.1", b"rez 0.1"), "no positive 'res'"),
    ((b"\ndata\n", b"\ndat\n"), "without a 'data' line"),
    ((b"size ", b"size -"), "size must be a node count"),
    ((b"size ", b"size 9"), "header's size says"),
    ((b"size ", b"size 0 #"), "size is 0 but"),
    ((b"# Octomap OcTree binary file", b"# Octomap OcTree bin file"), "first line"),
])
def test_bad_bt_header(change, match, small_bt):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unknown keywords are skipped with a warning
        with pytest.raises(FormatError, match=match) as err:
            F.decode_bt(_replace(small_bt, *change), "bad.bt")
    assert err.value.offset is not None


def test_size_mismatch_names_the_size_field(small_bt):
    bad = _replace(small_bt, b"size ", b"size 1")
    with pytest.raises(FormatError, match="header's size says") as err:
        F.decode_bt(bad)
    assert bad[err.value.offset - 5: err.value.offset] == b"size "
    # a huge count with a small body: checked against the bytes, nothing allocated from it
    with pytest.raises(FormatError, match="header's size says 4000000000"):
        F.decode_bt(_replace(small_bt, b"size ", b"size 4000000000 \n#"))


def test_impossible_bt_bodies():
    head = F._header(F.BINARY_MAGIC, "OcTree", 17 * 1 + 1, 0.1)
    n = len(head)
    with pytest.raises(FormatError, match="below depth 16") as err:  # 17 nested inner nodes
        F.decode_bt(head + b"\x03\x00" * 17)
    assert err.value.offset == n + 2 * 15
    with pytest.raises(FormatError, match="no children") as err:  # inner node with no children
        F.decode_bt(head + b"\x03\x00\x00\x00")
    assert err.value.offset == n + 2
    good = F._header(F.BINARY_MAGIC, "OcTree", 9, 0.1) + b"\x55\x55"  # root + 8 free leaves
    assert F.decode_bt(good).num_leaves() == 8
    with pytest.raises(FormatError, match="bytes follow the last node") as err:
        F.decode_bt(good + b"\n")
    assert err.value.offset == len(good)


def test_impossible_ot_bodies(small_ot):
    rec = np.float32(1.0).tobytes()
    head = F._header(F.FULL_MAGIC, "OcTree", 18, 0.1)
    with pytest.raises(FormatError, match="below depth 16") as err:
        F.decode_ot(head + (rec + b"\x01") * 18)
    assert err.value.offset == len(head) + 5 * 16
    with pytest.raises(FormatError, match="NaN") as err:
        F.decode_ot(head + rec + b"\x01" + np.float32(np.nan).tobytes() + b"\x00")
    assert err.value.offset == len(head) + 5
    with pytest.raises(FormatError, match="bytes follow the last node"):
        F.decode_ot(small_ot + b"\x00")
    with pytest.raises(FormatError, match="only 'OcTree'"):
        F.decode_ot(_replace(small_ot, b"id OcTree", b"id ColorOcTree"))


@pytest.mark.parametrize("fmt", ["bt", "ot"])
def test_random_corruption_never_crashes_or_hangs(fmt, small_bt, small_ot):
    buf = bytearray(small_bt if fmt == "bt" else small_ot)
    decode = F.decode_bt if fmt == "bt" else F.decode_ot
    start = _data_at(bytes(buf))
    rng = np.random.default_rng(3)
    t0 = time.perf_counter()
    for _ in range(300):
        bad = bytearray(buf)
        for pos in rng.integers(start, len(buf), size=rng.integers(1, 4)):
            bad[pos] = int(rng.integers(0, 256))
        try:
            tree = decode(bytes(bad))
        except FormatError as err:
            assert err.offset is not None
        else:
            assert tree.num_nodes() == int(bytes(buf).split(b"\nsize ")[1].split(b"\n")[0])
    assert time.perf_counter() - t0 < 5


def test_read_tree_keeps_growing_like_octomaps(data_dir):
    """A tree read from a file takes further scans exactly as OctoMap's does (same .ot bytes)."""
    octomap = _octomap()
    path = data_dir / "octomap" / "geb079.bt"
    ours = F.read_bt(path)
    om = octomap.OcTree(str(path).encode())
    for pts, origin in SCANS:
        ours.insert_point_cloud(pts, origin)
        om.insertPointCloud(pts, origin)
    assert ours.num_nodes() == om.size()
    assert F.encode_ot(ours) == om.write()

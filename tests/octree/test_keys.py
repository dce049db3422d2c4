"""Key arithmetic (occmap.octree.keys) against values derived by hand from OctoMap's
definitions: coordToKey = floor(x / res) + 32768, keyToCoord(key, depth), the child index
x-bit + 2·y-bit + 4·z-bit, the packed layout kx | ky << 20 | kz << 40."""

from __future__ import annotations

import numpy as np

from occmap.octree import keys as K


def test_coord_to_key_and_back():
    assert K.coord_to_key(0.0, 10.0) == 32768
    assert K.coord_to_key(-1e-9, 10.0) == 32767  # floor, not truncation
    assert K.coord_to_key(0.25, 10.0) == 32770
    assert K.key_to_coord(32770, 0.1) == (2 + 0.5) * 0.1
    assert K.key_in_range(0) and K.key_in_range(65535) and not K.key_in_range(-1) and not K.key_in_range(65536)
    np.testing.assert_array_equal(K.coord_to_keys(np.array([[0.0, -1e-9, 0.25]]), 0.1), [[32768, 32767, 32770]])
    np.testing.assert_array_equal(K.keys_in_range(np.array([[0, 65535, 3], [0, 65536, 3]])), [True, False])


def test_node_centres_at_depths():
    # depth 16: the voxel's own centre; depth 15: the 2-voxel cell floor((k - 32768) / 2), size 0.2
    c = K.node_centers(np.array([[32768, 32767, 32769], [32768, 32767, 32769]]), np.array([16, 15]), 0.1)
    np.testing.assert_allclose(c, [[0.05, -0.05, 0.15], [0.1, -0.1, 0.1]], rtol=1e-15)
    # the root (one cell of 65536 voxels): (floor(0 / 65536) + 0.5) * 65536 for key 32768
    assert K.node_centers(np.array([32768, 32768, 32768]), 0, 1.0).tolist() == [32768.0] * 3


def test_child_index_and_shared_depth():
    # below the root (depth 0) the top bit decides: key 32768 has it, 32767 does not
    assert K.child_index(32768, 32767, 32767, 0) == 1
    assert K.child_index(32767, 32768, 32768, 0) == 2 + 4
    assert K.child_index(1, 0, 1, 15) == 1 + 4  # the lowest bit at depth 15
    a = K.pack(32768, 5, 9)
    assert K.shared_depth(a, a) == 16
    assert K.shared_depth(a, K.pack(32769, 5, 9)) == 15  # differ in bit 0 only
    assert K.shared_depth(a, K.pack(32768, 5, 9 + 16)) == 11  # differ in bit 4
    assert K.shared_depth(K.pack(32768, 0, 0), K.pack(32767, 0, 0)) == 0


def test_packed_keys_are_linear_and_blocks_and_morton():
    a = K.pack(65535, 0, 300)
    assert K.unpack(a) == (65535, 0, 300)
    assert K.pack(65535, 0, 300) + K.pack(1, 0, 0) == K.pack(65536, 0, 300)  # one past the range, no carry
    assert K.pack(3, 0, 0) + K.pack(0, -1, 0) == K.pack(3, -1, 0)
    assert K.field(a, 2) == 300
    np.testing.assert_array_equal(K.pack_keys(np.array([[65535, 0, 300]])), [a])
    code = K.block_code(K.pack(17, 9, 65535))
    assert code != 0 and K.unpack(K.block_key(code)) == (16, 8, 65528)
    assert K.in_block(K.pack(17, 9, 65535)) == 1 + 8 * 1 + 64 * 7
    assert [K.morton(*v, 1) for v in ((1, 0, 0), (0, 1, 0), (0, 0, 1))] == [1, 2, 4]
    assert K.morton(2, 0, 3, 2) == (1 << 3) + 4 + (4 << 3)


def test_block_masks_relaid_in_morton_order_bit_for_bit():
    """A block's mask words (word lz, bit lx + 8·ly) → Morton-ordered words (voxel m at bit m & 63
    of word m >> 6), against keys.morton voxel by voxel, from empty to full blocks and each plane
    alone (the sign bit among them)."""
    from occmap.octree.blocks import morton_words

    rng = np.random.default_rng(3)
    voxel = np.arange(512)
    target = np.array([K.morton.py_func(i & 7, (i >> 3) & 7, i >> 6, 3) for i in voxel])
    cases = [rng.random(512) < p for p in np.linspace(0.0, 1.0, 41)] + [voxel >> 6 == z for z in range(8)]
    out = np.empty(8, np.int64)
    for bits in cases:
        words = np.packbits(bits.reshape(8, 64), axis=1, bitorder="little").view("<i8").ravel()
        morton_words(words, out)
        got = np.unpackbits(out.view(np.uint8), bitorder="little").astype(bool)
        np.testing.assert_array_equal(got[target], bits)


def test_blocks_merged_in_morton_order_with_or_without_room_for_their_indices(monkeypatch):
    """Blocks marked more than once (several threads' markings) come out once each, their masks
    OR-ed, in the Morton order of their keys (the octree's depth-first order, worked out here in
    Python from the keys); alike where the sort keys hold the blocks' indices and where there are
    more blocks than those bits hold (then the codes alone are sorted)."""
    from occmap.octree import blocks as B

    rng = np.random.default_rng(5)
    keys = rng.integers(0, 1 << 16, (300, 3)) & ~7
    codes = np.array([K.block_code(K.pack(*k)) for k in keys[rng.integers(0, len(keys), 900)]], np.int64)
    hits, frees = (np.where(rng.random((900, 8)) < 0.3, rng.integers(-(1 << 62), 1 << 62, (900, 8)), 0) for _ in range(2))
    expected = {}
    for c, h, f in zip(codes, hits, frees):
        h0, f0 = expected.get(c, (0, 0))
        expected[c] = (h0 | h, f0 | f)
    order = sorted(expected, key=lambda c: K.morton(*(int(v) >> 3 for v in K.unpack(K.block_key(c))), 13))
    for index_bits in (B._INDEX_BITS, 3):
        monkeypatch.setattr(B, "_INDEX_BITS", index_bits)
        c2, h2, f2 = B.merge_blocks(codes, hits, frees)
        np.testing.assert_array_equal(c2, order)
        np.testing.assert_array_equal(h2, [expected[c][0] for c in order])
        np.testing.assert_array_equal(f2, [expected[c][1] for c in order])

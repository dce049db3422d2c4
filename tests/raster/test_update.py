"""occmap.raster.update: the stamp codes and their roll-over."""

from __future__ import annotations

import numpy as np

from occmap.raster.update import SEEN, UNSEEN, ScanCodes, hit_stamp, miss_stamp


def test_stamps_of_a_scan_lie_above_every_earlier_one_and_a_hit_above_its_miss():
    assert (miss_stamp(1), hit_stamp(1)) == (2, 3)
    assert UNSEEN < SEEN < miss_stamp(1) < hit_stamp(1) < miss_stamp(2)


def test_codes_fit_the_dtype_and_roll_over_lowering_observed_stamps():
    codes = ScanCodes(np.uint16)
    assert codes.last == 32767 and hit_stamp(codes.last) == 65535
    assert ScanCodes(np.int32).last == 2**30 - 1
    stamps = np.array([UNSEEN, SEEN, 7, 65535], dtype=np.uint16)
    assert codes.take(5, stamps) == (1, 5)
    assert codes.take(40000, stamps) == (6, 32762)  # only what is left
    assert stamps.tolist() == [UNSEEN, SEEN, 7, 65535]  # not yet lowered
    assert codes.take(3, stamps) == (1, 3)  # none left: lowered, and again from 1
    assert stamps.tolist() == [UNSEEN, SEEN, SEEN, SEEN]


def test_a_strided_view_of_stamps_is_lowered_in_place():
    buf = np.zeros((2, 3, 2), dtype=np.int32)
    buf[..., 0] = 99  # the other field of each cell stays as it is
    buf[..., 1] = [[0, 5, 9], [1, 0, 2**31 - 1]]
    codes = ScanCodes(np.int32)
    codes.code = codes.last
    assert codes.take(1, buf[..., 1]) == (1, 1)
    assert buf[..., 1].tolist() == [[0, 1, 1], [1, 0, 1]] and (buf[..., 0] == 99).all()

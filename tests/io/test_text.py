"""The number tokenizer every text reader uses, and its errors naming file, line, field and token."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.errors import FormatError
from occmap.io._text import Table, first_non_number, not_a_number, numbers


def test_numbers_reads_what_numpy_reads():
    np.testing.assert_array_equal(numbers(" 1 -2.5e3\t nan inf\n-inf 7 "), [1, -2500, np.nan, np.inf, -np.inf, 7])
    for bad in ("1 2,5", "0x10", "1_000", "abc", "4 5 6abc"):
        assert numbers(bad) is None or numbers(bad).size != len(bad.split())


@pytest.mark.parametrize("text, expected", [("1 2 3", None), ("1 x 3", (1, "x")), ("1_0 2", (0, "1_0")),
                                            ("1 2 4,5", (2, "4,5")), ("  ", None)])
def test_first_non_number(text, expected):
    assert first_non_number(text) == expected


def test_not_a_number_names_file_line_field_and_token():
    e = not_a_number("log.txt", 7, 3, "x" * 60, "n r_1..r_n")
    assert isinstance(e, FormatError) and e.line == 7
    assert str(e) == f"log.txt, line 7: field 3 {'x' * 40!r} is not a number (expected n r_1..r_n)"


def test_table_rows_lines_and_comments():
    t = Table("a.xyz", b"# head\n1 2 3\n\n4 5 6 7 # note\n8 9 10\n", 1, comments=True)
    assert t.lines.tolist() == [2, 4, 5] and t.counts.tolist() == [3, 4, 3]
    np.testing.assert_array_equal(t.columns((0, 2)), [[1, 3], [4, 6], [8, 10]])
    with pytest.raises(FormatError, match=r"a.xyz, line 4: expected 3 fields \(x y z\), got 4"):
        t.require("a.xyz", exactly=3, what="x y z")


def test_table_bad_token_error():
    with pytest.raises(FormatError, match=r"b.txt, line 12: field 2 '2,5' is not a number") as e:
        Table("b.txt", b"1 2\n3 2,5\n", 11, comments=False)
    assert e.value.line == 12

"""Numbers in text files: the one tokenizer and the one "not a number" error every reader uses.

Tokens are separated by ASCII whitespace and read by NumPy's float parser (``np.fromstring`` with
``sep=" "``, the fastest text → float64 path): ``nan``, ``inf`` and exponents are numbers; ``1,5``,
``0x1`` and ``1_000`` are not. A token that is not a number is reported as a
:class:`~occmap.errors.FormatError` naming the file, the line (1-based), the field (1-based) and the
token, e.g. ``scan.xyz, line 3: field 2 '4,5' is not a number``. Lines and bytes are decoded as
latin-1, which never fails, so stray bytes surface as bad tokens with a line number.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import FormatError

__all__ = ["Table", "count", "first_non_number", "not_a_number", "numbers", "raise_not_a_number"]

#: Digits a header count may have: any count a file could hold fits, and no token of thousands of
#: digits reaches ``int()`` (which refuses more than 4300).
_COUNT_DIGITS = 18

_BLANK = np.zeros(256, dtype=bool)
_BLANK[[9, 10, 11, 12, 13, 32]] = True  # the bytes str.split() and np.fromstring skip


class Table:
    """Whitespace-separated numbers of an ASCII block, tokenised with NumPy.

    ``values`` holds every number in file order; row ``i`` (the ``i``-th non-blank line) starts at
    ``values[starts[i]]`` and has ``counts[i]`` numbers; ``lines[i]`` is its 1-based line number.
    """

    __slots__ = ("values", "starts", "counts", "lines")

    def __init__(self, path, data: bytes, line0: int, comments: bool):
        b = np.frombuffer(data, dtype=np.uint8)
        nl = np.flatnonzero(b == 10)  # newline positions
        blank = _BLANK[b]
        text = data
        if comments and b"#" in data:
            # blank out from the first '#' of a line to its end
            hashes = np.flatnonzero(b == 35)
            hline = np.searchsorted(nl, hashes)
            first = np.flatnonzero(np.r_[True, hline[1:] != hline[:-1]])
            begin = hashes[first]
            end = np.append(nl, b.size)[hline[first]]
            mark = np.zeros(b.size + 1, dtype=np.int8)
            mark[begin] = 1
            mark[end] -= 1
            in_comment = np.cumsum(mark[:-1], dtype=np.int8).astype(bool)
            blank |= in_comment
            text = np.where(in_comment, np.uint8(32), b).tobytes()
        token_start = ~blank
        token_start[1:] &= blank[:-1]
        tline = np.searchsorted(nl, np.flatnonzero(token_start))  # 0-based line of each token
        del blank, token_start
        self.starts = np.flatnonzero(np.r_[True, tline[1:] != tline[:-1]]) if tline.size else tline
        self.lines = tline[self.starts] + line0
        self.counts = np.diff(np.append(self.starts, tline.size))
        total = int(tline.size)
        # np.fromstring(sep=" ") is the fastest text → float64 path; it reads NaN/inf spellings
        # and fails (or, on old NumPy, stops early) at the first token that is not a number.
        # It returns [-1.] for all-blank text, hence the guard.
        values = numbers(text.decode("latin-1")) if total else np.zeros(0)
        if values is None or values.size != total:
            raise_not_a_number(path, text, line0)
            raise FormatError(path, "text could not be read as numbers")  # pragma: no cover
        self.values = values

    def __len__(self) -> int:
        return int(self.counts.shape[0])

    def columns(self, cols) -> np.ndarray:
        """(rows, len(cols)) float64 of the given 0-based columns (callers checked the counts)."""
        idx = self.starts[:, None] + np.asarray(cols, dtype=np.intp)[None, :]
        return self.values[idx]

    def require(self, path, *, at_least: int | None = None, exactly: int | None = None, what: str):
        """Raise FormatError at the first row with too few (or not exactly the right) numbers."""
        bad = self.counts < at_least if at_least is not None else self.counts != exactly
        if bad.any():
            i = int(np.argmax(bad))
            need = f"at least {at_least}" if at_least is not None else f"{exactly}"
            raise FormatError(path, f"expected {need} fields ({what}), got {self.counts[i]}", line=int(self.lines[i]))


def count(path, token: str, what: str, line: int) -> int:
    """A count from a header (``element vertex 1000``, ``WIDTH 640``): ASCII digits only (no sign,
    no ``²`` or other Unicode digits, at most 18 of them), else a FormatError naming the file,
    the line, the field and the token."""
    if not (token.isascii() and token.isdigit() and len(token) <= _COUNT_DIGITS):
        raise FormatError(path, f"{what} must be a whole number of at most {_COUNT_DIGITS} digits, got {token[:40]!r}", line=line)
    return int(token)


def numbers(text: str) -> np.ndarray | None:
    """Every whitespace-separated number in ``text`` as float64 (NumPy's parser: ``nan``, ``inf``
    and exponents read; no underscores, no commas), or None when a token is not a number."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return np.fromstring(text, dtype=np.float64, sep=" ")
        except ValueError:
            return None


def first_non_number(text: str) -> tuple[int, str] | None:
    """0-based index and text of the first token of ``text`` that :func:`numbers` does not read
    as one number (None when all are numbers). For error messages, off the fast path."""
    for j, tok in enumerate(text.split()):
        got = numbers(tok)
        if got is None or got.size != 1:
            return j, tok
    return None


def not_a_number(path, line: int, field: int, token: str, expected: str = "") -> FormatError:
    """The error for a field that is not a number: file, line, 1-based field, the token (cut at 40
    characters) and, when given, what the line should hold."""
    tail = f" (expected {expected})" if expected else ""
    return FormatError(path, f"field {field} {token[:40]!r} is not a number{tail}", line=line)


def raise_not_a_number(path, text: bytes, line0: int):
    """Error path only: find the first field of ``text`` (whose first line is ``line0``) that is
    not a number and raise naming its line and field."""
    for k, line in enumerate(text.decode("latin-1").split("\n")):
        bad = first_non_number(line)
        if bad is not None:
            raise not_a_number(path, line0 + k, bad[0] + 1, bad[1])

"""OctoMap's octree files, byte for byte as OctoMap 1.10 writes and reads them.

``.bt`` (``writeBinary`` / ``readBinary``): a text header, then two bytes per inner node giving
each child's kind (absent, free leaf, occupied leaf, inner); the tree is written at maximum
likelihood, so a reader knows each leaf only as free or occupied and gives it the clamping bound
of its class. ``.ot`` (``write`` / ``AbstractOcTree::read``): the same header with another first
line, then every node's float32 log-odds and a child mask — the tree exactly.

Header (both)::

    # Octomap OcTree binary file          (.ot: "# Octomap OcTree file")
    # (feel free to add / change comments, but leave the first line as it is!)
    #
    id OcTree
    size <nodes>
    res <resolution, as C++ prints a double>
    data
    <body>

Readers follow OctoMap's ``readHeader``: whitespace-separated keywords in any order, ``#`` starts
a comment line, ``data`` ends the header, unknown keywords are skipped with a warning, the legacy
id ``1`` means ``OcTree``. They are stricter where OctoMap would build a broken tree without
complaint: the node count must match ``size``, the body must end with the last node, no node may
lie below depth 16, and a ``.bt`` node marked inner must have children; each raises
:class:`~occmap.errors.FormatError` naming the file and the byte offset. Memory is bounded by the
file's length whatever its header claims.

One deliberate difference from OctoMap's ``readBinary``: OctoMap leaves the root of a ``.bt`` it
reads at the upper clamping bound (it never sets the root from its children), so a map without an
occupied leaf reads back with an "occupied" root. Here the root, like every inner node, gets the
maximum of its children; the two agree whenever the map has an occupied leaf. (A root with no
children at all carries no class in the file; it reads as occupied, as in OctoMap.)

Names: :func:`read_octree` (either format, OctoMap's ``AbstractOcTree::read``), :func:`read_bt` /
:func:`write_bt` (``readBinary`` / ``writeBinary``), :func:`read_ot` / :func:`write_ot` (``read`` /
``write``), and the same on bytes (``decode_*`` / ``encode_*``). The trees are built and read
through :meth:`OcTree.from_nodes` and :meth:`OcTree.nodes`; the kernels are in
:mod:`._octomap_codec`. Writes are atomic (:func:`occmap._files.write_atomic`).
"""

from __future__ import annotations

import re
import struct
import warnings
from pathlib import Path

import numpy as np

from .._files import write_atomic
from ..errors import FormatError
from ..octree import OcTree
from . import _octomap_codec as C

BINARY_MAGIC = b"# Octomap OcTree binary file"
FULL_MAGIC = b"# Octomap OcTree file"
_COMMENT = b"\n# (feel free to add / change comments, but leave the first line as it is!)\n#\n"
#: ids a ``.bt`` body may carry: every OctoMap occupancy tree writes the same binary body.
_BINARY_IDS = ("OcTree", "ColorOcTree", "OcTreeStamped")
_WORD = re.compile(rb"[^ \t\n\v\f\r]+")  # a token between C's isspace characters
_FLOAT = re.compile(rb"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_UINT = re.compile(rb"\+?\d+\Z")

_MESSAGES = {
    C.TRUNCATED: "the data ends inside a node (file truncated?)",
    C.TOO_DEEP: "a node lies below depth 16, the octree's depth",
    C.LEFTOVER: "bytes follow the last node of the tree",
    C.EMPTY_INNER: "a node marked as inner (bits 11) has no children",
    C.NAN_VALUE: "a node's log-odds is NaN",
}


# ------------------------------------------------------------------------------ writing

def _header(magic: bytes, tree_id: str, nodes: int, resolution: float, comment: str | None = None) -> bytes:
    # C++ `ostream << double` prints with precision 6 in the %g style
    notes = "".join(f"# {line}\n" for line in comment.splitlines()).encode() if comment else b""
    return (magic + _COMMENT + notes + f"id {tree_id}\nsize {nodes}\nres {format(resolution, 'g')}\ndata\n".encode())


def encode_bt(tree: OcTree, comment: str | None = None) -> bytes:
    """The bytes OctoMap's ``writeBinary`` writes for ``tree`` (which converts its tree to maximum
    likelihood and prunes it first); ``tree`` itself is left unchanged. ``comment``: lines added
    to the header as ``#`` comments (OctoMap's readers skip them)."""
    nodes = tree.nodes()
    lo, hi = (np.float32(v) for v in tree.clamping_log_odds)
    body, nodes = C.encode_bt(nodes.slots, len(nodes.slots), np.float32(tree.occupied_log_odds), lo, hi)
    if nodes < 0:
        raise RuntimeError("octree node pool is inconsistent: a node lies below depth 16")
    return _header(BINARY_MAGIC, "OcTree", int(nodes), tree.resolution, comment) + body.tobytes()


def encode_ot(tree: OcTree, comment: str | None = None) -> bytes:
    """The bytes OctoMap's ``write`` (``.ot``, every node's log-odds) writes for ``tree``
    (``comment`` as for :func:`encode_bt`)."""
    nodes = tree.nodes()
    body, nodes = C.encode_ot(nodes.slots, nodes.slots.view(np.uint32), len(nodes.slots))
    if nodes < 0:
        raise RuntimeError("octree node pool is inconsistent: a node below depth 16 or more reachable "
                           "nodes than stored values")
    return _header(FULL_MAGIC, "OcTree", int(nodes), tree.resolution, comment) + body.tobytes()


def write_bt(tree: OcTree, path) -> Path:
    """Write ``tree`` to ``path`` as OctoMap's ``.bt`` (maximum likelihood, pruned), atomically.
    Byte-identical to OctoMap's ``writeBinary`` for the same tree; ``tree`` is not modified."""
    return write_atomic(path, encode_bt(tree))


def write_ot(tree: OcTree, path) -> Path:
    """Write ``tree`` to ``path`` as OctoMap's ``.ot`` (every node with its log-odds), atomically."""
    return write_atomic(path, encode_ot(tree))


# ------------------------------------------------------------------------------ reading

class _Header:
    __slots__ = ("tree_id", "id_at", "size", "size_at", "res", "data_at")

    def __init__(self):
        self.tree_id, self.id_at, self.size, self.size_at, self.res, self.data_at = "", 0, 0, None, 0.0, 0


def _token(buf: bytes, pos: int) -> tuple[bytes, int, int]:
    """C++ ``stream >> string``: skip whitespace, read up to the next; (token, start, end), the
    token empty at the end of the file."""
    m = _WORD.search(buf, pos)
    if m is None:
        return b"", len(buf), len(buf)
    return m.group(), m.start(), m.end()


def _skip_line(buf: bytes, pos: int) -> int:
    nl = buf.find(b"\n", pos)
    return len(buf) if nl < 0 else nl + 1


def _parse_header(path, buf: bytes, magic: bytes) -> _Header:
    """OctoMap's header check (first line) and ``readHeader`` (the keywords up to ``data``)."""
    first_end = buf.find(b"\n")
    first = buf[: first_end if first_end >= 0 else len(buf)]
    if not first.startswith(magic):
        raise FormatError(path, f"first line must start with {magic.decode()!r}, found "
                          f"{first[:60].decode('latin-1')!r}", offset=0)
    h = _Header()
    pos = len(buf) if first_end < 0 else first_end + 1
    while True:
        tok, at, pos = _token(buf, pos)
        if not tok:
            raise FormatError(path, "the header ends without a 'data' line", offset=at)
        if tok == b"data":
            h.data_at = _skip_line(buf, pos)
            break
        if tok.startswith(b"#"):
            pos = _skip_line(buf, pos)
        elif tok in (b"id", b"res", b"size"):
            val, vat, pos = _token(buf, pos)
            if not val:
                raise FormatError(path, f"the header ends after {tok.decode()!r}", offset=vat)
            if tok == b"id":
                h.tree_id, h.id_at = val.decode("latin-1"), vat
            elif tok == b"res":
                if not _FLOAT.match(val):
                    raise FormatError(path, f"res must be a number, found {val[:40].decode('latin-1')!r}", offset=vat)
                h.res = float(val)
                if not (h.res > 0.0 and np.isfinite(h.res)):
                    raise FormatError(path, f"res must be a positive finite number of metres, found {h.res!r}",
                                      offset=vat)
            else:
                if not _UINT.match(val) or int(val) >= 1 << 32:
                    raise FormatError(path, f"size must be a node count (0 .. 2**32-1), found "
                                      f"{val[:40].decode('latin-1')!r}", offset=vat)
                h.size, h.size_at = int(val), vat
        else:
            warnings.warn(f"{path}: unknown keyword {tok[:40].decode('latin-1')!r} in the octree header "
                          f"(byte {at}), line skipped", stacklevel=4)
            pos = _skip_line(buf, pos)
    if not h.tree_id:
        raise FormatError(path, "the header sets no 'id'", offset=h.data_at)
    if h.res <= 0.0:
        raise FormatError(path, "the header sets no positive 'res'", offset=h.data_at)
    if h.tree_id == "1":  # OctoMap's deprecated id
        h.tree_id = "OcTree"
    return h


def _legacy_binary_header(path, buf: bytes) -> _Header | None:
    """OctoMap's pre-1.0 ``.bt`` header: int32 tree type 3, float64 res, uint32 size."""
    if len(buf) < 16 or struct.unpack_from("<i", buf, 0)[0] != 3:
        return None
    h = _Header()
    h.res = struct.unpack_from("<d", buf, 4)[0]
    if not (h.res > 0.0 and np.isfinite(h.res)):
        raise FormatError(path, f"invalid resolution {h.res!r} in the legacy binary header", offset=4)
    h.size, h.size_at = struct.unpack_from("<I", buf, 12)[0], 12
    h.tree_id, h.data_at = "OcTree", 16
    return h


def _read(path) -> bytes:
    try:
        return Path(path).read_bytes()
    except IsADirectoryError:
        raise FormatError(path, "is a directory, not an octree file") from None


def _check(path, h: _Header, err: int, offset: int, nodes: int):
    if err != C.OK:
        raise FormatError(path, _MESSAGES[err], offset=int(offset))
    if nodes != h.size:
        raise FormatError(path, f"the header's size says {h.size} nodes but the data holds {nodes}",
                          offset=h.size_at if h.size_at is not None else h.data_at)


def _empty_or_fail(path, h: _Header, buf: bytes) -> bool:
    """OctoMap reads no body when ``size`` is 0; then nothing may follow the header."""
    if h.size != 0:
        return False
    if len(buf) > h.data_at:
        raise FormatError(path, f"size is 0 but {len(buf) - h.data_at} bytes of data follow the header",
                          offset=h.data_at)
    return True


def decode_bt(buf: bytes, path="<bytes>", **tree_kwargs) -> OcTree:
    """An :class:`OcTree` from the bytes of a ``.bt`` file (see :func:`read_bt`)."""
    h = None if buf.startswith(BINARY_MAGIC) else _legacy_binary_header(path, buf)
    if h is None:
        h = _parse_header(path, buf, BINARY_MAGIC)
        if h.tree_id not in _BINARY_IDS:
            raise FormatError(path, f"id {h.tree_id!r} is not an occupancy octree (expected 'OcTree')",
                              offset=h.id_at)
    tree = OcTree(h.res, **tree_kwargs)
    if _empty_or_fail(path, h, buf):
        return tree
    data = np.frombuffer(buf, np.uint8)
    lo, hi = (np.float32(v) for v in tree.clamping_log_odds)
    slots, top, nodes, err, offset = C.decode_bt(data, h.data_at, lo, hi)
    _check(path, h, err, offset, nodes)
    return OcTree.from_nodes(h.res, slots[:top], int(nodes), **tree_kwargs)


def decode_ot(buf: bytes, path="<bytes>", **tree_kwargs) -> OcTree:
    """An :class:`OcTree` from the bytes of a ``.ot`` file (see :func:`read_ot`)."""
    h = _parse_header(path, buf, FULL_MAGIC)
    if h.tree_id != "OcTree":
        raise FormatError(path, f"id {h.tree_id!r}: only 'OcTree' .ot files can be read (other trees' "
                          f"node records differ)", offset=h.id_at)
    if _empty_or_fail(path, h, buf):
        return OcTree(h.res, **tree_kwargs)
    n_rec = (len(buf) - h.data_at) // 5
    rec = np.frombuffer(buf, np.dtype([("v", "<f4"), ("m", "u1")]), count=n_rec, offset=h.data_at)
    values = rec["v"].astype(np.float32)
    masks = np.ascontiguousarray(rec["m"])
    slots, top, nodes, err, offset = C.decode_ot(values, masks, h.data_at, len(buf))
    _check(path, h, err, offset, nodes)
    return OcTree.from_nodes(h.res, slots[:top], int(nodes), **tree_kwargs)


def read_bt(path, **tree_kwargs) -> OcTree:
    """Read an OctoMap ``.bt`` file (current or legacy header). Leaves get the clamping bound of
    their class (free: lower, occupied: upper), inner nodes the maximum of their children.
    ``tree_kwargs`` (``prob_hit``, ``clamp``, ...) go to :class:`OcTree`; the file stores only
    the resolution. Raises :class:`~occmap.errors.FormatError` for a malformed file."""
    return decode_bt(_read(path), path, **tree_kwargs)


def read_ot(path, **tree_kwargs) -> OcTree:
    """Read an OctoMap ``.ot`` file (id ``OcTree``): every node with its stored log-odds.
    ``tree_kwargs`` go to :class:`OcTree`. Raises :class:`~occmap.errors.FormatError`."""
    return decode_ot(_read(path), path, **tree_kwargs)


def read_octree(path, **tree_kwargs) -> OcTree:
    """Read ``.bt`` or ``.ot`` by the file's extension; any other extension by its first line."""
    suffix = Path(path).suffix.lower()
    if suffix == ".bt":
        return read_bt(path, **tree_kwargs)
    if suffix == ".ot":
        return read_ot(path, **tree_kwargs)
    buf = _read(path)
    if buf.startswith(BINARY_MAGIC):
        return decode_bt(buf, path, **tree_kwargs)
    if buf.startswith(FULL_MAGIC):
        return decode_ot(buf, path, **tree_kwargs)
    raise FormatError(path, "not an OctoMap file: expected extension .bt or .ot, or a first line "
                      f"starting with {BINARY_MAGIC.decode()!r} or {FULL_MAGIC.decode()!r}", offset=0)

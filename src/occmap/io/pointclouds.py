"""3D point cloud files → :class:`~occmap.cloud.PointCloud`, and back.

Every reader returns points in the **sensor** frame (metres, float64) with the sensor pose
``T_world_sensor`` in ``PointCloud.pose`` where the format records one, and drops points with a
non-finite coordinate (NaN, ±inf), counting them in ``PointCloud.dropped``. Files may be plain or
compressed with gzip, bzip2 or xz (detected from the first bytes, whatever the name); the whole
file is read into memory once and parsed with NumPy, never point by point. Byte offsets in error
messages count bytes of the (decompressed) data; line numbers start at 1.

Formats
-------
``read_xyz``
    ASCII, one point per line, ``x y z`` then any number of further columns (ignored). Blank
    lines and ``#`` comments are skipped. A line with fewer than three numbers, or a field that is
    not a number, raises :class:`~occmap.errors.FormatError` naming the line.
``read_pcd``
    PCL's PCD v0.7 (and v0.6 without ``VIEWPOINT``/``POINTS``), ``DATA ascii`` or ``binary``.
    ``x``, ``y``, ``z`` are picked by name from any ``FIELDS``/``SIZE``/``TYPE``/``COUNT``
    layout (``F`` 4/8, ``I`` and ``U`` 1/2/4/8 bytes; binary data little-endian, records packed
    in field order). ``VIEWPOINT tx ty tz qw qx qy qz`` becomes ``pose``: points stay in the frame
    they are stored in and the viewpoint places that frame in the world, which is how PCL's own
    viewer uses it (``PCLVisualizer`` sets ``sensor_origin_``/``sensor_orientation_`` as the
    cloud actor's transform). ``binary_compressed`` (LZF) is refused with a clear error.
    Bytes after the last binary record are ignored, as PCL does.
``read_ply``
    PLY ``ascii 1.0``, ``binary_little_endian 1.0`` and ``binary_big_endian 1.0``. The
    ``vertex`` element's ``x``, ``y``, ``z`` properties (any numeric type) are read; other
    vertex properties and elements after ``vertex`` are skipped. Elements before ``vertex`` are
    skipped too, except, in binary files, one with a ``list`` property (its size is not known
    without walking it item by item), which raises :class:`~occmap.errors.FormatError`.
``read_kitti_bin``
    KITTI Velodyne ``.bin``: packed little-endian float32 records ``x y z reflectance``.
``read_uos``
    3DTK / Univ. Osnabrück ``scanNNN.3d`` with its pose; see :func:`read_uos` for the frame and
    pose conventions.

Writers (:func:`write_xyz`, :func:`write_pcd`, :func:`write_ply`) take an (N, 3) array or a
:class:`~occmap.cloud.PointCloud` and write through :func:`occmap._files.write_atomic`, so a crash
never leaves half a file. PCD keeps the cloud's pose (sensor-frame points + ``VIEWPOINT``);
XYZ and PLY have no pose, so a cloud goes out in the world frame.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .. import checks
from .._files import write_atomic
from ..cloud import PointCloud
from ..errors import FormatError, InvalidArgumentError, MissingFileError, ShapeError
from ..geometry.se3 import SE3
from ._compression import EXTENSIONS, read_bytes
from . import _text
from ._text import Table

__all__ = [
    "read_cloud",
    "read_xyz",
    "read_pcd",
    "read_ply",
    "read_kitti_bin",
    "read_uos",
    "uos_euler_to_matrix",
    "uos_matrix_to_se3",
    "uos_points_to_rh",
    "write_xyz",
    "write_pcd",
    "write_ply",
]

_MAX_HEADER = 1 << 16  # bytes of PCD / PLY header searched for the end of the header


# --------------------------------------------------------------------------------------------
# shared helpers


def _finite_cloud(points: np.ndarray, *, pose=None, drop_origin=False, dropped=0) -> PointCloud:
    """Build a PointCloud from (N, 3) float64, dropping non-finite rows (and exact zeros)."""
    keep = np.isfinite(points).all(axis=1)
    if drop_origin:
        keep &= (points != 0.0).any(axis=1)
    n_bad = int(points.shape[0] - np.count_nonzero(keep))
    if n_bad:
        points = points[keep]
    return PointCloud(np.ascontiguousarray(points, dtype=np.float64), pose, None, dropped + n_bad)


def _as_points(points, name="points") -> np.ndarray:
    if isinstance(points, PointCloud):
        return points.points
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError(f"{name} must have shape (N, 3), got {p.shape}")
    return p


def _parse_pose(pose) -> SE3 | None:
    if pose is None or isinstance(pose, SE3):
        return pose
    return SE3(pose)


def _declared_columns(path, table: Table, cols, dtypes, names) -> np.ndarray:
    """Columns ``cols`` of an ASCII table, rounded to the type the header declares for each (a
    ``float`` column written as ``0.1`` holds float32(0.1), as it would in a binary file).
    Integer columns must hold whole numbers within the type's range. Returns float64 (N, k)."""
    pts = table.columns(cols)
    for k, dt in enumerate(dtypes):
        dt = np.dtype(dt)
        col = pts[:, k]
        if dt.kind == "f":
            if dt.itemsize < 8:
                with np.errstate(over="ignore"):
                    pts[:, k] = col.astype(dt)
        else:
            info = np.iinfo(dt)
            bad = ~((col == np.floor(col)) & (col >= info.min) & (col <= info.max))
            if bad.any():
                i = int(np.argmax(bad))
                msg = f"field {names[k]!r} = {float(col[i])!r} does not fit the declared type {dt.name}"
                raise FormatError(path, msg, line=int(table.lines[i]))
    return pts


def _nth_newline_end(data: bytes, start: int, n: int) -> int:
    """Byte position just after the ``n``-th newline at or after ``start`` (or len(data))."""
    if n <= 0:
        return start
    nl = np.flatnonzero(np.frombuffer(data, dtype=np.uint8, offset=start) == 10)
    if nl.size < n:
        return len(data)
    return start + int(nl[n - 1]) + 1


def _header_lines(data: bytes, stop):
    """Yield ``(line_number, text, end_offset)`` of header lines until ``stop(text)`` is true."""
    pos = 0
    number = 0
    while True:
        end = data.find(b"\n", pos, pos + _MAX_HEADER)
        if end < 0:
            if pos >= len(data) or len(data) - pos >= _MAX_HEADER:
                return
            end = len(data)
        number += 1
        text = data[pos:end].decode("latin-1").rstrip("\r")
        yield number, text, min(end + 1, len(data))
        if stop(text):
            return
        pos = end + 1
        if pos > _MAX_HEADER:
            return


# --------------------------------------------------------------------------------------------
# XYZ


def read_xyz(path, pose=None) -> PointCloud:
    """Read an ASCII ``x y z [more columns…]`` file (plain, .gz, .bz2 or .xz), one point a line.

    Parameters
    ----------
    path : str or Path
    pose : SE3 or (4, 4) array, optional
        ``T_world_sensor`` to attach to the cloud (the format has none; default identity).

    Columns after the third are ignored; blank lines and ``#`` comments are skipped; points with
    a NaN or infinite coordinate are dropped and counted in ``dropped``.
    """
    return _read_xyz(path, _parse_pose(pose))


_RAW = object()  # sentinel: _read_xyz returns the raw (N, 3) array


def _read_xyz(path, pose, scale=1.0, first_line_header=None) -> np.ndarray | PointCloud:
    data = read_bytes(path)
    start, line0 = 0, 1
    if first_line_header is not None:
        end = data.find(b"\n")
        first = data[: end if end >= 0 else len(data)].decode("latin-1")
        if first_line_header.fullmatch(first.strip()):
            start, line0 = (end + 1 if end >= 0 else len(data)), 2
    table = Table(path, data[start:] if start else data, line0, comments=True)
    table.require(path, at_least=3, what="x y z")
    pts = table.columns((0, 1, 2))
    if scale != 1.0:
        pts *= scale
    if pose is _RAW:
        return pts
    return _finite_cloud(pts, pose=pose)


# --------------------------------------------------------------------------------------------
# PCD

_PCD_TYPES = {
    ("F", 4): "f4", ("F", 8): "f8",
    ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
    ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
}  # fmt: skip


def _is_data_line(text: str) -> bool:
    words = text.split()
    return bool(words) and words[0].upper() == "DATA"


def read_pcd(path, drop_origin: bool = True) -> PointCloud:
    """Read a PCL ``.pcd`` file (``DATA ascii`` or ``binary``) into a :class:`PointCloud`.

    Parameters
    ----------
    path : str or Path
    drop_origin : bool
        Drop points that are exactly ``(0, 0, 0)`` (default true). Many drivers (Velodyne
        among them) write a zero point for a beam without a return; such a point would insert
        an occupied voxel at the sensor. They are counted in ``dropped`` with the non-finite
        points. Pass ``False`` to keep the file's points as they are (non-finite ones are
        still dropped).

    ``pose`` comes from ``VIEWPOINT tx ty tz qw qx qy qz``; its quaternion is normalised (a
    norm off by more than 1e-3 is an error). An absent ``VIEWPOINT`` or PCL's default
    ``0 0 0 1 0 0 0`` (written when the pose is not known) gives the identity with
    ``has_pose`` false. ``stamp`` is None.
    """
    data = read_bytes(path)
    hdr: dict[str, tuple[int, list[str]]] = {}
    data_start = None
    last_line = 0
    for number, text, end in _header_lines(data, _is_data_line):
        last_line = number
        words = text.split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0].upper()
        if key not in {"VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
                       "VIEWPOINT", "POINTS", "DATA"}:  # fmt: skip
            raise FormatError(path, f"unknown PCD header keyword {words[0][:40]!r}", line=number)
        hdr["FIELDS" if key == "COLUMNS" else key] = (number, words[1:])
        if key == "DATA":
            data_start = end
    if data_start is None:
        raise FormatError(path, "not a PCD file: no DATA line in the header", line=last_line or None)

    def need(key):
        if key not in hdr:
            raise FormatError(path, f"PCD header has no {key} line", line=hdr["DATA"][0])
        return hdr[key]

    def ints(key, count=None):
        line, words = need(key)
        vals = [_text.count(path, w, f"{key} value (integers >= 0)", line) for w in words]
        if count is not None and len(vals) != count:
            raise FormatError(path, f"{key} has {len(vals)} values, expected {count} (one per field)", line=line)
        return vals

    fields_line, fields = need("FIELDS")
    nf = len(fields)
    if nf == 0:
        raise FormatError(path, "FIELDS is empty", line=fields_line)
    sizes = ints("SIZE", nf)
    type_line, types = need("TYPE")
    if len(types) != nf:
        raise FormatError(path, f"TYPE has {len(types)} values, expected {nf} (one per field)", line=type_line)
    counts = ints("COUNT", nf) if "COUNT" in hdr else [1] * nf
    width = ints("WIDTH", 1)[0]
    height = ints("HEIGHT", 1)[0] if "HEIGHT" in hdr else 1
    n_points = ints("POINTS", 1)[0] if "POINTS" in hdr else width * height
    if n_points != width * height:
        raise FormatError(path, f"POINTS {n_points} != WIDTH × HEIGHT = {width} × {height}", line=hdr["POINTS"][0])
    dtypes = []
    for f, s, t in zip(fields, sizes, types):
        dt = _PCD_TYPES.get((t.upper(), s))
        if dt is None:
            raise FormatError(path, f"field {f!r}: unsupported TYPE {t!r} with SIZE {s}", line=type_line)
        dtypes.append(dt)
    index = {}
    for k, f in enumerate(fields):
        index.setdefault(f, k)
    for axis in "xyz":
        if axis not in index:
            raise FormatError(path, f"PCD has no field {axis!r} (FIELDS {' '.join(fields)[:80]})", line=fields_line)
        if counts[index[axis]] != 1:
            raise FormatError(path, f"field {axis!r} has COUNT {counts[index[axis]]}, expected 1", line=fields_line)

    pose = None
    if "VIEWPOINT" in hdr:
        vline, words = hdr["VIEWPOINT"]
        try:
            vp = np.array([float(w) for w in words], dtype=np.float64)
        except ValueError:
            vp = np.zeros(0)
        if vp.shape != (7,) or not np.isfinite(vp).all():
            got = " ".join(words)[:120]
            raise FormatError(path, f"VIEWPOINT must be 7 finite numbers tx ty tz qw qx qy qz, got {got!r}", line=vline)
        norm = float(np.linalg.norm(vp[3:]))
        if abs(norm - 1.0) > 1e-3:
            msg = f"VIEWPOINT quaternion {vp[3:].tolist()} has norm {norm:.6g}, expected 1"
            raise FormatError(path, msg, line=vline)
        if not np.array_equal(vp, [0, 0, 0, 1, 0, 0, 0]):
            pose = SE3.from_quat(vp[3:] / norm, vp[:3])

    data_line, data_kind = hdr["DATA"]
    kind = data_kind[0].lower() if data_kind else ""
    if kind == "ascii":
        table = Table(path, data[data_start:], data_line + 1, comments=False)
        ncols = sum(counts)
        table.require(path, exactly=ncols, what=" ".join(fields)[:80])
        if len(table) != n_points:
            line = int(table.lines[n_points]) if len(table) > n_points else data_line + 1 + len(table)
            raise FormatError(path, f"expected {n_points} points (POINTS), found {len(table)}", line=line)
        col = np.cumsum([0] + counts[:-1])
        pts = _declared_columns(path, table, [col[index[a]] for a in "xyz"], [dtypes[index[a]] for a in "xyz"], "xyz")
    elif kind == "binary":
        offsets = np.cumsum([0] + [s * c for s, c in zip(sizes, counts)])
        rec = int(offsets[-1])
        need_bytes = n_points * rec
        have = len(data) - data_start
        if have < need_bytes:
            raise FormatError(
                path,
                f"binary data truncated: {n_points} points × {rec} bytes need {need_bytes} bytes, "
                f"{have} left (point {have // rec if rec else 0} is incomplete)",
                offset=data_start + (have // rec) * rec if rec else data_start,
            )
        dt = np.dtype({
            "names": ["x", "y", "z"],
            "formats": ["<" + dtypes[index[a]] for a in "xyz"],
            "offsets": [int(offsets[index[a]]) for a in "xyz"],
            "itemsize": rec,
        })  # fmt: skip
        recs = np.frombuffer(data, dtype=dt, count=n_points, offset=data_start)
        pts = np.empty((n_points, 3), dtype=np.float64)
        for k, a in enumerate("xyz"):
            pts[:, k] = recs[a]
    elif kind == "binary_compressed":
        raise FormatError(
            path,
            "DATA binary_compressed (LZF) is not supported; convert the file to binary or ascii "
            "first (e.g. pcl_convert_pcd_ascii_binary in.pcd out.pcd 1)",
            line=data_line,
        )
    else:
        got = " ".join(data_kind)[:40]
        raise FormatError(path, f"DATA must be ascii, binary or binary_compressed, got {got!r}", line=data_line)
    return _finite_cloud(pts, pose=pose, drop_origin=drop_origin)


# --------------------------------------------------------------------------------------------
# PLY

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def read_ply(path) -> PointCloud:
    """Read the ``vertex`` element's ``x y z`` from a PLY file (ascii, binary little- or big-endian).

    The pose is identity (PLY has none); non-finite points are dropped and counted.
    """
    data = read_bytes(path)
    if data[:3] != b"ply":
        raise FormatError(path, "not a PLY file: it does not start with 'ply'", offset=0)
    fmt = None
    elements: list[list] = []  # [name, count, line, [(prop_name, dtype | None for list)], list_lines]
    data_start = None
    last = 0
    for number, text, end in _header_lines(data, lambda t: t.strip() == "end_header"):
        last = number
        words = text.split()
        if number == 1:
            if words != ["ply"]:
                raise FormatError(path, "not a PLY file: first line must be 'ply'", line=1)
            continue
        if not words or words[0] in ("comment", "obj_info"):
            continue
        key = words[0]
        if key == "end_header":
            data_start = end
        elif key == "format":
            if len(words) != 3 or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise FormatError(path, f"unsupported PLY format line {text.strip()[:80]!r}", line=number)
            fmt = words[1]
        elif key == "element":
            if len(words) != 3:
                msg = f"bad element line {text.strip()[:80]!r}, expected 'element NAME COUNT'"
                raise FormatError(path, msg, line=number)
            elements.append([words[1], _text.count(path, words[2], f"element {words[1][:40]} count", number), number, []])
        elif key == "property":
            if not elements:
                raise FormatError(path, "property before any element", line=number)
            if len(words) == 5 and words[1] == "list":
                if words[2] not in _PLY_TYPES or words[3] not in _PLY_TYPES:
                    raise FormatError(path, f"unknown PLY type in {text.strip()[:80]!r}", line=number)
                elements[-1][3].append((words[4], None))
            elif len(words) == 3 and words[1] in _PLY_TYPES:
                elements[-1][3].append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise FormatError(path, f"bad property line {text.strip()[:80]!r}", line=number)
        else:
            raise FormatError(path, f"unknown PLY header keyword {key[:40]!r}", line=number)
    if data_start is None:
        raise FormatError(path, "PLY header has no end_header line", line=last or None)
    if fmt is None:
        raise FormatError(path, "PLY header has no format line", line=last)
    header_lines = last
    vertex = next((e for e in elements if e[0] == "vertex"), None)
    if vertex is None:
        raise FormatError(path, "PLY file has no vertex element", line=header_lines)
    name, count, vline, props = vertex
    pnames = [p[0] for p in props]
    for axis in "xyz":
        if axis not in pnames:
            raise FormatError(path, f"vertex element has no property {axis!r}", line=vline)
    if any(p[1] is None for p in props):
        raise FormatError(path, "vertex element with a list property is not supported", line=vline)
    before = elements[: elements.index(vertex)]

    if fmt == "ascii":
        skip = sum(e[1] for e in before)
        start = _nth_newline_end(data, data_start, skip)
        stop = _nth_newline_end(data, start, count)
        line0 = header_lines + skip + 1
        table = Table(path, data[start:stop], line0, comments=False)
        if len(table) != count:
            raise FormatError(path, f"expected {count} vertex lines, found {len(table)}", line=line0 + len(table))
        table.require(path, exactly=len(props), what=" ".join(pnames)[:80])
        cols = [pnames.index(a) for a in "xyz"]
        pts = _declared_columns(path, table, cols, [props[c][1] for c in cols], "xyz")
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        offset = data_start
        for e in before:
            if any(p[1] is None for p in e[3]):
                raise FormatError(
                    path,
                    f"element {e[0]!r} with a list property comes before 'vertex'; skipping it in a "
                    "binary PLY is not supported",
                    line=e[2],
                )
            offset += e[1] * sum(np.dtype(p[1]).itemsize for p in e[3])
        dt = np.dtype({"names": [f"p{k}" for k in range(len(props))],
                       "formats": [order + p[1] for p in props]})  # fmt: skip
        end = offset + count * dt.itemsize
        if end > len(data):
            have = max(len(data) - offset, 0)
            raise FormatError(
                path,
                f"binary vertex data truncated: {count} vertices × {dt.itemsize} bytes need "
                f"{count * dt.itemsize} bytes, {have} left",
                offset=offset + (have // dt.itemsize) * dt.itemsize,
            )
        recs = np.frombuffer(data, dtype=dt, count=count, offset=offset)
        pts = np.empty((count, 3), dtype=np.float64)
        for k, a in enumerate("xyz"):
            pts[:, k] = recs[f"p{pnames.index(a)}"]
    return _finite_cloud(pts)


# --------------------------------------------------------------------------------------------
# KITTI


def read_kitti_bin(path, pose=None) -> PointCloud:
    """Read a KITTI Velodyne ``.bin`` scan: little-endian float32 ``x y z reflectance`` records.

    Reflectance is not kept. ``pose`` (SE3 or 4×4, default identity) is attached as given.
    A size that is not a multiple of 16 bytes raises FormatError at the incomplete record.
    """
    data = read_bytes(path)
    n, rest = divmod(len(data), 16)
    if rest:
        raise FormatError(
            path,
            f"size {len(data)} is not a multiple of 16 (float32 x y z reflectance records); "
            f"the last record has {rest} bytes",
            offset=n * 16,
        )
    recs = np.frombuffer(data, dtype="<f4").reshape(n, 4)
    return _finite_cloud(recs[:, :3].astype(np.float64), pose=_parse_pose(pose))


# --------------------------------------------------------------------------------------------
# UOS / 3DTK

#: 3DTK left-handed (x right, y up, z forward) → right-handed (x forward, y left, z up) axes.
_UOS_C = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
_UOS_HEADER = re.compile(r"\d+\s*[xX×]\s*\d+")


def uos_points_to_rh(points_cm) -> np.ndarray:
    """3DTK points (..., 3) — centimetres, left-handed x right, y up, z forward — to metres in
    a right-handed frame with x forward, y left, z up: ``(z, −x, y) / 100``.

    This is 3DTK's own conversion (``TdtkRosWrapper::pointcloud2scan`` does the inverse,
    ``(x, y, z)_3dtk = (−100 y, 100 z, 100 x)``, and ``toRieglMat`` / ``frames2ros`` in
    ``include/slam6d/globals.icc`` and ``src/ros/tdtkroswrapper.cc`` treat poses the same way).
    """
    p = np.asarray(points_cm, dtype=np.float64)
    return np.stack((p[..., 2], -p[..., 0], p[..., 1]), axis=-1) / 100.0


def uos_euler_to_matrix(translation_cm, angles_deg) -> np.ndarray:
    """3DTK's ``EulerToMatrix4`` for a ``.pose`` file: a (4, 4) matrix in 3DTK's own frame
    (left-handed, centimetres), ``M = [[Rx(θx) Ry(θy) Rz(θz), t], [0, 1]]``, acting on column
    vectors (``p_world = M p_scan``).

    Angles are in degrees as the file stores them (3DTK's ``readPoseHelper`` converts them to
    radians); ``Rx``, ``Ry``, ``Rz`` are the usual right-hand-rule matrices applied to the
    coordinates as written. Use :func:`uos_matrix_to_se3` to get an :class:`SE3` in metres.
    """
    t = np.asarray(translation_cm, dtype=np.float64).reshape(3)
    ax, ay, az = np.radians(np.asarray(angles_deg, dtype=np.float64).reshape(3))
    sx, cx, sy, cy, sz, cz = np.sin(ax), np.cos(ax), np.sin(ay), np.cos(ay), np.sin(az), np.cos(az)
    m = np.eye(4)
    m[:3, :3] = [
        [cy * cz, -cy * sz, sy],
        [sx * sy * cz + cx * sz, -sx * sy * sz + cx * cz, -sx * cy],
        [-cx * sy * cz + sx * sz, cx * sy * sz + sx * cz, cx * cy],
    ]
    m[:3, 3] = t
    return m


def uos_matrix_to_se3(matrix) -> SE3:
    """A 3DTK pose matrix (4, 4) — left-handed, centimetres, ``p_world = M p_scan`` — as
    ``T_world_sensor`` in the right-handed metre frame of :func:`uos_points_to_rh`:
    ``R = C R_3dtk Cᵀ``, ``t = C t_3dtk / 100`` with ``C`` the axis map ``(x, y, z) → (z, −x, y)``.

    The rotation block is replaced by its nearest rotation (the files keep 6 significant digits,
    which is not orthonormal to 1e-6).
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ShapeError(f"matrix must have shape (4, 4), got {m.shape}")
    out = np.eye(4)
    out[:3, :3] = _UOS_C @ m[:3, :3] @ _UOS_C.T
    out[:3, 3] = _UOS_C @ m[:3, 3] / 100.0
    return SE3.from_matrix(out, project=True)


def _uos_sidecar(scan_path: Path, suffixes) -> Path:
    stem = scan_path.name[: -len(scan_path.suffix)] if scan_path.suffix else scan_path.name
    tried = []
    for suf in suffixes:
        p = scan_path.with_name(stem + suf)
        if p.exists():
            return p
        tried.append(str(p))
    raise MissingFileError(scan_path, f"no pose file beside the scan: tried {', '.join(tried)}")


def _uos_frames(path) -> np.ndarray:
    table = Table(path, read_bytes(path), 1, comments=True)
    if len(table) == 0:
        raise FormatError(path, "frames file holds no matrix", line=1)
    n = int(table.counts[-1])
    line = int(table.lines[-1])
    if n not in (16, 17):
        raise FormatError(path, f"expected 16 matrix values and a flag (17 fields), got {n}", line=line)
    vals = table.values[table.starts[-1] : table.starts[-1] + 16]
    m = vals.reshape(4, 4).T  # OpenGL / column-major
    if not np.isfinite(m).all() or np.abs(m[3] - (0, 0, 0, 1)).max() > 1e-6:
        raise FormatError(path, f"last matrix is not a rigid transform (last row {m[3].tolist()})", line=line)
    return m


def _uos_pose_file(path) -> np.ndarray:
    table = Table(path, read_bytes(path), 1, comments=False)
    if table.values.size < 6 or len(table) < 2 or table.counts[0] != 3 or table.counts[1] != 3:
        line = int(table.lines[min(len(table), 2) - 1]) if len(table) else 1
        raise FormatError(path, "expected 'x y z' (cm) on line 1 and 'rx ry rz' (degrees) on line 2", line=line)
    v = table.values[:6]
    if not np.isfinite(v).all():
        raise FormatError(path, f"non-finite pose values {v.tolist()}", line=1)
    return uos_euler_to_matrix(v[:3], v[3:])


#: Range (m) at which the Osnabrück scanner of the 3DTK samples writes a beam that saw nothing: its
#: 16-bit maximum, 32,767 mm (see ../shared/data/README.md: "a range at or above the sensor's
#: maximum means no return").
UOS_NO_RETURN = 32.767


def read_uos(scan_path, pose="frames", no_return: float | None = UOS_NO_RETURN) -> PointCloud:
    """Read a 3DTK / UOS ``scanNNN.3d`` scan with its pose.

    Frames and units
    ----------------
    3DTK stores ``x y z`` in centimetres in a left-handed frame (x right, y up, z forward);
    further columns (reflectance, colour) are ignored, and a first line ``W x H`` (the scan's
    resolution, written by old 3DTK tools) is skipped. Points are returned in metres in the
    right-handed frame x forward, y left, z up: ``(x, y, z)_rh = (z, −x, y)_3dtk / 100``
    (3DTK's own convention, see :func:`uos_points_to_rh`). Poses go through the same axis map
    (:func:`uos_matrix_to_se3`), so ``cloud.world_points()`` equals 3DTK's registered points
    with the axis map applied.

    Parameters
    ----------
    scan_path : str or Path
        The ``.3d`` file; pose files are looked for beside it.
    pose : "frames", "pose", None or SE3
        * ``"frames"`` (default): the last line of ``scanNNN.frames`` (or, when that is
          absent, ``scanNNN.frames_slam6d_2009``): the registered pose from 3DTK's slam6D,
          16 values of a column-major (OpenGL) 4×4 matrix in cm plus a flag, as 3DTK's
          ``readPoseHelper`` reads it.
        * ``"pose"``: ``scanNNN.pose``, the initial (odometry) estimate: translation in cm on
          line 1, angles ``θx θy θz`` in degrees on line 2, turned into a matrix by 3DTK's
          ``EulerToMatrix4``: ``R = Rx(θx) Ry(θy) Rz(θz)`` in 3DTK's frame
          (:func:`uos_euler_to_matrix`).
        * ``None``: identity (the sensor frame).
        * an :class:`SE3` (or 4×4 array): used as ``T_world_sensor`` as given (metres, right-handed).
    no_return : float or None
        Range in metres at which the scanner reports "no return" (default :data:`UOS_NO_RETURN`):
        points within 2 cm of it or beyond are dropped and counted in ``cloud.dropped`` (in the
        samples these lie at 32.755-32.770 m, the file's rounded coordinates, and no real return
        beyond 32.4 m; inserted, they would be hits on an arc that is not there); ``None`` keeps
        every point.
    """
    scan_path = Path(scan_path)
    pts_cm = _read_xyz(scan_path, _RAW, first_line_header=_UOS_HEADER)
    saturated = 0
    if no_return is not None:
        reach = 100.0 * (checks.positive("no_return", no_return, "metres") - 0.02)
        beyond = np.einsum("ij,ij->i", pts_cm, pts_cm) >= reach * reach  # (NaN rows compare False)
        saturated = int(np.count_nonzero(beyond))
        if saturated:
            pts_cm = pts_cm[~beyond]
    if isinstance(pose, str):
        if pose == "frames":
            T = uos_matrix_to_se3(_uos_frames(_uos_sidecar(scan_path, (".frames", ".frames_slam6d_2009"))))
        elif pose == "pose":
            T = uos_matrix_to_se3(_uos_pose_file(_uos_sidecar(scan_path, (".pose",))))
        else:
            raise InvalidArgumentError(f"pose must be 'frames', 'pose', None or an SE3, got {pose!r}")
    else:
        T = _parse_pose(pose)
    return _finite_cloud(uos_points_to_rh(pts_cm), pose=T, dropped=saturated)


# --------------------------------------------------------------------------------------------
# dispatch

_READERS = {
    ".xyz": "xyz", ".txt": "xyz", ".dat": "xyz", ".pts": "xyz", ".asc": "xyz",
    ".pcd": "pcd", ".ply": "ply", ".bin": "bin", ".3d": "uos",
}  # fmt: skip


def read_cloud(path, **kw) -> PointCloud:
    """Read a point cloud, choosing the reader by extension (a trailing .gz/.bz2/.xz is looked
    through): ``.xyz .txt .dat .pts .asc`` → :func:`read_xyz`, ``.pcd`` → :func:`read_pcd`,
    ``.ply`` → :func:`read_ply`, ``.bin`` → :func:`read_kitti_bin`, ``.3d`` → :func:`read_uos`.
    Keyword arguments go to that reader."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    if suffixes and suffixes[-1] in EXTENSIONS:
        suffixes.pop()
    kind = _READERS.get(suffixes[-1] if suffixes else "")
    if kind is None:
        raise InvalidArgumentError(
            f"{path}: unknown point cloud extension; expected one of {', '.join(sorted(_READERS))} "
            "(optionally followed by .gz, .bz2 or .xz)"
        )
    reader = {"xyz": read_xyz, "pcd": read_pcd, "ply": read_ply, "bin": read_kitti_bin, "uos": read_uos}[kind]
    return reader(path, **kw)


# --------------------------------------------------------------------------------------------
# writers


def _format_rows(values: np.ndarray, fmt: str) -> bytes:
    """Rows of ``values`` (N, k) as text, one line each, by one %-format of the whole array."""
    n, k = values.shape
    if n == 0:
        return b""
    line = " ".join([fmt] * k) + "\n"
    return ((line * n) % tuple(values.ravel().tolist())).encode("ascii")


def write_xyz(path, points) -> Path:
    """Write ``x y z`` lines (float64, shortest text that reads back exactly). ``points`` is an
    (N, 3) array or a :class:`PointCloud`; the format has no pose, so a cloud is written in the
    world frame (:meth:`~PointCloud.world_points`), as :func:`write_ply` does. Returns the path."""
    pts = points.world_points() if isinstance(points, PointCloud) else _as_points(points)
    return write_atomic(path, _format_rows(pts, "%r"))


def write_pcd(path, points, *, viewpoint=None, binary: bool = True) -> Path:
    """Write a PCD v0.7 file with float32 fields ``x y z``, ``DATA binary`` (or ``ascii``).

    ``points`` is an (N, 3) array or a :class:`PointCloud`; ``viewpoint`` (SE3 or 4×4) is
    written as ``VIEWPOINT`` and defaults to the cloud's pose (identity for an array), so
    :func:`read_pcd` gives back the same cloud up to float32 rounding. Coordinates are stored as
    float32 (about 7 significant digits: keep clouds in a local frame). Returns the path.
    """
    pts = _as_points(points)
    if viewpoint is None and isinstance(points, PointCloud):
        viewpoint = points.pose
    vp = _parse_pose(viewpoint)
    if vp is None:
        vp_text = "0 0 0 1 0 0 0"
    else:
        q = vp.rotation.as_quat()
        vp_text = " ".join(repr(float(v)) for v in (*vp.translation, *q))
    n = pts.shape[0]
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n"
        f"TYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT {vp_text}\nPOINTS {n}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    ).encode("ascii")
    f32 = pts.astype("<f4")
    body = f32.tobytes() if binary else _format_rows(f32.astype(np.float64), "%.9g")
    return write_atomic(path, header + body)


def write_ply(path, points, colors=None, binary: bool = True) -> Path:
    """Write points as a PLY ``vertex`` element (float32 ``x y z``), optionally coloured.

    Parameters
    ----------
    points : (N, 3) array, or a :class:`PointCloud` (its :meth:`~PointCloud.world_points`)
    colors : (N, 3) array or (3,) colour, optional
        Written as ``uchar red green blue``. Integer arrays must hold 0–255; floating arrays
        are read as 0–1 and scaled by 255 (rounded).
    binary : bool
        ``binary_little_endian 1.0`` (default) or ``ascii 1.0``.

    The header is the standard one MeshLab, CloudCompare and Open3D read. Returns the path.
    """
    pts = points.world_points() if isinstance(points, PointCloud) else _as_points(points)
    n = pts.shape[0]
    rgb = None
    if colors is not None:
        c = np.asarray(colors)
        if c.shape == (3,):
            c = np.broadcast_to(c, (n, 3))
        if c.shape != (n, 3):
            raise ShapeError(f"colors must have shape (N, 3) = ({n}, 3) or (3,), got {c.shape}")
        if np.issubdtype(c.dtype, np.floating):
            if not (np.isfinite(c).all() and c.min(initial=0) >= 0 and c.max(initial=0) <= 1):
                raise InvalidArgumentError("floating colors must lie in [0, 1]")
            rgb = np.rint(c * 255.0).astype(np.uint8)
        elif np.issubdtype(c.dtype, np.integer) or c.dtype == np.bool_:
            if c.size and (c.min() < 0 or c.max() > 255):
                raise InvalidArgumentError("integer colors must lie in 0..255")
            rgb = c.astype(np.uint8)
        else:
            raise InvalidArgumentError(f"colors must be numeric, got dtype {c.dtype}")
    props = "property float x\nproperty float y\nproperty float z\n"
    if rgb is not None:
        props += "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\ncomment written by occmap\n"
        f"element vertex {n}\n{props}end_header\n"
    ).encode("ascii")
    f32 = pts.astype("<f4")
    if binary:
        if rgb is None:
            body = f32.tobytes()
        else:
            rec = np.empty(n, dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)])
            rec["xyz"] = f32
            rec["rgb"] = rgb
            body = rec.tobytes()
    else:
        if rgb is None:
            body = _format_rows(f32.astype(np.float64), "%.9g")
        else:
            # 9 significant digits read back to the same float32; colours print as integers
            table = np.concatenate((f32.astype(np.float64), rgb.astype(np.float64)), axis=1)
            body = _format_rows(table, "%.9g")
    return write_atomic(path, header + body)

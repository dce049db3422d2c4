"""Numba kernels of the geometry core: plain float64 arrays in, arrays out.

Conventions: quaternions are (w, x, y, z), Hamilton product; rotation matrices act on column
vectors; transforms are homogeneous 4×4 (or 3×3 in 2D).

Calling convention: inputs are C-contiguous arrays of any leading shape, viewed here as rows
``(n, ...)``; an operand with a single row is broadcast with stride 0 (``i * step``, step 0 or
1), and a scalar operand may also be a plain float (see :func:`_flat`). Constant arguments (a
mode, an axis) come first. The caller allocates ``out`` in its final shape (NumPy's allocator
gives large outputs huge pages, which halves the cost of writing them); the kernel fills it and
returns nothing, since boxing a returned array costs Numba more than NumPy's whole allocation of
a small one. Each kernel checks its input in the same pass and raises :class:`Rejected` with the
index of the first bad element. Checks are written ``not (err <= tol)`` so NaN fails them; no
fastmath, which would assume NaN away.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import inline_kernel, kernel, kernel_parallel


class Rejected(Exception):
    """Raised by a kernel with the flat index of the first element its checks rejected."""


# Point loops this long or longer run on all cores; shorter ones stay serial, where the thread
# pool's dispatch would cost more than it saves.
PARALLEL_MIN = 1 << 16

UNIT_TOL = 1e-6
ROT_TOL_SQ = 1e-12  # ROTATION_TOL², compared with ‖RᵀR − I‖²_F
# cos(pitch) at or below which a matrix is at gimbal lock up to rounding (4 ulp of 1): the
# roll = 0 convention then changes the matrix by at most 2·GIMBAL_EPS
GIMBAL_EPS = 4.0 * 2.220446049250313e-16


# ---------------------------------------------------------------- checks


@inline_kernel
def _rotation_error_sq(R, i):
    """‖RᵀR − I‖²_F of the 3×3 block ``R[i]``, +inf when its determinant is ≤ 0, NaN if non-finite."""
    a00, a01, a02 = R[i, 0, 0], R[i, 0, 1], R[i, 0, 2]
    a10, a11, a12 = R[i, 1, 0], R[i, 1, 1], R[i, 1, 2]
    a20, a21, a22 = R[i, 2, 0], R[i, 2, 1], R[i, 2, 2]
    c00 = a00 * a00 + a10 * a10 + a20 * a20 - 1.0
    c11 = a01 * a01 + a11 * a11 + a21 * a21 - 1.0
    c22 = a02 * a02 + a12 * a12 + a22 * a22 - 1.0
    c01 = a00 * a01 + a10 * a11 + a20 * a21
    c02 = a00 * a02 + a10 * a12 + a20 * a22
    c12 = a01 * a02 + a11 * a12 + a21 * a22
    err = c00 * c00 + c11 * c11 + c22 * c22 + 2.0 * (c01 * c01 + c02 * c02 + c12 * c12)
    det = a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)
    if det <= 0.0:
        return np.inf
    return err


@kernel
def _rigid_ok(T, i):
    """True when ``T[i]`` (4×4) has a rotation block, a finite translation and last row (0, 0, 0, 1)."""
    if not (_rotation_error_sq(T, i) <= ROT_TOL_SQ):
        return False
    last = abs(T[i, 3, 0]) + abs(T[i, 3, 1]) + abs(T[i, 3, 2]) + abs(T[i, 3, 3] - 1.0)
    t = T[i, 0, 3] + T[i, 1, 3] + T[i, 2, 3]
    return last <= UNIT_TOL and t - t == 0.0


@kernel
def _rot2_ok(R, i):
    """True when the top-left 2×2 block of ``R[i]`` is a planar rotation [[c, −s], [s, c]]."""
    c, s = R[i, 0, 0], R[i, 1, 0]
    e = (R[i, 0, 1] + s) ** 2 + (R[i, 1, 1] - c) ** 2 + (c * c + s * s - 1.0) ** 2
    return e <= ROT_TOL_SQ


@kernel
def _rigid2_ok(T, i):
    last = abs(T[i, 2, 0]) + abs(T[i, 2, 1]) + abs(T[i, 2, 2] - 1.0)
    t = T[i, 0, 2] + T[i, 1, 2]
    return _rot2_ok(T, i) and last <= UNIT_TOL and t - t == 0.0


@inline_kernel
def _unit4(w, x, y, z):
    """True when ``|‖(w, x, y, z)‖² − 1| ≤ UNIT_TOL`` (False for NaN/inf)."""
    return abs(w * w + x * x + y * y + z * z - 1.0) <= UNIT_TOL


@inline_kernel
def _unit_ok(q, i):
    return _unit4(q[i, 0], q[i, 1], q[i, 2], q[i, 3])


@inline_kernel
def _finite4(w, x, y, z):
    """True when w, x, y, z are finite (so is their sum: one test for four values)."""
    s = w + x + y + z
    return s - s == 0.0


@kernel
def _finite_row(a, i):
    s = 0.0
    for j in range(a.shape[1]):
        s += a[i, j]
    return s - s == 0.0


@kernel
def rotation_errors(R, out):
    """‖RᵀR − I‖_F of each 3×3 matrix (+inf for det ≤ 0, NaN for non-finite) into ``out``."""
    f = R.reshape((-1, 3, 3))
    o = out.reshape(-1)
    for i in range(f.shape[0]):
        o[i] = math.sqrt(_rotation_error_sq(f, i))


@kernel
def first_nonfinite(a):
    """Index of the first row of the 2-D array ``a`` holding NaN or ±inf, or -1."""
    for i in range(a.shape[0]):
        if not _finite_row(a, i):
            return i
    return -1


@kernel
def check_rigid(T):
    """Raise :class:`Rejected` for the first 4×4 in ``T`` that is not a rigid transform."""
    f = T.reshape((-1, 4, 4))
    for i in range(f.shape[0]):
        if not _rigid_ok(f, i):
            raise Rejected(i)


@kernel
def check_rotation(R):
    """Raise :class:`Rejected` for the first 3×3 in ``R`` that is not a rotation."""
    f = R.reshape((-1, 3, 3))
    for i in range(f.shape[0]):
        if not (_rotation_error_sq(f, i) <= ROT_TOL_SQ):
            raise Rejected(i)


_TWO_PI = 2.0 * math.pi


@inline_kernel
def wrap_angle_one(a):
    """One angle (radians) wrapped to (−π, π] by :func:`occmap.geometry.so2.wrap_angle`'s rule, to
    the bit: for kernels, and for scalars in Python (a dispatcher call is cheaper than NumPy's)."""
    w = a - _TWO_PI * np.rint(a / _TWO_PI)
    if w <= -math.pi:
        w += _TWO_PI
    if w > math.pi:
        w -= _TWO_PI
    return w


@kernel
def _atan2(y, x):
    """atan2 in (−π, π]: the −π that atan2 returns for a sine of −0.0 becomes π."""
    a = math.atan2(y, x)
    return math.pi if a == -math.pi else a


@kernel
def _flat(x):
    """A scalar operand as a 1-D array: a single element comes as a one-element array (the C path,
    ``_arrays.entry``) or a 0-d one, batches come 1-D and may be strided (a column of an (N, 3) array
    is read in place; :func:`._arrays.broadcast` flattens the others)."""
    return np.atleast_1d(np.asarray(x))


def _by_rows(row, width=1, branchless=False):
    """The loop of every kernel whose rows are independent, written once: an inline kernel
    ``rows(operands, o)`` that runs ``row(operands, o, i)`` (False: element i is rejected) for each
    of the ``o.shape[0] // width`` rows ``i`` of ``o`` (``width`` > 1: the kernel passes ``o``
    flat and the row indexes it). From :data:`PARALLEL_MIN` rows one pass runs on all cores
    counting the rejected rows; a serial pass (for shorter inputs, or to find the first rejected
    row after a parallel pass) raises :class:`Rejected` with its index. A ``branchless`` row
    writes its output whatever its input: shorter inputs then first take a pass that only notes
    whether every row passed, a loop without branches that the compiler vectorises. Call
    ``rows`` from module-level kernels only: Numba caches those with ``rows`` and ``parallel``
    compiled in, but not kernels made here on their own (their cache key would hold the random
    id of each kernel they call)."""

    @kernel_parallel
    def parallel(operands, o):
        bad = 0
        for i in prange(o.shape[0] // width):
            # prange indices are unsigned: cast, or a broadcast select ``i if ... else 0`` types as float
            if not row(operands, o, np.int64(i)):
                bad += 1
        return bad

    @inline_kernel
    def rows(operands, o):
        n = o.shape[0] // width
        if n >= PARALLEL_MIN:
            if parallel(operands, o) == 0:
                return
        elif branchless:
            ok = True
            for i in range(n):
                ok &= row(operands, o, i)
            if ok:
                return
        for i in range(n):
            if not row(operands, o, i):
                raise Rejected(i)

    return rows


# ---------------------------------------------------------------- SO(3) basics


@kernel
def hat(w, out):
    f = w.reshape((-1, 3))
    o = out.reshape((-1, 3, 3))
    for i in range(f.shape[0]):
        if not _finite_row(f, i):
            raise Rejected(i)
        x, y, z = f[i, 0], f[i, 1], f[i, 2]
        o[i, 0, 0], o[i, 0, 1], o[i, 0, 2] = 0.0, -z, y
        o[i, 1, 0], o[i, 1, 1], o[i, 1, 2] = z, 0.0, -x
        o[i, 2, 0], o[i, 2, 1], o[i, 2, 2] = -y, x, 0.0


@inline_kernel
def _vee_row(operands, o, i):
    (f,) = operands
    if not _finite_row(f, i):
        return False
    o[i, 0] = 0.5 * (f[i, 7] - f[i, 5])
    o[i, 1] = 0.5 * (f[i, 2] - f[i, 6])
    o[i, 2] = 0.5 * (f[i, 3] - f[i, 1])
    return True


_vee_rows = _by_rows(_vee_row)


@kernel
def vee(W, out):
    _vee_rows((W.reshape((-1, 9)),), out.reshape((-1, 3)))


@kernel
def rot_axis(axis, angle, out):
    """Elementary rotations about coordinate axis 0 (x), 1 (y) or 2 (z)."""
    f = _flat(angle)
    o = out.reshape((-1, 3, 3))
    j = (axis + 1) % 3
    k = (axis + 2) % 3
    for i in range(f.shape[0]):
        a = f[i]
        if not (a - a == 0.0):
            raise Rejected(i)
        c, s = math.cos(a), math.sin(a)
        for r in range(3):
            for q in range(3):
                o[i, r, q] = 0.0
        o[i, axis, axis] = 1.0
        o[i, j, j] = c
        o[i, j, k] = -s
        o[i, k, j] = s
        o[i, k, k] = c


# ---------------------------------------------------------------- quaternions


@inline_kernel
def _quat_to_rot(w, x, y, z, o, i):
    """Write the rotation of (w, x, y, z) into ``o[i]``; the 2/‖q‖² factor makes it exact for any
    non-zero q, so near-unit input still yields an orthonormal matrix to rounding."""
    s = 2.0 / (w * w + x * x + y * y + z * z)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    o[i, 0, 0] = 1.0 - (yy + zz)
    o[i, 0, 1] = xy - wz
    o[i, 0, 2] = xz + wy
    o[i, 1, 0] = xy + wz
    o[i, 1, 1] = 1.0 - (xx + zz)
    o[i, 1, 2] = yz - wx
    o[i, 2, 0] = xz - wy
    o[i, 2, 1] = yz + wx
    o[i, 2, 2] = 1.0 - (xx + yy)


@inline_kernel
def _quat_to_matrix_row(operands, o, i):
    """Row i of quat_to_matrix; False for a quaternion that is not of unit norm."""
    (f,) = operands
    if not _unit_ok(f, i):
        return False
    _quat_to_rot(f[i, 0], f[i, 1], f[i, 2], f[i, 3], o, i)
    return True


_quat_to_matrix_rows = _by_rows(_quat_to_matrix_row)


@kernel
def quat_to_matrix(q, out):
    _quat_to_matrix_rows((q.reshape((-1, 4)),), out.reshape((-1, 3, 3)))


@inline_kernel
def _rot_to_quat(R, i, o, j):
    """Shepperd's pivoted method on ``R[i]`` into ``o[j]``: take the square root of the largest of
    1 + tr R and 1 + 2R_kk − tr R, so no division by a small number; exact for 180° turns.
    Result has w ≥ 0 and unit norm."""
    r00, r11, r22 = R[i, 0, 0], R[i, 1, 1], R[i, 2, 2]
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        w = 0.5 * math.sqrt(1.0 + tr)
        f = 0.25 / w
        x = (R[i, 2, 1] - R[i, 1, 2]) * f
        y = (R[i, 0, 2] - R[i, 2, 0]) * f
        z = (R[i, 1, 0] - R[i, 0, 1]) * f
    elif r00 >= r11 and r00 >= r22:
        x = 0.5 * math.sqrt(1.0 + r00 - r11 - r22)
        f = 0.25 / x
        w = (R[i, 2, 1] - R[i, 1, 2]) * f
        y = (R[i, 0, 1] + R[i, 1, 0]) * f
        z = (R[i, 0, 2] + R[i, 2, 0]) * f
    elif r11 >= r22:
        y = 0.5 * math.sqrt(1.0 - r00 + r11 - r22)
        f = 0.25 / y
        w = (R[i, 0, 2] - R[i, 2, 0]) * f
        x = (R[i, 0, 1] + R[i, 1, 0]) * f
        z = (R[i, 1, 2] + R[i, 2, 1]) * f
    else:
        z = 0.5 * math.sqrt(1.0 - r00 - r11 + r22)
        f = 0.25 / z
        w = (R[i, 1, 0] - R[i, 0, 1]) * f
        x = (R[i, 0, 2] + R[i, 2, 0]) * f
        y = (R[i, 1, 2] + R[i, 2, 1]) * f
    inv = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        inv = -inv
    o[j, 0] = w * inv
    o[j, 1] = x * inv
    o[j, 2] = y * inv
    o[j, 3] = z * inv


@inline_kernel
def _matrix_to_quat_row(operands, o, i):
    """Row i of matrix_to_quat; False for a matrix that is not a rotation."""
    (f,) = operands
    if not (_rotation_error_sq(f, i) <= ROT_TOL_SQ):
        return False
    _rot_to_quat(f, i, o, i)
    return True


_matrix_to_quat_rows = _by_rows(_matrix_to_quat_row)


@kernel
def matrix_to_quat(R, out):
    _matrix_to_quat_rows((R.reshape((-1, 3, 3)),), out.reshape((-1, 4)))


#: Flat indices into quaternion arrays are unsigned: Numba adds no negative-index wraparound to
#: them, which would cost a select per read and keep the compiler from vectorising the loop
_U = np.uint64


@inline_kernel
def _quat_product(a, j, b, k, o, i):
    """``o[i:i + 4] = a[j:j + 4] ⊗ b[k:k + 4]`` (Hamilton product) for flat arrays and unsigned
    indices; True when both factors are finite. Branchless: the product is written either way."""
    pw, px, py, pz = a[j], a[j + _U(1)], a[j + _U(2)], a[j + _U(3)]
    qw, qx, qy, qz = b[k], b[k + _U(1)], b[k + _U(2)], b[k + _U(3)]
    o[i] = pw * qw - px * qx - py * qy - pz * qz
    o[i + _U(1)] = pw * qx + px * qw + py * qz - pz * qy
    o[i + _U(2)] = pw * qy - px * qz + py * qw + pz * qx
    o[i + _U(3)] = pw * qz + px * qy - py * qx + pz * qw
    return _finite4(pw, px, py, pz) & _finite4(qw, qx, qy, qz)


@inline_kernel
def _quat_multiply_row(operands, o, i):
    a, b = operands
    p = _U(4) * _U(i)
    return _quat_product(a, p, b, p, o, p)


@inline_kernel
def _quat_left_multiply_row(operands, o, i):
    a, b = operands  # a: one quaternion
    p = _U(4) * _U(i)
    return _quat_product(a, _U(0), b, p, o, p)


@inline_kernel
def _quat_right_multiply_row(operands, o, i):
    a, b = operands  # b: one quaternion
    p = _U(4) * _U(i)
    return _quat_product(a, p, b, _U(0), o, p)


_quat_multiply_rows = _by_rows(_quat_multiply_row, 4, branchless=True)
_quat_left_multiply_rows = _by_rows(_quat_left_multiply_row, 4, branchless=True)
_quat_right_multiply_rows = _by_rows(_quat_right_multiply_row, 4, branchless=True)


@kernel
def quat_multiply(a, b, out):
    """Hamilton products of flat rows, one loop for each way the operands broadcast (batch ⊗
    batch, one ⊗ batch, batch ⊗ one): with every step a constant and no branch, the compiler
    vectorises them (at 10⁴ rows 2.5× the former loop, with steps 0 or 1 and a branch a row)."""
    fa, fb, o = a.reshape(-1), b.reshape(-1), out.reshape(-1)
    if fa.shape[0] == fb.shape[0]:
        _quat_multiply_rows((fa, fb), o)
    elif fa.shape[0] == 4:
        _quat_left_multiply_rows((fa, fb), o)
    else:
        _quat_right_multiply_rows((fa, fb), o)


@kernel
def quat_multiply_one(a, b, out):
    """Single-element form of :func:`quat_multiply` for the C single path (``_arrays.entry``): (4,)
    arrays read as they are, no row loop and no branch-free pass before it (0.10 µs a call through
    it, 0.26 µs through :func:`quat_multiply`)."""
    if not _quat_product(a, _U(0), b, _U(0), out, _U(0)):
        raise Rejected(0)


@kernel
def _max_abs4(w, x, y, z):
    return max(max(abs(w), abs(x)), max(abs(y), abs(z)))


@kernel
def quat_scale(mode, q, out):
    """mode 0: conjugate; 1: inverse (conjugate / ‖q‖²); 2: normalise. Rejects non-finite input,
    and zero quaternions for modes 1 and 2. Norms are taken of q / max|q_k|, so they neither
    underflow nor overflow for any finite non-zero q."""
    f = q.reshape((-1, 4))
    o = out.reshape((-1, 4))
    for i in range(f.shape[0]):
        w, x, y, z = f[i, 0], f[i, 1], f[i, 2], f[i, 3]
        m = _max_abs4(w, x, y, z)
        if not (m - m == 0.0) or (mode != 0 and m == 0.0):
            raise Rejected(i)
        if mode == 0:
            a, b = 1.0, -1.0
        else:
            ws, xs, ys, zs = w / m, x / m, y / m, z / m
            n = math.sqrt(ws * ws + xs * xs + ys * ys + zs * zs)
            if mode == 1:  # q* / ‖q‖² = (q / m)* / (n² m)
                a = 1.0 / (n * n * m)
                b = -a
            else:
                a = b = 1.0 / n
            w, x, y, z = ws, xs, ys, zs
        o[i, 0], o[i, 1], o[i, 2], o[i, 3] = w * a, x * b, y * b, z * b


@kernel
def _map_row(M, p, o, i):
    """o[i] = M[:, :3] @ p[i] + M[:, 3] for a 3×4 affine map ``M``; returns the sum of p[i]
    (non-finite exactly when p[i] is, so one reduction checks a whole cloud)."""
    x, y, z = p[i, 0], p[i, 1], p[i, 2]
    o[i, 0] = M[0, 0] * x + M[0, 1] * y + M[0, 2] * z + M[0, 3]
    o[i, 1] = M[1, 0] * x + M[1, 1] * y + M[1, 2] * z + M[1, 3]
    o[i, 2] = M[2, 0] * x + M[2, 1] * y + M[2, 2] * z + M[2, 3]
    return x + y + z


@kernel_parallel
def _map_rows_parallel(M, p, o):
    total = 0.0
    for i in prange(p.shape[0]):
        total += _map_row(M, p, o, i)
    return total


@kernel
def _map_points(M, p, o):
    """Apply one 3×4 map to every row of ``p`` (n, 3) into ``o``, on all cores for long inputs;
    raises :class:`Rejected` at the first non-finite point."""
    n = p.shape[0]
    if n >= PARALLEL_MIN:
        total = _map_rows_parallel(M, p, o)
    else:
        total = 0.0
        for i in range(n):
            total += _map_row(M, p, o, i)
    if not (total - total == 0.0):  # some point is NaN/inf (or the sum overflowed): find it
        for i in range(n):
            s = p[i, 0] + p[i, 1] + p[i, 2]
            if not (s - s == 0.0):
                raise Rejected(i)


@kernel
def quat_rotate(q, v, out):
    """v' = q (0, v) q*, as v + w t + u × t with t = 2 u × v and u the vector part; one quaternion
    applied to many vectors goes through its matrix and :func:`_map_points`."""
    fq = q.reshape((-1, 4))
    fv = v.reshape((-1, 3))
    o = out.reshape((-1, 3))
    if o.shape[0] == 0:
        return
    if fq.shape[0] == 1:
        if not _unit_ok(fq, 0):
            raise Rejected(0)
        M = np.zeros((1, 3, 4))
        _quat_to_rot(fq[0, 0], fq[0, 1], fq[0, 2], fq[0, 3], M, 0)
        _map_points(M[0], fv, o)
        return
    sv = 1 if fv.shape[0] > 1 else 0
    for i in range(o.shape[0]):
        if not _unit_ok(fq, i):
            raise Rejected(i)
        w, x, y, z = fq[i, 0], fq[i, 1], fq[i, 2], fq[i, 3]
        j = i * sv
        px, py, pz = fv[j, 0], fv[j, 1], fv[j, 2]
        s = px + py + pz
        if not (s - s == 0.0):
            raise Rejected(i)
        tx = 2.0 * (y * pz - z * py)
        ty = 2.0 * (z * px - x * pz)
        tz = 2.0 * (x * py - y * px)
        o[i, 0] = px + w * tx + (y * tz - z * ty)
        o[i, 1] = py + w * ty + (z * tx - x * tz)
        o[i, 2] = pz + w * tz + (x * ty - y * tx)


@kernel
def _sinc_half(theta):
    """sin(θ/2)/θ, by its series below 1e-3 where the quotient loses digits."""
    if theta < 1e-3:
        t2 = theta * theta
        return 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
    return math.sin(0.5 * theta) / theta


@kernel
def axis_angle_to_quat(axis, angle, out):
    fa = axis.reshape((-1, 3))
    fg = _flat(angle)
    o = out.reshape((-1, 4))
    sa = 1 if fa.shape[0] > 1 else 0
    sg = 1 if fg.shape[0] > 1 else 0
    for i in range(o.shape[0]):
        x, y, z = fa[i * sa, 0], fa[i * sa, 1], fa[i * sa, 2]
        a = fg[i * sg]
        norm = math.sqrt(x * x + y * y + z * z)
        inv = 1.0 / norm
        if not (norm > 0.0 and inv - inv == 0.0 and a - a == 0.0):
            raise Rejected(i)
        s = math.sin(0.5 * a) * inv
        o[i, 0] = math.cos(0.5 * a)
        o[i, 1] = x * s
        o[i, 2] = y * s
        o[i, 3] = z * s


@kernel
def _quat_axis_angle(w, x, y, z):
    """(axis x, y, z, angle) of (w, x, y, z): angle = 2·atan2(‖v‖, |w|) ∈ [0, π], accurate at both
    ends (no acos); axis (1, 0, 0) for the identity. The vector part is scaled by its largest
    component first, so neither tiny (even subnormal) nor huge parts lose digits."""
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    m = max(max(abs(x), abs(y)), abs(z))
    if m == 0.0:
        return 1.0, 0.0, 0.0, 0.0
    xs, ys, zs = x / m, y / m, z / m
    ns = math.sqrt(xs * xs + ys * ys + zs * zs)
    return xs / ns, ys / ns, zs / ns, 2.0 * math.atan2(m * ns, w)


@kernel
def _write_axis_angle(o, i, w, x, y, z, rotvec):
    """Row i of ``o``: the rotation vector (3 columns) or axis and angle (4 columns)."""
    ax, ay, az, angle = _quat_axis_angle(w, x, y, z)
    if rotvec:
        o[i, 0], o[i, 1], o[i, 2] = ax * angle, ay * angle, az * angle
    else:
        o[i, 0], o[i, 1], o[i, 2], o[i, 3] = ax, ay, az, angle


@kernel
def quat_to_axis_angle(q, out):
    f = q.reshape((-1, 4))
    o = out.reshape((-1, 4))
    for i in range(f.shape[0]):
        if not _unit_ok(f, i):
            raise Rejected(i)
        _write_axis_angle(o, i, f[i, 0], f[i, 1], f[i, 2], f[i, 3], False)


@kernel
def matrix_to_axis_angle(rotvec, R, out):
    """Axis and angle (``rotvec`` False, 4 columns) or rotation vectors (True, 3 columns)."""
    f = R.reshape((-1, 3, 3))
    o = out.reshape((-1, out.shape[-1]))
    q = np.empty((1, 4))
    for i in range(f.shape[0]):
        if not (_rotation_error_sq(f, i) <= ROT_TOL_SQ):
            raise Rejected(i)
        _rot_to_quat(f, i, q, 0)
        _write_axis_angle(o, i, q[0, 0], q[0, 1], q[0, 2], q[0, 3], rotvec)


@inline_kernel
def _slerp(aw, ax, ay, az, bw, bx, by, bz, u):
    """Spherical linear interpolation from unit quaternion a (u = 0) to b (u = 1) along the
    shorter arc (b negated when a·b < 0), as a tuple (w, x, y, z). The angle Ω between them is
    2·atan2(‖a − b‖, ‖a + b‖), accurate for nearly equal quaternions; normalised lerp takes over
    below Ω = 1e-6 rad, where sin(Ω) would divide rounding noise."""
    if aw * bw + ax * bx + ay * by + az * bz < 0.0:
        bw, bx, by, bz = -bw, -bx, -by, -bz
    ew, ex, ey, ez = aw - bw, ax - bx, ay - by, az - bz
    gw, gx, gy, gz = aw + bw, ax + bx, ay + by, az + bz
    omega = 2.0 * math.atan2(math.sqrt(ew * ew + ex * ex + ey * ey + ez * ez),
                             math.sqrt(gw * gw + gx * gx + gy * gy + gz * gz))
    if omega < 1e-6:
        wa, wb = 1.0 - u, u
    else:
        so = math.sin(omega)
        wa = math.sin((1.0 - u) * omega) / so
        wb = math.sin(u * omega) / so
    w, x, y, z = wa * aw + wb * bw, wa * ax + wb * bx, wa * ay + wb * by, wa * az + wb * bz
    inv = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return w * inv, x * inv, y * inv, z * inv


@inline_kernel
def _quat_slerp_row(operands, o, i):
    """Row i of quat_slerp (``a``, ``b`` (n, 4) and ``t`` (n,) read at steps 0 or 1); False when
    a quaternion is not of unit norm or t is not finite."""
    a, b, t, sa, sb, st = operands
    j, k, u = i * sa, i * sb, t[i * st]
    if not (_unit_ok(a, j) and _unit_ok(b, k) and u - u == 0.0):
        return False
    o[i, 0], o[i, 1], o[i, 2], o[i, 3] = _slerp(a[j, 0], a[j, 1], a[j, 2], a[j, 3], b[k, 0], b[k, 1], b[k, 2], b[k, 3], u)
    return True


_quat_slerp_rows = _by_rows(_quat_slerp_row)


@kernel
def quat_slerp(q0, q1, t, out):
    """:func:`_slerp` of each row."""
    fa = q0.reshape((-1, 4))
    fb = q1.reshape((-1, 4))
    ft = _flat(t)
    steps = (1 if fa.shape[0] > 1 else 0, 1 if fb.shape[0] > 1 else 0, 1 if ft.shape[0] > 1 else 0)
    _quat_slerp_rows((fa, fb, ft) + steps, out.reshape((-1, 4)))


@kernel
def interpolate_samples(stamps, trans, quats, t, q_out, t_out):
    """Rows ``i`` of ``q_out`` (m, 4) and ``t_out`` (m, 3): a time-stamped link's pose at ``t[i]``
    from its samples (``stamps`` (n,) sorted and distinct, n ≥ 2; translations (n, 3); unit
    quaternions (n, 4)). Between the sample before ``t[i]`` and the one after (the last two at
    the last stamp; ``t`` within the stamps), at the fraction ``a`` of the way: the translation
    ``lo + a (hi − lo)``, the rotation :func:`_slerp`; at ``a`` 0 or 1 the sample itself, bit for
    bit."""
    n = stamps.shape[0]
    for i in range(t.shape[0]):
        hi = min(max(np.searchsorted(stamps, t[i], side="right"), 1), n - 1)
        lo = hi - 1
        a = (t[i] - stamps[lo]) / (stamps[hi] - stamps[lo])
        if a == 0.0 or a == 1.0:
            k = lo if a == 0.0 else hi
            q_out[i, :] = quats[k]
            t_out[i, :] = trans[k]
            continue
        for c in range(3):
            t_out[i, c] = trans[lo, c] + a * (trans[hi, c] - trans[lo, c])
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = _slerp(
            quats[lo, 0], quats[lo, 1], quats[lo, 2], quats[lo, 3], quats[hi, 0], quats[hi, 1], quats[hi, 2], quats[hi, 3], a)


@kernel
def quat_slerp_one(q0, q1, t, out):
    """Single-element form of :func:`quat_slerp`: (4,) arrays and a float ``t``."""
    if not (_unit4(q0[0], q0[1], q0[2], q0[3]) and _unit4(q1[0], q1[1], q1[2], q1[3]) and t - t == 0.0):
        raise Rejected(0)
    out[0], out[1], out[2], out[3] = _slerp(q0[0], q0[1], q0[2], q0[3], q1[0], q1[1], q1[2], q1[3], t)


# ---------------------------------------------------------------- exp / log on SO(3)


@kernel
def exp_so3(rv, out):
    f = rv.reshape((-1, 3))
    o = out.reshape((-1, 3, 3))
    for i in range(f.shape[0]):
        x, y, z = f[i, 0], f[i, 1], f[i, 2]
        theta = math.sqrt(x * x + y * y + z * z)
        if not (theta - theta == 0.0):
            raise Rejected(i)
        s = _sinc_half(theta)
        _quat_to_rot(math.cos(0.5 * theta), x * s, y * s, z * s, o, i)


# ---------------------------------------------------------------- Euler Z-Y-X


@inline_kernel
def _euler_zyx_entries(a, b, g, o, i):
    """Write R = Rz(a) Ry(b) Rx(g) into ``o[i]``, entry by entry."""
    cy, sy = math.cos(a), math.sin(a)
    cp, sp = math.cos(b), math.sin(b)
    cr, sr = math.cos(g), math.sin(g)
    o[i, 0, 0] = cy * cp
    o[i, 0, 1] = cy * sp * sr - sy * cr
    o[i, 0, 2] = cy * sp * cr + sy * sr
    o[i, 1, 0] = sy * cp
    o[i, 1, 1] = sy * sp * sr + cy * cr
    o[i, 1, 2] = sy * sp * cr - cy * sr
    o[i, 2, 0] = -sp
    o[i, 2, 1] = cp * sr
    o[i, 2, 2] = cp * cr


@kernel
def matrix_to_euler_zyx(R, out):
    """(yaw, pitch, roll) rows with pitch ∈ [−π/2, π/2]. Yaw comes from the first column; roll is
    then solved from entries of size O(1) given that yaw (cos and sin of yaw are the normalised
    first column), so the angles reproduce R to rounding even where cos(pitch) is tiny. At gimbal
    lock (cos(pitch) ≤ GIMBAL_EPS) roll is 0 by convention and yaw takes the whole angle."""
    f = R.reshape((-1, 3, 3))
    o = out.reshape((-1, 3))
    for i in range(f.shape[0]):
        if not (_rotation_error_sq(f, i) <= ROT_TOL_SQ):
            raise Rejected(i)
        r00, r10 = f[i, 0, 0], f[i, 1, 0]
        cp = math.hypot(r00, r10)
        o[i, 1] = math.atan2(-f[i, 2, 0], cp)
        if cp <= GIMBAL_EPS:
            o[i, 0] = _atan2(-f[i, 0, 1], f[i, 1, 1])
            o[i, 2] = 0.0
        else:
            cy, sy = r00 / cp, r10 / cp
            o[i, 0] = _atan2(r10, r00)
            o[i, 2] = _atan2(sy * f[i, 0, 2] - cy * f[i, 1, 2], cy * f[i, 1, 1] - sy * f[i, 0, 1])


# ---------------------------------------------------------------- SE(3)


@kernel
def make_transform(R, t, out):
    fr = R.reshape((-1, 3, 3))
    ft = t.reshape((-1, 3))
    o = out.reshape((-1, 4, 4))
    sr = 1 if fr.shape[0] > 1 else 0
    st = 1 if ft.shape[0] > 1 else 0
    for i in range(o.shape[0]):
        ir, it = i * sr, i * st
        if not (_rotation_error_sq(fr, ir) <= ROT_TOL_SQ and _finite_row(ft, it)):
            raise Rejected(i)
        for r in range(3):
            for c in range(3):
                o[i, r, c] = fr[ir, r, c]
            o[i, r, 3] = ft[it, r]
        o[i, 3, 0], o[i, 3, 1], o[i, 3, 2], o[i, 3, 3] = 0.0, 0.0, 0.0, 1.0


@inline_kernel
def _invert_rigid(T, out, d):
    """``[[Rᵀ, −Rᵀt], [0, 1]]`` of each rigid transform in ``T``: (d+1)×(d+1) blocks, d = 3 (3D) or
    2 (planar), each checked first."""
    f = T.reshape((-1, d + 1, d + 1))
    o = out.reshape((-1, d + 1, d + 1))
    for i in range(f.shape[0]):
        if not (_rigid_ok(f, i) if d == 3 else _rigid2_ok(f, i)):
            raise Rejected(i)
        for r in range(d):
            acc = 0.0
            for c in range(d):
                o[i, r, c] = f[i, c, r]
                acc += f[i, c, r] * f[i, c, d]
            o[i, r, d] = -acc
            o[i, d, r] = 0.0
        o[i, d, d] = 1.0


@kernel
def invert_transform(T, out):
    _invert_rigid(T, out, 3)


@inline_kernel
def _renormalize(o, i):
    """Bring the rotation block of ``o[i]``, a product of rotations a few ulp off SO(3), back onto
    it: the first two rows lose half their dot product each along the other (x − e/2·y,
    y − e/2·x), the third is their cross product, and each row is scaled by the first-order
    inverse norm (3 − ‖v‖²)/2. An error ε leaves O(ε²), so long chains of products stay
    orthonormal to rounding (about 40 flops; the DCM renormalisation of Premerlani & Bizard)."""
    x0, x1, x2 = o[i, 0, 0], o[i, 0, 1], o[i, 0, 2]
    y0, y1, y2 = o[i, 1, 0], o[i, 1, 1], o[i, 1, 2]
    e = 0.5 * (x0 * y0 + x1 * y1 + x2 * y2)
    x0, x1, x2, y0, y1, y2 = x0 - e * y0, x1 - e * y1, x2 - e * y2, y0 - e * x0, y1 - e * x1, y2 - e * x2
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    sx = 0.5 * (3.0 - (x0 * x0 + x1 * x1 + x2 * x2))
    sy = 0.5 * (3.0 - (y0 * y0 + y1 * y1 + y2 * y2))
    sz = 0.5 * (3.0 - (z0 * z0 + z1 * z1 + z2 * z2))
    o[i, 0, 0], o[i, 0, 1], o[i, 0, 2] = sx * x0, sx * x1, sx * x2
    o[i, 1, 0], o[i, 1, 1], o[i, 1, 2] = sy * y0, sy * y1, sy * y2
    o[i, 2, 0], o[i, 2, 1], o[i, 2, 2] = sz * z0, sz * z1, sz * z2


@inline_kernel
def _compose(A, B, out, size, renormalize):
    """A @ B for ``size`` × ``size`` blocks: 3×3 rotations, or 4×4 rigid transforms using their
    (0, 0, 0, 1) last rows; the rotation block renormalised (:func:`_renormalize`) on request."""
    fa = A.reshape((-1, size, size))
    fb = B.reshape((-1, size, size))
    o = out.reshape((-1, size, size))
    sa = 1 if fa.shape[0] > 1 else 0
    sb = 1 if fb.shape[0] > 1 else 0
    for i in range(o.shape[0]):
        ia, ib = i * sa, i * sb
        for r in range(3):
            for c in range(size):
                o[i, r, c] = fa[ia, r, 0] * fb[ib, 0, c] + fa[ia, r, 1] * fb[ib, 1, c] + fa[ia, r, 2] * fb[ib, 2, c]
            if size == 4:
                o[i, r, 3] += fa[ia, r, 3]
        if renormalize:
            _renormalize(o, i)
        if size == 4:
            o[i, 3, 0], o[i, 3, 1], o[i, 3, 2], o[i, 3, 3] = 0.0, 0.0, 0.0, 1.0


@kernel
def compose_transforms(A, B, out):
    """A @ B for rigid 4×4 transforms, using their (0, 0, 0, 1) last rows."""
    _compose(A, B, out, 4, False)


@kernel
def compose_rigid(A, B, out):
    """:func:`compose_transforms` with the rotation block renormalised (``SE3 @``)."""
    _compose(A, B, out, 4, True)


@kernel
def compose_rotations(A, B, out):
    """A @ B for 3×3 rotations, renormalised (``SO3 @``)."""
    _compose(A, B, out, 3, True)


@inline_kernel
def _apply_matrices(A, p, out, size):
    """Apply rigid transforms (``size`` 4: 4×4) or rotations (3: 3×3) to points (3); a shared
    matrix is validated once and goes through :func:`_map_points`."""
    fa = A.reshape((-1, size, size))
    fp = p.reshape((-1, 3))
    o = out.reshape((-1, 3))
    if o.shape[0] == 0:
        return
    if fa.shape[0] == 1:
        if not (_rigid_ok(fa, 0) if size == 4 else _rotation_error_sq(fa, 0) <= ROT_TOL_SQ):
            raise Rejected(0)
        M = fa[0]
        if size == 3:  # as a 3×4 map without translation
            M = np.zeros((3, 4))
            M[:, :3] = fa[0]
        _map_points(M, fp, o)
        return
    sp = 1 if fp.shape[0] > 1 else 0
    for i in range(o.shape[0]):
        if not (_rigid_ok(fa, i) if size == 4 else _rotation_error_sq(fa, i) <= ROT_TOL_SQ):
            raise Rejected(i)
        j = i * sp
        x, y, z = fp[j, 0], fp[j, 1], fp[j, 2]
        s = x + y + z
        if not (s - s == 0.0):
            raise Rejected(i)
        for r in range(3):
            o[i, r] = fa[i, r, 0] * x + fa[i, r, 1] * y + fa[i, r, 2] * z
            if size == 4:
                o[i, r] += fa[i, r, 3]


@kernel
def transform_points(T, p, out):
    """Apply rigid transforms (4×4) to points (3), see :func:`_apply_matrices`."""
    _apply_matrices(T, p, out, 4)


@kernel
def rotate_points(R, p, out):
    """Apply rotations (3×3) to points (3), see :func:`_apply_matrices`."""
    _apply_matrices(R, p, out, 3)


@kernel
def _se3_coeffs(theta):
    """(b, c) = ((1 − cos θ)/θ², (θ − sin θ)/θ³), by their series below 0.1 where the quotients
    cancel; the cancellation left above 0.1 is absorbed by the θ² of the φ^² they multiply."""
    t2 = theta * theta
    if theta < 0.1:
        b = 0.5 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0))))
        c = (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0 * (1.0 - t2 / 110.0)))) / 6.0
    else:
        h = math.sin(0.5 * theta)
        b = 2.0 * h * h / t2
        c = (theta - math.sin(theta)) / (t2 * theta)
    return b, c


@kernel
def exp_se3(xi, out):
    """Twist (ρ, φ) (translation part first, as Sophus and Barfoot) to a 4×4 transform:
    R = exp(φ^), t = V ρ with V = I + b φ^ + c φ^²."""
    f = xi.reshape((-1, 6))
    o = out.reshape((-1, 4, 4))
    for i in range(f.shape[0]):
        if not _finite_row(f, i):
            raise Rejected(i)
        rx, ry, rz, x, y, z = f[i, 0], f[i, 1], f[i, 2], f[i, 3], f[i, 4], f[i, 5]
        theta = math.sqrt(x * x + y * y + z * z)
        sh = _sinc_half(theta)
        _quat_to_rot(math.cos(0.5 * theta), x * sh, y * sh, z * sh, o, i)
        b, c = _se3_coeffs(theta)
        # φ × ρ and φ × (φ × ρ)
        c1x, c1y, c1z = y * rz - z * ry, z * rx - x * rz, x * ry - y * rx
        c2x, c2y, c2z = y * c1z - z * c1y, z * c1x - x * c1z, x * c1y - y * c1x
        o[i, 0, 3] = rx + b * c1x + c * c2x
        o[i, 1, 3] = ry + b * c1y + c * c2y
        o[i, 2, 3] = rz + b * c1z + c * c2z
        o[i, 3, 0], o[i, 3, 1], o[i, 3, 2], o[i, 3, 3] = 0.0, 0.0, 0.0, 1.0


@kernel
def log_se3(T, out):
    """Inverse of :func:`exp_se3`: φ = log R, ρ = V⁻¹ t with V⁻¹ = I − ½ φ^ + d φ^²,
    d = (1 − (θ/2) cot(θ/2)) / θ², by its series below 0.1; finite up to and at θ = π."""
    f = T.reshape((-1, 4, 4))
    o = out.reshape((-1, 6))
    q = np.empty((1, 4))
    for i in range(f.shape[0]):
        if not _rigid_ok(f, i):
            raise Rejected(i)
        _rot_to_quat(f, i, q, 0)
        ax, ay, az, theta = _quat_axis_angle(q[0, 0], q[0, 1], q[0, 2], q[0, 3])
        x, y, z = ax * theta, ay * theta, az * theta
        o[i, 3], o[i, 4], o[i, 5] = x, y, z
        t2 = theta * theta
        if theta < 0.1:
            d = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2 * t2 * t2 / 1209600.0
        else:
            h = 0.5 * theta
            d = (1.0 - h * math.cos(h) / math.sin(h)) / t2
        tx, ty, tz = f[i, 0, 3], f[i, 1, 3], f[i, 2, 3]
        c1x, c1y, c1z = y * tz - z * ty, z * tx - x * tz, x * ty - y * tx
        c2x, c2y, c2z = y * c1z - z * c1y, z * c1x - x * c1z, x * c1y - y * c1x
        o[i, 0] = tx - 0.5 * c1x + d * c2x
        o[i, 1] = ty - 0.5 * c1y + d * c2y
        o[i, 2] = tz - 0.5 * c1z + d * c2z


# ---------------------------------------------------------------- SE(2)


@inline_kernel
def _se2_entries(x, y, t, o, i):
    """Write the pose (x, y, t) as a 3×3 homogeneous matrix into ``o[i]``."""
    c, s = math.cos(t), math.sin(t)
    o[i, 0, 0], o[i, 0, 1], o[i, 0, 2] = c, -s, x
    o[i, 1, 0], o[i, 1, 1], o[i, 1, 2] = s, c, y
    o[i, 2, 0], o[i, 2, 1], o[i, 2, 2] = 0.0, 0.0, 1.0


# ---------------------------------------------------------------- 3×3 matrices of three scalars

#: kinds of :func:`matrix_of_three`: Rz(x) Ry(y) Rx(z) (Euler Z-Y-X), and the planar pose (x, y, θ = z)
EULER_ZYX = 0
SE2_POSE = 1


@inline_kernel
def _three_entries(kind, x, y, z, o, i):
    """Write the matrix of ``kind`` into ``o[i]``; False (nothing written) for NaN/inf."""
    s = x + y + z
    if not (s - s == 0.0):
        return False
    if kind == EULER_ZYX:
        _euler_zyx_entries(x, y, z, o, i)
    else:
        _se2_entries(x, y, z, o, i)
    return True


@inline_kernel
def _three_row(operands, o, i):
    kind, x, y, z = operands
    return _three_entries(kind, x[i if x.shape[0] > 1 else 0], y[i if y.shape[0] > 1 else 0],
                          z[i if z.shape[0] > 1 else 0], o, i)


_three_rows = _by_rows(_three_row)


@kernel
def matrix_of_three(kind, x, y, z, out):
    """3×3 matrices of ``kind`` (:data:`EULER_ZYX` or :data:`SE2_POSE`) from three scalar
    operands, 1-D (see :func:`_flat`) with single elements broadcast."""
    _three_rows((kind, _flat(x), _flat(y), _flat(z)), out.reshape((-1, 3, 3)))


@kernel
def euler_zyx_to_matrix_one(yaw, pitch, roll, out):
    """Single-element form of :func:`matrix_of_three` for :data:`EULER_ZYX` (the C single path,
    ``_arrays.entry``): three floats, no row loop."""
    if not _three_entries(EULER_ZYX, yaw, pitch, roll, out.reshape((1, 3, 3)), 0):
        raise Rejected(0)


@kernel
def se2_matrix_one(x, y, theta, out):
    """Single-element form of :func:`matrix_of_three` for :data:`SE2_POSE`."""
    if not _three_entries(SE2_POSE, x, y, theta, out.reshape((1, 3, 3)), 0):
        raise Rejected(0)


@kernel
def se2_from_matrix(T, out):
    f = T.reshape((-1, 3, 3))
    o = out.reshape((-1, 3))
    for i in range(f.shape[0]):
        if not _rigid2_ok(f, i):
            raise Rejected(i)
        o[i, 0] = f[i, 0, 2]
        o[i, 1] = f[i, 1, 2]
        o[i, 2] = _atan2(f[i, 1, 0], f[i, 0, 0])


@kernel
def transform_points2(T, p, out):
    """2D counterpart of :func:`transform_points`: 3×3 transforms, 2-vectors."""
    ft = T.reshape((-1, 3, 3))
    fp = p.reshape((-1, 2))
    o = out.reshape((-1, 2))
    if o.shape[0] == 0:
        return
    st = 1 if ft.shape[0] > 1 else 0
    sp = 1 if fp.shape[0] > 1 else 0
    if st == 0 and not _rigid2_ok(ft, 0):
        raise Rejected(0)
    for i in range(o.shape[0]):
        k = i * st
        if st == 1 and not _rigid2_ok(ft, k):
            raise Rejected(i)
        j = i * sp
        x, y = fp[j, 0], fp[j, 1]
        s = x + y
        if not (s - s == 0.0):
            raise Rejected(i)
        o[i, 0] = ft[k, 0, 0] * x + ft[k, 0, 1] * y + ft[k, 0, 2]
        o[i, 1] = ft[k, 1, 0] * x + ft[k, 1, 1] * y + ft[k, 1, 2]


@kernel
def invert_transform2(T, out):
    _invert_rigid(T, out, 2)

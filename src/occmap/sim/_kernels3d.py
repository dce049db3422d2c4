"""Numba kernels of the 3D simulator: exact ray casting against axis-aligned boxes, vertical
cylinders and a ground plane; the point-in-solid test; and the voxel rasterisation of the truth.

Plain float64 arrays in, arrays out; the caller validates shapes and finiteness and allocates
``out``. Boxes are rows ``[xmin, ymin, zmin, xmax, ymax, zmax]``, cylinders rows
``[cx, cy, r, zmin, zmax]`` (vertical axis), the ground the half-space ``z <= ground_z`` when
``has_ground``. Every solid is closed: a point on a surface is inside.

The per-ray work is written out inline in one serial kernel over a span of rays (a call to a
helper that takes arrays costs ~25 ns inside Numba, as much as testing a box); the parallel kernel
hands out chunks of rays to it, one call per chunk. No fastmath: the hit tests rely on IEEE
comparisons with ±inf.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import inline_kernel, kernel, kernel_parallel


# Rays per task of the parallel kernel, and batches shorter than this many rays run serially.
CHUNK = 512
PARALLEL_MIN = 4096


@inline_kernel
def _slab(near, far, o, d, inv, tn, tf):
    """The ray's parameter interval ``[tn, tf]`` clipped to the slab between the planes ``near``
    and ``far`` of one axis (``near`` the face the ray meets first, ``inv = 1/d``). A ray parallel
    to the axis' planes (``d = 0``) keeps the interval when its origin lies in the slab, else the
    interval becomes empty (``tn = inf > tf = −inf``)."""
    if d != 0.0:
        t1 = (near - o) * inv
        t2 = (far - o) * inv
        return (t1 if t1 > tn else tn), (t2 if t2 < tf else tf)
    if near <= o <= far:
        return tn, tf
    return np.inf, -np.inf


@kernel
def cast_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, start, stop,
              out):
    """``out[i]`` for ``start <= i < stop`` = distance along the unit ray ``origins[k] +
    t·directions[i]`` (t ≥ 0) to the first solid, ``inf`` when none lies within ``max_range``;
    ``k = i`` when ``origins`` has one row per ray, else 0 (one origin for all). A ray that starts
    inside or on a solid reads 0.

    Boxes: the slab test (entry = largest near-slab distance, exit = smallest far-slab distance;
    an axis the ray runs parallel to is either always inside its slab or never). Cylinders: the
    radial quadratic (roots written without cancellation) intersected with the z slab. A tangent
    ray touches the surface and counts as a hit."""
    ostep = 1 if origins.shape[0] > 1 else 0  # one origin per ray, or one for all
    nb = boxes.shape[0]
    nc = cylinders.shape[0]
    for i in range(start, stop):
        k = i * ostep
        ox = origins[k, 0]
        oy = origins[k, 1]
        oz = origins[k, 2]
        dx = directions[i, 0]
        dy = directions[i, 1]
        dz = directions[i, 2]
        ix = 1.0 / dx if dx != 0.0 else 0.0
        iy = 1.0 / dy if dy != 0.0 else 0.0
        iz = 1.0 / dz if dz != 0.0 else 0.0
        best = np.inf
        if has_ground:
            if oz <= ground_z:
                best = 0.0
            elif dz < 0.0:
                best = (ground_z - oz) * iz
        # per ray, the columns of a box row that hold the near and the far face on each axis
        nxc = 0 if dx >= 0.0 else 3
        nyc = 1 if dy >= 0.0 else 4
        nzc = 2 if dz >= 0.0 else 5
        # ---- boxes
        for j in range(nb):
            if best == 0.0:
                break
            tn, tf = _slab(boxes[j, nxc], boxes[j, 3 - nxc], ox, dx, ix, -np.inf, np.inf)
            tn, tf = _slab(boxes[j, nyc], boxes[j, 5 - nyc], oy, dy, iy, tn, tf)
            if tn > tf or tf < 0.0 or tn >= best:
                continue  # early out: most boxes miss in plan view
            tn, tf = _slab(boxes[j, nzc], boxes[j, 7 - nzc], oz, dz, iz, tn, tf)
            if tn > tf or tf < 0.0:
                continue
            tn = tn if tn > 0.0 else 0.0
            best = tn if tn < best else best
        # ---- vertical cylinders
        a = dx * dx + dy * dy
        for j in range(nc):
            if best == 0.0:
                break
            tn = -np.inf
            tf = np.inf
            lo = cylinders[j, 3]
            hi = cylinders[j, 4]
            if dz == 0.0:
                if oz < lo or oz > hi:
                    continue
            else:
                t1 = (lo - oz) * iz
                t2 = (hi - oz) * iz
                tn = t1 if t1 < t2 else t2
                tf = t2 if t1 < t2 else t1
            fx = ox - cylinders[j, 0]
            fy = oy - cylinders[j, 1]
            r = cylinders[j, 2]
            c = fx * fx + fy * fy - r * r
            if a == 0.0:
                if c > 0.0:
                    continue  # a vertical ray outside the disc
            else:
                b = fx * dx + fy * dy
                if c > 0.0 and b >= 0.0:
                    continue  # outside the disc and not closing in on it
                disc = b * b - a * c
                if disc < 0.0:
                    continue
                sq = math.sqrt(disc)
                q = -b - sq if b >= 0.0 else -b + sq
                if q == 0.0:
                    t1 = 0.0  # b = 0 and disc = 0: c = 0, the ray touches at its origin
                    t2 = 0.0
                else:
                    t1 = q / a
                    t2 = c / q
                    if t1 > t2:
                        t1, t2 = t2, t1
                if t1 > tn:
                    tn = t1
                if t2 < tf:
                    tf = t2
            if tn > tf or tf < 0.0:
                continue
            if tn < 0.0:
                tn = 0.0
            if tn < best:
                best = tn
        out[i] = best if best <= max_range else np.inf
    return out


@kernel
def cast_rays(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, out):
    """:func:`cast_span` over all rays, on one core."""
    return cast_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, 0,
                     directions.shape[0], out)


@kernel_parallel
def cast_rays_parallel(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, out):
    """:func:`cast_span` over all rays, in chunks of :data:`CHUNK` rays on all cores."""
    n = directions.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        cast_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range,
                  c * CHUNK, min(n, (c + 1) * CHUNK), out)
    return out


@kernel
def rotate(R, vectors, out):
    """``out[i] = R @ vectors[i]`` for (N, 3) vectors (NumPy's ``vectors @ R.T`` takes a slow
    path on a transposed 3×3)."""
    for i in range(vectors.shape[0]):
        x = vectors[i, 0]
        y = vectors[i, 1]
        z = vectors[i, 2]
        out[i, 0] = R[0, 0] * x + R[0, 1] * y + R[0, 2] * z
        out[i, 1] = R[1, 0] * x + R[1, 1] * y + R[1, 2] * z
        out[i, 2] = R[2, 0] * x + R[2, 1] * y + R[2, 2] * z
    return out


@kernel
def lidar_points(directions, ranges, noise, uniform, dropout, min_range, max_range, out):
    """Write the returned points into ``out`` (N, 3) and return how many there are. Beam i with a
    finite true range is the j-th such beam; it reads ``ranges[i] + noise[j]`` and returns when
    that lies in ``[min_range, max_range]`` and ``uniform[j] >= dropout`` (``noise`` and
    ``uniform`` may be empty when unused: zero noise, no dropout). The point is the reading
    times the unit direction."""
    use_noise = noise.shape[0] > 0
    use_drop = uniform.shape[0] > 0
    j = 0
    n = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if not math.isfinite(r):
            continue
        if use_noise:
            r += noise[j]
        ok = min_range <= r <= max_range
        if use_drop and uniform[j] < dropout:
            ok = False
        j += 1
        if ok:
            out[n, 0] = directions[i, 0] * r
            out[n, 1] = directions[i, 1] * r
            out[n, 2] = directions[i, 2] * r
            n += 1
    return n


@kernel_parallel
def occupied(points, boxes, cylinders, ground_z, has_ground, out):
    """``out[i]`` = whether ``points[i]`` lies inside or on a solid (or on or below the ground)."""
    nb = boxes.shape[0]
    nc = cylinders.shape[0]
    for i in prange(points.shape[0]):
        x = points[i, 0]
        y = points[i, 1]
        z = points[i, 2]
        hit = has_ground and z <= ground_z
        if not hit:
            for j in range(nb):
                if (boxes[j, 0] <= x <= boxes[j, 3] and boxes[j, 1] <= y <= boxes[j, 4]
                        and boxes[j, 2] <= z <= boxes[j, 5]):
                    hit = True
                    break
        if not hit:
            for j in range(nc):
                if cylinders[j, 3] <= z <= cylinders[j, 4]:
                    fx = x - cylinders[j, 0]
                    fy = y - cylinders[j, 1]
                    r = cylinders[j, 2]
                    if fx * fx + fy * fy <= r * r:
                        hit = True
                        break
        out[i] = hit
    return out


@kernel
def _in_voxel_axis(k, lo, hi, res, overlap):
    """Whether voxel ``k`` (global index, spanning ``[k·res, (k+1)·res]``) belongs to the closed
    interval ``[lo, hi]``: its centre ``(k + 0.5)·res`` inside it, or (``overlap``) the voxel's
    closed interval meeting it."""
    if overlap:
        return k * res <= hi and (k + 1) * res >= lo
    c = (k + 0.5) * res
    return lo <= c <= hi


@kernel
def _axis_range(lo, hi, k0, n, res, overlap):
    """The first and last local index ``i`` in ``0..n-1`` whose voxel ``k0 + i`` belongs to
    ``[lo, hi]`` (see :func:`_in_voxel_axis`); ``first > last`` when none. An estimate from
    ``floor`` is widened by two voxels and then trimmed with the exact test."""
    a = int(math.floor(lo / res)) - k0 - 2
    b = int(math.floor(hi / res)) - k0 + 2
    if a < 0:
        a = 0
    if b > n - 1:
        b = n - 1
    while a <= b and not _in_voxel_axis(k0 + a, lo, hi, res, overlap):
        a += 1
    while b >= a and not _in_voxel_axis(k0 + b, lo, hi, res, overlap):
        b -= 1
    return a, b


@kernel
def rasterize(boxes, cylinders, ground_z, has_ground, k0, res, overlap, out):
    """Mark in ``out`` (nx, ny, nz) bool the voxels that belong to a solid. Local voxel
    (i, j, l) is global voxel ``k0 + (i, j, l)`` with centre ``(k0 + (i, j, l) + 0.5)·res``
    (the octree's key-to-coordinate rule). Centre mode: the centre lies in a closed solid.
    ``overlap`` mode: the closed voxel cube meets a closed solid."""
    nx = out.shape[0]
    ny = out.shape[1]
    nz = out.shape[2]
    kx = k0[0]
    ky = k0[1]
    kz = k0[2]
    if has_ground:
        top = -1
        for l in range(nz):
            if _in_voxel_axis(kz + l, -np.inf, ground_z, res, overlap):
                top = l
        for i in range(nx):
            for j in range(ny):
                for l in range(top + 1):
                    out[i, j, l] = True
    for m in range(boxes.shape[0]):
        xa, xb = _axis_range(boxes[m, 0], boxes[m, 3], kx, nx, res, overlap)
        ya, yb = _axis_range(boxes[m, 1], boxes[m, 4], ky, ny, res, overlap)
        za, zb = _axis_range(boxes[m, 2], boxes[m, 5], kz, nz, res, overlap)
        for i in range(xa, xb + 1):
            for j in range(ya, yb + 1):
                for l in range(za, zb + 1):
                    out[i, j, l] = True
    for m in range(cylinders.shape[0]):
        cx = cylinders[m, 0]
        cy = cylinders[m, 1]
        r = cylinders[m, 2]
        xa, xb = _axis_range(cx - r, cx + r, kx, nx, res, overlap)
        ya, yb = _axis_range(cy - r, cy + r, ky, ny, res, overlap)
        za, zb = _axis_range(cylinders[m, 3], cylinders[m, 4], kz, nz, res, overlap)
        for i in range(xa, xb + 1):
            if overlap:  # the nearest point of the voxel's square to the axis
                fx = min(max(cx, (kx + i) * res), (kx + i + 1) * res) - cx
            else:
                fx = (kx + i + 0.5) * res - cx
            for j in range(ya, yb + 1):
                if overlap:
                    fy = min(max(cy, (ky + j) * res), (ky + j + 1) * res) - cy
                else:
                    fy = (ky + j + 0.5) * res - cy
                if fx * fx + fy * fy <= r * r:
                    for l in range(za, zb + 1):
                        out[i, j, l] = True
    return out

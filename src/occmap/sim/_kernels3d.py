"""Numba kernels of the 3D simulator: exact ray casting against axis-aligned boxes, vertical
cylinders and a ground plane, over all solids or through a 2D grid of them; the point-in-solid
test; and the voxel rasterisation of the truth.

Plain float64 arrays in, arrays out; the caller validates shapes and finiteness and allocates
``out``. Boxes are rows ``[xmin, ymin, zmin, xmax, ymax, zmax]``, cylinders rows
``[cx, cy, r, zmin, zmax]`` (vertical axis), the ground the half-space ``z <= ground_z`` when
``has_ground``. Every solid is closed: a point on a surface is inside.

The per-ray work runs in one serial kernel over a span of rays, its helpers inlined (a call to a
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


@inline_kernel
def _box_entry(boxes, j, nxc, nyc, nzc, ox, oy, oz, dx, dy, dz, ix, iy, iz, best):
    """``best`` lowered to where the ray enters box ``j``, if it does so nearer (0 when it starts
    inside or on it): the slab test, entry = largest near-slab distance, exit = smallest far-slab
    distance; an axis the ray runs parallel to is either always inside its slab or never.
    ``nxc``, ``nyc``, ``nzc`` are the columns of the near face on each axis (0–2 for a positive
    direction, 3–5 for a negative one)."""
    tn, tf = _slab(boxes[j, nxc], boxes[j, 3 - nxc], ox, dx, ix, -np.inf, np.inf)
    tn, tf = _slab(boxes[j, nyc], boxes[j, 5 - nyc], oy, dy, iy, tn, tf)
    if tn > tf or tf < 0.0 or tn >= best:
        return best  # early out: most boxes miss in plan view
    tn, tf = _slab(boxes[j, nzc], boxes[j, 7 - nzc], oz, dz, iz, tn, tf)
    if tn > tf or tf < 0.0:
        return best
    tn = tn if tn > 0.0 else 0.0
    return tn if tn < best else best


@inline_kernel
def _cylinder_entry(cylinders, j, ox, oy, oz, dx, dy, dz, iz, a, best):
    """``best`` lowered to where the ray enters vertical cylinder ``j``, if it does so nearer (0
    when it starts inside or on it): the radial quadratic (``a = dx² + dy²``, roots written
    without cancellation) intersected with the z slab. A tangent ray touches the surface and
    counts as a hit."""
    tn = -np.inf
    tf = np.inf
    lo = cylinders[j, 3]
    hi = cylinders[j, 4]
    if dz == 0.0:
        if oz < lo or oz > hi:
            return best
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
            return best  # a vertical ray outside the disc
    else:
        b = fx * dx + fy * dy
        if c > 0.0 and b >= 0.0:
            return best  # outside the disc and not closing in on it
        disc = b * b - a * c
        if disc < 0.0:
            return best
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
        return best
    if tn < 0.0:
        tn = 0.0
    return tn if tn < best else best


@inline_kernel
def _ray(origins, directions, i, ostep):
    """Ray ``i``: its origin (row ``i·ostep``: one per ray, or one for all), its direction and the
    direction's reciprocals (0 for a zero component)."""
    k = i * ostep
    dx = directions[i, 0]
    dy = directions[i, 1]
    dz = directions[i, 2]
    return (origins[k, 0], origins[k, 1], origins[k, 2], dx, dy, dz,
            1.0 / dx if dx != 0.0 else 0.0, 1.0 / dy if dy != 0.0 else 0.0,
            1.0 / dz if dz != 0.0 else 0.0)


@inline_kernel
def _near_columns(dx, dy, dz):
    """The columns of a box row that hold the face a ray of this direction meets first, per axis."""
    return 0 if dx >= 0.0 else 3, 1 if dy >= 0.0 else 4, 2 if dz >= 0.0 else 5


@inline_kernel
def _ground_entry(oz, dz, iz, ground_z, has_ground):
    """Where the ray meets the ground half-space (0 when it starts on or below it), else inf."""
    if has_ground:
        if oz <= ground_z:
            return 0.0
        if dz < 0.0:
            return (ground_z - oz) * iz
    return np.inf


@kernel
def cast_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, start, stop,
              out):
    """``out[i]`` for ``start <= i < stop`` = distance along the unit ray ``origins[k] +
    t·directions[i]`` (t ≥ 0) to the first solid, ``inf`` when none lies within ``max_range``;
    ``k = i`` when ``origins`` has one row per ray, else 0 (one origin for all). A ray that starts
    inside or on a solid reads 0. Every box and cylinder is tested (:func:`_box_entry`,
    :func:`_cylinder_entry`); :func:`cast_grid_span` tests only those along the ray."""
    ostep = 1 if origins.shape[0] > 1 else 0  # one origin per ray, or one for all
    nb = boxes.shape[0]
    nc = cylinders.shape[0]
    for i in range(start, stop):
        ox, oy, oz, dx, dy, dz, ix, iy, iz = _ray(origins, directions, i, ostep)
        nxc, nyc, nzc = _near_columns(dx, dy, dz)
        best = _ground_entry(oz, dz, iz, ground_z, has_ground)
        for j in range(nb):
            if best == 0.0:
                break
            best = _box_entry(boxes, j, nxc, nyc, nzc, ox, oy, oz, dx, dy, dz, ix, iy, iz, best)
        a = dx * dx + dy * dy
        for j in range(nc):
            if best == 0.0:
                break
            best = _cylinder_entry(cylinders, j, ox, oy, oz, dx, dy, dz, iz, a, best)
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


@inline_kernel
def _in_box(boxes, j, x, y, z):
    """Whether the point lies inside or on box ``j``."""
    return (boxes[j, 0] <= x <= boxes[j, 3] and boxes[j, 1] <= y <= boxes[j, 4]
            and boxes[j, 2] <= z <= boxes[j, 5])


@inline_kernel
def _in_cylinder(cylinders, j, x, y, z):
    """Whether the point lies inside or on vertical cylinder ``j``."""
    if not cylinders[j, 3] <= z <= cylinders[j, 4]:
        return False
    fx = x - cylinders[j, 0]
    fy = y - cylinders[j, 1]
    r = cylinders[j, 2]
    return fx * fx + fy * fy <= r * r


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
        for j in range(nb):
            if hit:
                break
            hit = _in_box(boxes, j, x, y, z)
        for j in range(nc):
            if hit:
                break
            hit = _in_cylinder(cylinders, j, x, y, z)
        out[i] = hit
    return out


# ------------------------------------------------------------------ the solids on a 2D grid
#
# A world of thousands of solids is cast against through a uniform grid over the xy plane: cell
# (cx, cy) spans [x0 + cx·cell, x0 + (cx+1)·cell] × [y0 + cy·cell, y0 + (cy+1)·cell] and lists
# (CSR: ``start[c] .. start[c+1]`` into ``items``, c = cy·nx + cx) every solid whose footprint,
# grown by a margin, meets it. A ray visits the cells its xy shadow crosses, nearest first
# (Amanatides–Woo), testing only their solids, and stops once its nearest hit lies before the cell's
# far edge. The result is the very value :func:`cast_span` gives over all solids (the same tests,
# the same minimum): a solid hit at t lies under the ray's shadow at t, and the margin (far above
# the rounding of the walk, ~1e-12 m) puts it into every cell the walk may assign that stretch of
# the shadow to, also where the shadow grazes a cell corner or an edge.


@kernel
def bin_rects(rects, x0, y0, cell, nx, ny):
    """The CSR lists ``(start (nx·ny + 1,), items)`` of the grid cells (see above) that each
    rectangle ``[xmin, ymin, xmax, ymax]`` of ``rects`` (N, 4) meets; ``items`` holds rectangle
    indices, ascending within a cell. Cell indices are clipped to the grid."""
    n = rects.shape[0]
    lo = np.empty((n, 2), dtype=np.int64)
    hi = np.empty((n, 2), dtype=np.int64)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for k in range(n):
        lo[k, 0] = min(max(int(math.floor((rects[k, 0] - x0) / cell)), 0), nx - 1)
        lo[k, 1] = min(max(int(math.floor((rects[k, 1] - y0) / cell)), 0), ny - 1)
        hi[k, 0] = min(max(int(math.floor((rects[k, 2] - x0) / cell)), 0), nx - 1)
        hi[k, 1] = min(max(int(math.floor((rects[k, 3] - y0) / cell)), 0), ny - 1)
        for cy in range(lo[k, 1], hi[k, 1] + 1):
            for cx in range(lo[k, 0], hi[k, 0] + 1):
                start[cy * nx + cx + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(start[nx * ny], dtype=np.int64)
    for k in range(n):
        for cy in range(lo[k, 1], hi[k, 1] + 1):
            for cx in range(lo[k, 0], hi[k, 0] + 1):
                c = cy * nx + cx
                items[fill[c]] = k
                fill[c] += 1
    return start, items


@inline_kernel
def _edge_time(x0, cell, c, step, o, inv):
    """The ray parameter at which it leaves grid column (or row) ``c`` moving by ``step`` (±1),
    inf when it runs parallel to the columns (``step`` 0)."""
    if step == 0:
        return np.inf
    return (x0 + (c + 1 if step > 0 else c) * cell - o) * inv


@kernel
def cast_grid_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, x0, y0,
                   cell, nx, ny, box_start, box_items, cyl_start, cyl_items, start, stop, out):
    """:func:`cast_span` for rays ``start .. stop``, testing only the solids of the grid cells
    (see above) along each ray, up to the first hit, ``max_range`` or the grid's edge."""
    ostep = 1 if origins.shape[0] > 1 else 0
    x1 = x0 + nx * cell
    y1 = y0 + ny * cell
    for i in range(start, stop):
        ox, oy, oz, dx, dy, dz, ix, iy, iz = _ray(origins, directions, i, ostep)
        nxc, nyc, nzc = _near_columns(dx, dy, dz)
        best = _ground_entry(oz, dz, iz, ground_z, has_ground)
        a = dx * dx + dy * dy
        # the stretch [tn, tf] of the ray over the grid and within max_range
        tn, tf = _slab(x0 if dx >= 0.0 else x1, x1 if dx >= 0.0 else x0, ox, dx, ix, 0.0, max_range)
        tn, tf = _slab(y0 if dy >= 0.0 else y1, y1 if dy >= 0.0 else y0, oy, dy, iy, tn, tf)
        if tn <= tf and best > 0.0:
            cx = min(max(int(math.floor((ox + tn * dx - x0) / cell)), 0), nx - 1)
            cy = min(max(int(math.floor((oy + tn * dy - y0) / cell)), 0), ny - 1)
            sx = 0 if dx == 0.0 else (1 if dx > 0.0 else -1)
            sy = 0 if dy == 0.0 else (1 if dy > 0.0 else -1)
            tx = _edge_time(x0, cell, cx, sx, ox, ix)
            ty = _edge_time(y0, cell, cy, sy, oy, iy)
            while True:
                c = cy * nx + cx
                for m in range(box_start[c], box_start[c + 1]):
                    if best == 0.0:
                        break
                    best = _box_entry(boxes, box_items[m], nxc, nyc, nzc, ox, oy, oz, dx, dy, dz,
                                      ix, iy, iz, best)
                for m in range(cyl_start[c], cyl_start[c + 1]):
                    if best == 0.0:
                        break
                    best = _cylinder_entry(cylinders, cyl_items[m], ox, oy, oz, dx, dy, dz, iz, a,
                                           best)
                t_exit = tx if tx < ty else ty
                if best <= t_exit or t_exit >= tf:
                    break
                if tx < ty:
                    cx += sx
                    if cx < 0 or cx >= nx:
                        break
                    tx = _edge_time(x0, cell, cx, sx, ox, ix)
                else:
                    cy += sy
                    if cy < 0 or cy >= ny:
                        break
                    ty = _edge_time(y0, cell, cy, sy, oy, iy)
        out[i] = best if best <= max_range else np.inf
    return out


@kernel
def cast_grid_rays(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, x0, y0,
                   cell, nx, ny, box_start, box_items, cyl_start, cyl_items, out):
    """:func:`cast_grid_span` over all rays, on one core."""
    return cast_grid_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range,
                          x0, y0, cell, nx, ny, box_start, box_items, cyl_start, cyl_items, 0,
                          directions.shape[0], out)


@kernel_parallel
def cast_grid_rays_parallel(origins, directions, boxes, cylinders, ground_z, has_ground, max_range,
                            x0, y0, cell, nx, ny, box_start, box_items, cyl_start, cyl_items, out):
    """:func:`cast_grid_span` over all rays, in chunks of :data:`CHUNK` rays on all cores."""
    n = directions.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        cast_grid_span(origins, directions, boxes, cylinders, ground_z, has_ground, max_range, x0,
                       y0, cell, nx, ny, box_start, box_items, cyl_start, cyl_items, c * CHUNK,
                       min(n, (c + 1) * CHUNK), out)
    return out


@kernel_parallel
def occupied_grid(points, boxes, cylinders, ground_z, has_ground, x0, y0, cell, nx, ny, box_start,
                  box_items, cyl_start, cyl_items, out):
    """:func:`occupied`, testing only the solids listed in the grid cell (see above) of each
    point; a point off the grid is inside no solid."""
    for i in prange(points.shape[0]):
        x = points[i, 0]
        y = points[i, 1]
        z = points[i, 2]
        hit = has_ground and z <= ground_z
        fx = math.floor((x - x0) / cell)
        fy = math.floor((y - y0) / cell)
        if not hit and 0.0 <= fx < nx and 0.0 <= fy < ny:
            c = int(fy) * nx + int(fx)
            for m in range(box_start[c], box_start[c + 1]):
                if hit:
                    break
                hit = _in_box(boxes, box_items[m], x, y, z)
            for m in range(cyl_start[c], cyl_start[c + 1]):
                if hit:
                    break
                hit = _in_cylinder(cylinders, cyl_items[m], x, y, z)
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

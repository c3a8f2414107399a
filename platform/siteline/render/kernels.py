"""Compiled loops of the coverage and depth probes on the CPU: one pass over the points marks their
disks, where a chain of torch calls would make a dozen passes over 100k-point arrays per probe (view
generation runs about a thousand probes a pair). The projection and the disk diameters come from the
renderer (siteline.render.zbuffer), so these give exactly what its render would cover."""

from __future__ import annotations

import numpy as np

from siteline.pointpass import kernel


@kernel
def mark_disks(
    ui: np.ndarray,
    vi: np.ndarray,
    diameters: np.ndarray,
    kept: np.ndarray,
    hit: np.ndarray,
    hit_kept: np.ndarray,
) -> None:
    """Mark in ``hit`` (H, W) bool every pixel the disk of each point covers (diameter ``diameters``
    px, centred on pixel (``ui``, ``vi``), int64; points off the image mark nothing), and in
    ``hit_kept`` those of points where ``kept``. A disk of diameter d covers the pixels whose centres
    lie within d / 2 of its own (siteline.render.splats.disk_offsets)."""
    h, w = hit.shape
    for i in range(len(ui)):
        d = diameters[i]
        k = d // 2
        r2 = (d / 2.0) ** 2
        u0, v0 = ui[i], vi[i]
        if u0 + k < 0 or u0 - k >= w or v0 + k < 0 or v0 - k >= h:
            continue
        for dv in range(-k, k + 1):
            v = v0 + dv
            if v < 0 or v >= h:
                continue
            for du in range(-k, k + 1):
                u = u0 + du
                if u < 0 or u >= w or du * du + dv * dv > r2:
                    continue
                hit[v, u] = True
                if kept[i]:
                    hit_kept[v, u] = True


@kernel
def nearest_depths(ui: np.ndarray, vi: np.ndarray, z: np.ndarray, box: np.ndarray, out: np.ndarray) -> None:
    """Per pixel of the window ``box`` (x0, y0, x1, y1: columns x0..x1-1, rows y0..y1-1) the depth of
    the nearest point that falls in it (one-pixel points), written into ``out`` (y1 - y0, x1 - x0)
    float32, which starts at inf."""
    x0, y0, x1, y1 = box[0], box[1], box[2], box[3]
    for i in range(len(ui)):
        u, v = ui[i], vi[i]
        if x0 <= u < x1 and y0 <= v < y1 and z[i] < out[v - y0, u - x0]:
            out[v - y0, u - x0] = z[i]


@kernel
def splat_nearest(
    ui: np.ndarray,
    vi: np.ndarray,
    z: np.ndarray,
    diameters: np.ndarray,
    rise: np.ndarray,
    index: np.ndarray,
    zbuf: np.ndarray,
    width: int,
) -> None:
    """Keep in ``zbuf`` ((H W + 1,) int64 keys, the last slot unused here) per pixel the smallest key
    (float32 depth bits << 32 | point ``index``) of the disks that cover it: each point's disk of
    ``diameters`` px centred on pixel (``ui``, ``vi``), its depth ``z`` (float32, metres, > 0) plus
    ``rise`` x the pixel's squared distance from the centre (world splats' paraboloid; 0 for fixed
    disks). The minimum does not depend on the order of the points: the result is the one a
    ``scatter_reduce`` of the same keys gives, on any device."""
    height = (len(zbuf) - 1) // width
    scratch = np.empty(1, np.float32)
    bits = scratch.view(np.int32)
    for i in range(len(ui)):
        d = diameters[i]
        k = d // 2
        r2 = (d / 2.0) ** 2
        u0, v0 = ui[i], vi[i]
        if u0 + k < 0 or u0 - k >= width or v0 + k < 0 or v0 - k >= height:
            continue
        low = np.int64(index[i])
        for dv in range(-k, k + 1):
            v = v0 + dv
            if v < 0 or v >= height:
                continue
            for du in range(-k, k + 1):
                u = u0 + du
                q = du * du + dv * dv
                if u < 0 or u >= width or q > r2:
                    continue
                scratch[0] = z[i] + rise[i] * np.float32(q)
                key = (np.int64(bits[0]) << 32) | low
                pix = v * width + u
                if key < zbuf[pix]:
                    zbuf[pix] = key


@kernel
def square_nearest(z: np.ndarray, hit: np.ndarray, radius: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of (H W,) depths ``z`` (inf where ``hit`` is False): the nearest depth and whether any
    pixel is hit in the (2 ``radius`` + 1) square around it (rows, then columns)."""
    n = len(z)
    height = n // width
    rows_min = np.empty(n, np.float32)
    rows_any = np.zeros(n, np.bool_)
    for y in range(height):
        for x in range(width):
            m = np.float32(np.inf)
            a = False
            for dx in range(max(0, x - radius), min(width, x + radius + 1)):
                m = min(m, z[y * width + dx])
                a = a or hit[y * width + dx]
            rows_min[y * width + x], rows_any[y * width + x] = m, a
    near = np.empty(n, np.float32)
    around = np.zeros(n, np.bool_)
    for y in range(height):
        for x in range(width):
            m = np.float32(np.inf)
            a = False
            for dy in range(max(0, y - radius), min(height, y + radius + 1)):
                m = min(m, rows_min[dy * width + x])
                a = a or rows_any[dy * width + x]
            near[y * width + x], around[y * width + x] = m, a
    return near, around


@kernel
def fill_gaps(
    index: np.ndarray,
    depth: np.ndarray,
    ring: np.ndarray,
    enclosed: np.ndarray,
    same_surface: np.float32,
    radius: int,
    width: int,
) -> np.ndarray:
    """The gap fill of siteline.render.fill, in one pass (see there): ``index`` (H W,) int64 winning
    point per pixel (-1 none) and ``depth`` (H W,) float32 are changed in place; returns the (H W,)
    bool pixels filled. ring: (M, 4) int64 rows (du, dv, squared distance, sector) of the offsets
    within ``radius`` but the centre; enclosed: (256,) bool per set of occupied sectors."""
    n = len(index)
    height = n // width
    hit = index >= 0
    z = np.where(hit, depth, np.float32(np.inf)).astype(np.float32)
    near, around = square_nearest(z, hit, radius, width)
    out_index, out_depth = index.copy(), depth.copy()  # a fill reads the points drawn, never a filled one
    filled = np.zeros(n, np.bool_)
    widen = np.float32(1.0) + same_surface
    for p in range(n):
        if not ((not hit[p] and around[p]) or (hit[p] and z[p] > near[p] * widen)):
            continue
        x, y = p % width, p // width
        front = np.float32(np.inf)
        for k in range(len(ring)):
            u, v = x + ring[k, 0], y + ring[k, 1]
            if 0 <= u < width and 0 <= v < height:
                front = min(front, z[v * width + u])
        limit = front * widen
        bits, best, best_key = 0, -1, np.int64(0)
        for k in range(len(ring)):
            u, v = x + ring[k, 0], y + ring[k, 1]
            if 0 <= u < width and 0 <= v < height and z[v * width + u] <= limit:
                q = v * width + u
                bits |= 1 << ring[k, 3]
                key = (ring[k, 2] << 32) | q
                if best < 0 or key < best_key:
                    best, best_key = q, key
        if enclosed[bits] and ((not hit[p]) or z[p] > limit) and best >= 0:
            out_index[p], out_depth[p], filled[p] = index[best], depth[best], True
    index[:] = out_index
    depth[:] = out_depth
    return filled


@kernel
def _on_a_line(bits: int, nearest: np.ndarray, keep2: float) -> bool:
    """Whether the pixel lies within sqrt(``keep2``) pixels of the segment joining the nearest samples
    of two opposite sectors held in ``bits`` (``nearest``: (8, 2) their offsets from the pixel's
    centre): between two samples of a line, a pole's or a beam's."""
    for k in range(4):
        if not (bits >> k & 1 and bits >> (k + 4) & 1):
            continue
        ax, ay = nearest[k, 0], nearest[k, 1]
        bx, by = nearest[k + 4, 0], nearest[k + 4, 1]
        ex, ey = bx - ax, by - ay
        t = min(max(-(ax * ex + ay * ey) / max(ex * ex + ey * ey, np.float32(1e-12)), 0.0), 1.0)
        px, py = ax + t * ex, ay + t * ey
        if px * px + py * py <= keep2:
            return True
    return False


@kernel
def trim_edges(
    index: np.ndarray,
    drawn: np.ndarray,
    centre_index: np.ndarray,
    centre: np.ndarray,
    ring: np.ndarray,
    enclosed: np.ndarray,
    knobs: np.ndarray,
    width: int,
) -> np.ndarray:
    """The edge trim of siteline.render.edges, in one pass (see there): ``index`` (H W,) int64 winning
    point per pixel (-1 none) and ``drawn`` (2, H W) float32, the winner's depth (metres; changed in
    place with ``index``) and its spacing in pixels; returns the (H W,) bool pixels trimmed.
    centre_index: (H W,) int64 the nearest point whose own pixel this is (-1 none); centre: (3, H W)
    float32 its depth (inf none) and where in the pixel it falls (u, v: 0 to 1 from the pixel's
    corner); ring: (M, 4) int64 rows (du, dv, squared distance, sector) sorted by distance; enclosed:
    (256,) bool per set of occupied sectors that encloses a pixel (one that lies on a line between
    two opposite sectors' nearest samples is kept too: :func:`_on_a_line`); knobs: (3,) float32
    TRIM_SAME_SPACINGS over the focal length (pixels), KEEP_SPACINGS, REACH_SPACINGS."""
    n = len(index)
    height = n // width
    depth, spacing_px = drawn[0], drawn[1]
    centre_depth, centre_u, centre_v = centre[0], centre[1], centre[2]
    out_index, out_depth = index.copy(), depth.copy()
    trimmed = np.zeros(n, np.bool_)
    same, keep_spacings, reach_spacings = knobs[0], knobs[1], knobs[2]
    half = np.float32(0.5)
    nearest = np.zeros((8, 2), np.float32)  # per sector, the offset of its nearest sample
    for p in range(n):
        if index[p] < 0:
            continue
        s = spacing_px[p]
        limit = depth[p] * (np.float32(1.0) + same * s)  # depth + TRIM_SAME_SPACINGS x spacing in metres
        keep2 = (keep_spacings * s) ** 2
        reach2 = (reach_spacings * s) ** 2
        if centre_depth[p] <= limit:
            du, dv = centre_u[p] - half, centre_v[p] - half
            if du * du + dv * dv <= keep2:
                continue
        x, y = p % width, p // width
        bits, far, keep = 0, -1, False
        for k in range(len(ring)):
            if ring[k, 2] > reach2 + 2:
                break
            u, v = x + ring[k, 0], y + ring[k, 1]
            if u < 0 or u >= width or v < 0 or v >= height:
                continue
            q = v * width + u
            c = centre_depth[q]
            if c <= limit:
                du, dv = ring[k, 0] + centre_u[q] - half, ring[k, 1] + centre_v[q] - half
                if du * du + dv * dv <= keep2:
                    keep = True
                    break
                if ring[k, 2] <= reach2:
                    sector = ring[k, 3]
                    if not bits >> sector & 1:
                        nearest[sector, 0], nearest[sector, 1] = du, dv
                    bits |= 1 << sector
                    if enclosed[bits]:
                        keep = True
                        break
            elif far < 0 and c < np.inf and ring[k, 2] <= reach2:
                far = q
        if not keep and far >= 0 and not _on_a_line(bits, nearest, keep2):
            out_index[p], out_depth[p], trimmed[p] = centre_index[far], centre_depth[far], True
    index[:] = out_index
    drawn[0] = out_depth
    return trimmed


@kernel
def see_through(
    index: np.ndarray,
    depth: np.ndarray,
    centre_index: np.ndarray,
    centre: np.ndarray,
    ring: np.ndarray,
    enclosed: np.ndarray,
    knobs: np.ndarray,
    width: int,
) -> np.ndarray:
    """The holes of siteline.render.edges.see_through, in one pass (see there): per pixel of (H W,)
    ``index`` (winning point, -1 none) and ``depth`` (its depth, metres), the nearer point whose
    surface its winner shows through, -1 elsewhere. centre_index: (H W,) the point drawn as a
    one-pixel centre there (-1 none); centre: (2, H W) float32 its depth (inf none) and spacing in
    pixels;
    ring: (M, 4) int64 rows (du, dv, squared distance, sector) sorted by distance, as far as any
    reach; enclosed: (256,) bool per set of occupied sectors; knobs: (2,) float32 SAME_SURFACE and
    REACH_SPACINGS."""
    n = len(index)
    height = n // width
    centre_depth, centre_spacing_px = centre[0], centre[1]
    widen = np.float32(1.0) + knobs[0]
    reach_spacings = knobs[1]
    radius = 0
    for k in range(len(ring)):
        radius = max(radius, abs(ring[k, 0]), abs(ring[k, 1]))
    near, _ = square_nearest(centre_depth, centre_depth < np.inf, radius, width)
    # the widest reach of any centre around a pixel bounds how far its scan goes: a dense surface's
    # holes are looked for within a few pixels, a sparse one's as far as its spacing reaches
    widest, _ = square_nearest(-centre_spacing_px, centre_depth < np.inf, radius, width)
    out = np.full(n, -1, np.int64)
    for p in range(n):
        if index[p] < 0 or not near[p] * widen < depth[p]:
            continue
        x, y = p % width, p // width
        bound2 = (reach_spacings * -widest[p]) ** 2
        first, front, reach2, bits = -1, np.float32(np.inf), np.float32(0.0), 0
        for k in range(len(ring)):
            if ring[k, 2] > bound2 or (first >= 0 and ring[k, 2] > reach2):
                break
            u, v = x + ring[k, 0], y + ring[k, 1]
            if u < 0 or u >= width or v < 0 or v >= height:
                continue
            q = v * width + u
            c = centre_depth[q]
            if not c * widen < depth[p]:  # not nearer than the winner
                continue
            if first < 0:
                first, front = q, c
                reach2 = (reach_spacings * centre_spacing_px[q]) ** 2
                if ring[k, 2] > reach2:
                    break
            if c <= front * widen:
                bits |= 1 << ring[k, 3]
                if enclosed[bits]:
                    out[p] = centre_index[first]
                    break
    return out


@kernel
def cell_counts(xyz: np.ndarray, level: np.ndarray, which: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """The points in the cell of each point ``which`` ((M,) int64 positions) names
    (siteline.render.splats.surface_spacing), exactly where under ``cap`` ((M,) int64), else some
    count of at least ``cap``. xyz: (N, 3) float32 site-local metres; level: (N,) int64, each point's
    cell is two half cells of 2**level metres, in two grids one half cell apart; returns (M,) int64
    the larger of the point's two cells' counts. Per grid, the named points are counted among
    themselves first (a cell they fill to ``cap`` is full whatever the rest); only the cells left
    under it are then counted over every point, behind a 64 kB filter of those cells: a pair's changed
    points are often a quarter of a view's, the sparse cells among them a few per cent. Where most
    points are named (a pair's labelled ones) every point's cell is counted once instead (its count
    is then exact above ``cap`` too: :func:`_count_keys`). Every table numbers each cell once
    (:func:`_key_ids`)."""
    n = which.shape[0]
    best = np.zeros(n, np.int64)
    if 2 * n > xyz.shape[0]:  # most points named (a pair's labelled ones): one count over them all
        for shift in (0, 1):
            every = np.empty(xyz.shape[0], np.uint64)
            for p in range(xyz.shape[0]):
                every[p] = _cell_key(xyz, level, p, shift)
            count = _count_keys(every)
            for j in range(n):
                best[j] = max(best[j], count[which[j]])
        return best
    for shift in (0, 1):
        keys = np.empty(n, np.uint64)
        for j in range(n):
            keys[j] = _cell_key(xyz, level, which[j], shift)
        named = _count_keys(keys)
        left = np.flatnonzero(named < cap)
        seen = np.zeros(1 << 16, np.bool_)  # a 64 kB filter: most points' cells hold no cell left
        for m in range(len(left)):
            seen[(keys[left[m]] * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(48)] = True
        ids, table, table_ids = _key_ids(keys[left])
        mask = len(table) - 1
        count = np.zeros(len(left), np.int64)  # per cell id (fewer than the keys)
        for p in range(xyz.shape[0]):
            k = _cell_key(xyz, level, p, shift)
            if not seen[(k * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(48)]:
                continue
            i = _slot(k, mask)
            while table[i] != 0:
                if table[i] == k:
                    count[table_ids[i]] += 1
                    break
                i = (i + 1) & mask
        for j in range(n):
            best[j] = max(best[j], named[j])
        for m in range(len(left)):
            best[left[m]] = max(best[left[m]], count[ids[m]])
    return best


@kernel
def _count_keys(keys: np.ndarray) -> np.ndarray:
    """(M,) int64: for each of ``keys``, how many of them equal it."""
    ids = _key_ids(keys)[0]
    count = np.zeros(len(keys), np.int64)
    for j in range(len(keys)):
        count[ids[j]] += 1
    out = np.empty(len(keys), np.int64)
    for j in range(len(keys)):
        out[j] = count[ids[j]]
    return out


@kernel
def _key_ids(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each of ``keys`` (nonzero uint64) numbered by its distinct value, in order of first sight:
    (M,) int64 ids; and the open-addressing table of the distinct values, (S,) uint64 keys (0: empty)
    and (S,) int64 their ids, S a power of two at least twice their number. The table grows with the
    distinct values, not with the keys, so it stays small (and in the cache) where they repeat."""
    size = 1024
    table = np.zeros(size, np.uint64)
    table_ids = np.zeros(size, np.int64)
    out = np.empty(len(keys), np.int64)
    n = 0
    for j in range(len(keys)):
        k = keys[j]
        mask = size - 1
        i = _slot(k, mask)
        while table[i] != 0 and table[i] != k:
            i = (i + 1) & mask
        if table[i] == 0:
            if 2 * (n + 1) > size:  # twice the slots, and this key's slot found again there
                size *= 2
                table, table_ids = _rehashed(table, table_ids, size)
                mask = size - 1
                i = _slot(k, mask)
                while table[i] != 0:
                    i = (i + 1) & mask
            table[i] = k
            table_ids[i] = n
            n += 1
        out[j] = table_ids[i]
    return out, table, table_ids


@kernel
def _rehashed(table: np.ndarray, table_ids: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The keys (0: empty) and ids of an open-addressing table put into a new one of ``size`` slots."""
    keys = np.zeros(size, np.uint64)
    ids = np.zeros(size, np.int64)
    mask = size - 1
    for s in range(len(table)):
        if table[s] != 0:
            i = _slot(table[s], mask)
            while keys[i] != 0:
                i = (i + 1) & mask
            keys[i] = table[s]
            ids[i] = table_ids[s]
    return keys, ids


@kernel
def _cell_key(xyz: np.ndarray, level: np.ndarray, p: int, shift: int) -> np.uint64:
    """Point ``p``'s cell of two half cells (2**level[p] metres each), in the grid shifted by
    ``shift`` half cells, as a nonzero key: 21 bits of each horizontal cell index, 16 of the vertical
    (their two's complement: a key tells apart cells within 2**20 and 2**15 cells of the origin), 6 of
    the level. (The vertical index once took 21 bits, the level's among them: below the origin the
    cells of every level shared keys.)"""
    scale = np.float32(np.ldexp(1.0, -level[p]))
    a = (np.int64(np.floor(xyz[p, 0] * scale)) + shift) >> 1
    b = (np.int64(np.floor(xyz[p, 1] * scale)) + shift) >> 1
    c = (np.int64(np.floor(xyz[p, 2] * scale)) + shift) >> 1
    key = (a & 0x1FFFFF) | ((b & 0x1FFFFF) << 21) | ((c & 0xFFFF) << 42) | ((level[p] & 0x3F) << 58)
    return np.uint64(key) + np.uint64(1)


@kernel
def _slot(key: np.uint64, mask: int) -> np.int64:
    """A key's first slot in a table of ``mask + 1`` (splitmix64's finaliser, low bits)."""
    h = key ^ (key >> np.uint64(30))
    h = h * np.uint64(0xBF58476D1CE4E5B9)
    h = h ^ (h >> np.uint64(27))
    h = h * np.uint64(0x94D049BB133111EB)
    h = h ^ (h >> np.uint64(31))
    return np.int64(h & np.uint64(mask))

"""Masks M_k and Delta_ki (MODEL.md eq. 12, 11), built per pixel into depth-sorted lists.

Scanning every silhouette costs the sum of the silhouette areas (tens of millions of pixel
tests for a 0.1 m grid) per frame. Instead, each pixel asks only the locations that can claim
its reading, through a static index built once per camera and grid:

- the image is cut into square tiles; for every (location k, tile t) whose silhouette
  rectangle overlaps t, `pair_depth_bounds` scans the overlap once and records the depth
  interval [lo, hi] outside which no reading z can pass k's mask test there:
  lo = min (mu - W), hi = max (mu + W) over the overlap's pixels, where W is the half-width of
  the test at the pixel's object sigma s ((z - mu)^2 < 2 s^2 (c - log s),
  c = log(1 - pi_out) - log(sqrt(2 pi)) - log(pi_out / z_max)), plus a small slack for rounding;
- pairs are sorted by tile, then lo; each tile keeps the longest interval it holds (span).

Per frame, `pixel_entries` finds in its tile the pairs with lo in [z - span, z] by binary
search and runs the exact mask test of the reference on those with z <= hi. The candidates are
a superset of the mask by construction, so the lists are the same as a scan of every
silhouette. With `fill == 0` the kernel writes each pixel's count; with `fill == 1` it writes
the entries into the pixel's slice at `offsets[p]`, keeping it sorted by (mu, location id) as
it goes (insertion, no atomics). On the CPU `pixel_entries_once` does both in one pass (each
mask test once). Frames of a batch are blocks of pixels and of locations: the
entries of frame b name location b * n_locations + k. With `background_occludes`, a location
does not claim a pixel whose known background is clearly in front of it.

Where its memory allows (engine.Engine's `table`), a finer static index replaces the tiles:
the pixel table holds every (pixel, location) pair of the silhouettes where some reading can
pass the mask test (mu > 0, W > 0), with the pair's mu, object sigma s, log s and W (rounded up),
per pixel sorted by (float32 mu, location id), the lists' order. A pair can take reading z only
where mu - W < z < mu + W; along a pixel's pairs the running maximum of mu + W from the front
(`key` x) and the running minimum of mu - W from the back (`key` y) are monotonic, each
rounded outwards to float32. Per frame a pixel finds by binary search its first pair with
x > z and its first after that with y >= z, and walks the pairs between: every pair with
|z - mu| < W lies there, and on the demo
frame almost nothing else (240,000 pairs walked for 225,000 entries, against 560,000 within
the pixel's largest W of z). It skips those with |z - mu| >= W and runs the mask test of the
tile path on the others, from the stored mu and s: the same arithmetic, so the same entries,
already in order (no object_depth per frame, no sorting). On the CPU each pixel's thread
first asks for the next pixel's records (`prefetch_pairs`, a hint with no effect on the
result), so they are on their way while it tests its own.
"""

from typing import Any

import warp as wp

from .pixel_model import (LOG_SQRT_2PI, GeometryArrays, PixelLists, PixelModel, f64, gaussian_logpdf_from_log,
                          is_reading, object_delta)
from .pixel_model import object_depth, object_log_inlier, object_sigma

EMPTY = wp.constant(wp.float64(1.0e300))


@wp.struct
class TileIndex:
    """For each image tile, the locations whose silhouette overlaps it, with depth bounds."""

    size: int  # tile edge, pixels
    tiles_x: int  # tiles per image row
    start: wp.array(dtype=wp.int32)  # first pair of each tile (n_tiles + 1)
    loc: wp.array(dtype=wp.int32)  # location of each pair, sorted by tile, then lo
    lo: wp.array(dtype=wp.float64)  # a reading below lo cannot pass the pair's mask test
    hi: wp.array(dtype=wp.float64)  # nor one above hi
    span: wp.array(dtype=wp.float64)  # longest hi - lo of each tile


@wp.struct
class TablePair:
    """One pair of the pixel table, its fields side by side: a pixel's walk reads one record
    a pair (32 bytes, two a cache line) instead of five arrays (the table is tens of MB, more
    than a CPU's cache, so the walk waits on memory)."""

    mu: wp.float64  # the object depth (object_depth)
    sigma: wp.float64  # its object sigma (object_sigma)
    log_sigma: wp.float64  # wp.log of it
    loc: wp.int32  # the location
    half: wp.float32  # the test's half-width W, rounded up


@wp.struct
class PixelTable:
    """Per pixel, the silhouette pairs where a reading can pass the mask test (module doc);
    use = 0: empty, the tile index serves."""

    use: int
    width: int  # image width, pixels (p = v * width + u within a frame)
    start: wp.array(dtype=wp.int32)  # first pair of each pixel (n_pixels + 1)
    key: wp.array(dtype=wp.vec2f)  # per pair, sorted per pixel by (float32 mu, loc): the largest mu + W
    # of the pixel's pairs up to it, and the least mu - W from it on (rounded outwards)
    pair: wp.array(dtype=TablePair)  # the pairs in the same order


@wp.func
def hidden_by_background(pm: PixelModel, bg: wp.array2d(dtype=wp.float64), p: int, mu: wp.float64) -> bool:
    """The known background (pi_out < 1) lies clearly in front of the object's depth mu."""
    return pm.background_occludes == 1 and bg[p, 3] < f64(1.0) and bg[p, 0] + pm.occlusion_margin < mu


@wp.func
def test_half_width(pm: PixelModel, s: wp.float64) -> wp.float64:
    """Half-width W of the mask test at object sigma s: (z - mu)^2 < W^2 (0: nothing passes)."""
    q = pm.log_inlier_weight - LOG_SQRT_2PI - pm.log_outlier - wp.log(s)
    if q > f64(0.0):
        return s * wp.sqrt(f64(2.0) * q)
    return f64(0.0)


@wp.func
def pixel_reach(geo: GeometryArrays, pm: PixelModel, k: int, d: wp.vec3d) -> wp.vec3d:
    """(mu, s, W) of location k at the pixel of ray d: its object depth, object sigma and the
    mask test's half-width there; W = 0 where no reading can pass (mu <= 0: not the object's)."""
    o = object_depth(geo, k, d)
    if o[0] > f64(0.0):
        s = object_sigma(pm, o[0], o[1])
        return wp.vec3d(o[0], s, test_half_width(pm, s))
    return wp.vec3d(o[0], f64(0.0), f64(0.0))


@wp.kernel(enable_backward=False)
def pair_depth_bounds(
    geo: GeometryArrays,
    pm: PixelModel,
    size: int,
    tiles_x: int,
    pair_loc: wp.array(dtype=wp.int32),
    pair_tile: wp.array(dtype=wp.int32),
    lo: wp.array(dtype=wp.float64),
    hi: wp.array(dtype=wp.float64),
):
    """Depth interval of each (location, tile) pair; lo = EMPTY where nothing can pass."""
    i = wp.tid()
    k = pair_loc[i]
    t = pair_tile[i]
    r = geo.rect[k]
    u0 = wp.max(r[0], (t % tiles_x) * size)
    u1 = wp.min(r[2], (t % tiles_x) * size + size - 1)
    v0 = wp.max(r[1], (t / tiles_x) * size)
    v1 = wp.min(r[3], (t / tiles_x) * size + size - 1)
    lo_min = EMPTY
    hi_max = -EMPTY
    for v in range(v0, v1 + 1):
        for u in range(u0, u1 + 1):
            m = pixel_reach(geo, pm, k, geo.rays[v, u])
            if m[2] > f64(0.0):
                lo_min = wp.min(lo_min, m[0] - m[2])
                hi_max = wp.max(hi_max, m[0] + m[2])
    lo[i] = EMPTY
    hi[i] = -EMPTY
    if lo_min < EMPTY:
        slack = f64(1.0e-6) * (f64(1.0) + wp.abs(hi_max))
        lo[i] = lo_min - slack
        hi[i] = hi_max + slack


@wp.kernel(enable_backward=False)
def table_pairs(
    geo: GeometryArrays,
    pm: PixelModel,
    width: int,
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    pixel: wp.array(dtype=wp.int32),
    loc: wp.array(dtype=wp.int32),
    mu: wp.array(dtype=wp.float64),
    sigma: wp.array(dtype=wp.float64),
    log_sigma: wp.array(dtype=wp.float64),
    half: wp.array(dtype=wp.float32),
):
    """The pixel table's pairs of location k, scanned over its silhouette rectangle, written
    in scan order from offsets[k] (room for the rectangle's area); counts[k]: how many."""
    k = wp.tid()
    r = geo.rect[k]
    n = int(0)
    for v in range(r[1], r[3] + 1):
        for u in range(r[0], r[2] + 1):
            m = pixel_reach(geo, pm, k, geo.rays[v, u])
            if m[2] > f64(0.0):
                e = offsets[k] + n
                pixel[e] = v * width + u
                loc[e] = k
                mu[e] = m[0]
                sigma[e] = m[1]
                log_sigma[e] = wp.log(m[1])
                # rounded up past float32's rounding and the square roots' last bits
                half[e] = wp.float32(m[2] * f64(1.00001) + f64(1.0e-6) * (f64(1.0) + m[0]))
                n += 1
    counts[k] = n


@wp.func
def table_search(table: PixelTable, c: int, first: int, last: int, z: wp.float64) -> int:
    """The first pair in [first, last) whose walk key c has passed reading z (binary search,
    the keys being monotonic along a pixel's pairs): for c = 0, the running maximum of mu + W,
    the first above z (no earlier pair can take z); for c = 1, the running minimum of mu - W,
    the first at or above z (the walk's end: no later pair can take z)."""
    while first < last:
        mid = (first + last) / 2
        k = f64(table.key[mid][c])
        if k < z or (c == 0 and k == z):
            first = mid + 1
        else:
            last = mid
    return first


@wp.func
def table_entry(pm: PixelModel, bg: wp.array2d(dtype=wp.float64), table: PixelTable, j: int, p: int,
                z: wp.float64) -> wp.vec2d:
    """pair_entry from the pixel table's pair j: (mu, Delta) or mu = -1."""
    e = table.pair[j]
    mu = e.mu
    if wp.abs(z - mu) < wp.float64(e.half):
        inlier = pm.log_inlier_weight + gaussian_logpdf_from_log(z, mu, e.sigma, e.log_sigma)
        if inlier > pm.log_outlier and not hidden_by_background(pm, bg, p, mu):
            return wp.vec2d(mu, object_delta(pm, inlier))
    return wp.vec2d(f64(-1.0), f64(0.0))


@wp.func_native("""
#if !defined(__CUDA_ARCH__)
for (int i = first; i < last; i += 2)
    __builtin_prefetch(&pair.data[i], 0, 0);
#endif
""")
def prefetch_pairs(pair: wp.array(dtype=TablePair), first: int, last: int):
    """Ask the CPU's cache for the records first to last (every other one: two a line); a
    hint, nothing on a GPU (pixel_entries_once: the next pixel's, while this one is tested)."""
    ...


@wp.func
def candidates(tiles: TileIndex, table: PixelTable, u: int, v: int, z: wp.float64) -> wp.vec2i:
    """[first, last) of the pairs that pixel (u, v) with reading z scans: its table window
    (table_search), or its tile's pairs from z - span on (stopping earlier, see `more`)."""
    if table.use == 1:
        p = v * table.width + u
        first = table_search(table, 0, table.start[p], table.start[p + 1], z)
        return wp.vec2i(first, table_search(table, 1, first, table.start[p + 1], z))
    t = (v / tiles.size) * tiles.tiles_x + u / tiles.size
    return wp.vec2i(first_pair(tiles, t, z), tiles.start[t + 1])


@wp.func
def more(tiles: TileIndex, table: PixelTable, j: int, u: int, v: int, z: wp.float64) -> bool:
    """Pair j can still hold an entry for reading z: a later one cannot where this one is not
    (table: the least mu - W from j on is not below z; tiles: lo is above z)."""
    if table.use == 1:
        return True  # (candidates found the table's end)
    return tiles.lo[j] <= z


@wp.func
def candidate_entry(geo: GeometryArrays, pm: PixelModel, bg: wp.array2d(dtype=wp.float64),
                    tiles: TileIndex, table: PixelTable, j: int, p: int, u: int, v: int, d: wp.vec3d,
                    z: wp.float64) -> wp.vec2d:
    if table.use == 1:
        return table_entry(pm, bg, table, j, p, z)
    return pair_entry(geo, pm, bg, tiles, j, p, u, v, d, z)


@wp.func
def candidate_loc(tiles: TileIndex, table: PixelTable, j: int) -> wp.int32:
    if table.use == 1:
        return table.pair[j].loc
    return tiles.loc[j]


@wp.func
def entry_before(mu_a: wp.float32, k_a: wp.int32, mu_b: wp.float32, k_b: wp.int32) -> bool:
    return mu_a < mu_b or (mu_a == mu_b and k_a < k_b)


@wp.func
def lower_bound(values: wp.array(dtype=Any), first: int, last: int, key: Any) -> int:
    """The first index in [first, last) of the ascending `values` with values[i] >= key."""
    while first < last:
        mid = (first + last) / 2
        if values[mid] < key:
            first = mid + 1
        else:
            last = mid
    return first


@wp.func
def first_pair(tiles: TileIndex, t: int, z: wp.float64) -> int:
    """The first pair of tile t with lo >= z - span (binary search): earlier ones end before z."""
    return lower_bound(tiles.lo, tiles.start[t], tiles.start[t + 1], z - tiles.span[t])


@wp.func
def pair_entry(geo: GeometryArrays, pm: PixelModel, bg: wp.array2d(dtype=wp.float64), tiles: TileIndex,
               j: int, p: int, u: int, v: int, d: wp.vec3d, z: wp.float64) -> wp.vec2d:
    """Pair j's mask test at pixel p = (u, v), ray d, reading z: (mu, Delta) of its entry when
    the reading passes, else mu = -1."""
    if z <= tiles.hi[j]:
        k = tiles.loc[j]
        r = geo.rect[k]
        if u >= r[0] and u <= r[2] and v >= r[1] and v <= r[3]:
            o = object_depth(geo, k, d)
            mu = o[0]
            if mu > f64(0.0):
                inlier = object_log_inlier(pm, z, mu, o[1])
                if inlier > pm.log_outlier and not hidden_by_background(pm, bg, p, mu):
                    return wp.vec2d(mu, object_delta(pm, inlier))
    return wp.vec2d(f64(-1.0), f64(0.0))


@wp.func
def outward(x: wp.float64, up: wp.float64) -> wp.float32:
    """x as a float32 on its `up` side (+1 or -1) by more than float32's rounding."""
    return wp.float32(x + up * f64(1.0e-6) * (f64(1.0) + wp.abs(x)))


@wp.kernel(enable_backward=False)
def table_window(start: wp.array(dtype=wp.int32), pair: wp.array(dtype=TablePair),
                 key: wp.array(dtype=wp.vec2f)):
    """PixelTable.key of pixel p's pairs (in their order): the running maximum of mu + W from
    the front, the running minimum of mu - W from the back, each rounded outwards. One thread
    per pixel."""
    p = wp.tid()
    hi = -EMPTY
    for j in range(start[p], start[p + 1]):
        hi = wp.max(hi, pair[j].mu + f64(pair[j].half))
        key[j] = wp.vec2f(outward(hi, f64(1.0)), wp.float32(0.0))
    lo = EMPTY
    for jj in range(start[p + 1] - start[p]):
        j = start[p + 1] - 1 - jj
        lo = wp.min(lo, pair[j].mu - f64(pair[j].half))
        key[j] = wp.vec2f(key[j][0], outward(lo, f64(-1.0)))


@wp.kernel(enable_backward=False)
def pixel_entries(
    depth: wp.array3d(dtype=wp.float32),
    geo: GeometryArrays,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    tiles: TileIndex,
    table: PixelTable,
    n_locations: int,
    fill: int,
    lists: PixelLists,
    capacity: int,
    reserved: wp.array(dtype=wp.int32),
):
    b, v, u = wp.tid()
    p = (b * depth.shape[1] + v) * depth.shape[2] + u
    if fill == 1 and reserved.shape[0] > 0 and lists.counts[p] <= LOCAL_MATCHES:
        return  # after pixel_entries_once: only the lists too long for its stack buffer
    z = f64(depth[b, v, u])
    n = int(0)
    if is_reading(pm, z):
        d = geo.rays[v, u]
        e0 = int(0)
        if fill == 1:
            e0 = lists.offsets[p]
        span = candidates(tiles, table, u, v, z)
        j = span[0]
        while j < span[1] and more(tiles, table, j, u, v, z):
            m = candidate_entry(geo, pm, bg, tiles, table, j, p, u, v, d, z)
            if m[0] > f64(0.0):
                if fill == 1 and e0 + n < capacity:
                    mu32 = wp.float32(m[0])
                    kb = b * n_locations + candidate_loc(tiles, table, j)
                    e = e0 + n
                    while e > e0 and entry_before(mu32, kb, lists.mu[e - 1], lists.loc[e - 1]):
                        lists.loc[e] = lists.loc[e - 1]
                        lists.mu[e] = lists.mu[e - 1]
                        lists.delta[e] = lists.delta[e - 1]
                        e -= 1
                    lists.loc[e] = kb
                    lists.mu[e] = mu32
                    lists.delta[e] = wp.float32(m[1])
                n += 1
            j += 1
    if fill == 0:
        lists.counts[p] = n


LOCAL_MATCHES = 128  # pixel_entries_once keeps up to this many of a pixel's entries on its stack
LocalLoc = wp.types.vector(length=LOCAL_MATCHES, dtype=wp.int32)
LocalValues = wp.types.vector(length=LOCAL_MATCHES, dtype=wp.float32)


@wp.kernel(enable_backward=False)
def pixel_entries_once(
    depth: wp.array3d(dtype=wp.float32),
    geo: GeometryArrays,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    tiles: TileIndex,
    table: PixelTable,
    n_locations: int,
    lists: PixelLists,
    capacity: int,
    reserved: wp.array(dtype=wp.int32),
):
    """The lists in one pass (CPU): each pixel runs pixel_entries' mask tests once, keeps its
    entries sorted on its stack, takes its slice with an atomic add on reserved[0] (in pixel
    order on one CPU thread, so the offsets are the exclusive scan's) and copies them there if
    the slice fits the capacity. reserved[0] ends as the total, reserved[1] counts the pixels
    with more than LOCAL_MATCHES entries: pixel_entries (fill 1, these `reserved`) fills those."""
    b, v, u = wp.tid()
    p = (b * depth.shape[1] + v) * depth.shape[2] + u
    z = f64(depth[b, v, u])
    n = int(0)
    locs = LocalLoc()
    mus = LocalValues()
    deltas = LocalValues()
    if table.use == 1 and u + 1 < depth.shape[2]:  # the next pixel's records, on their way
        zn = f64(depth[b, v, u + 1])
        if is_reading(pm, zn):
            nxt = candidates(tiles, table, u + 1, v, zn)
            prefetch_pairs(table.pair, nxt[0], nxt[1])
    if is_reading(pm, z):
        d = geo.rays[v, u]
        span = candidates(tiles, table, u, v, z)
        j = span[0]
        while j < span[1] and more(tiles, table, j, u, v, z):
            m = candidate_entry(geo, pm, bg, tiles, table, j, p, u, v, d, z)
            if m[0] > f64(0.0):
                if n < LOCAL_MATCHES:
                    mu32 = wp.float32(m[0])
                    kb = b * n_locations + candidate_loc(tiles, table, j)
                    e = n
                    while e > 0 and entry_before(mu32, kb, mus[e - 1], locs[e - 1]):
                        locs[e] = locs[e - 1]
                        mus[e] = mus[e - 1]
                        deltas[e] = deltas[e - 1]
                        e -= 1
                    locs[e] = kb
                    mus[e] = mu32
                    deltas[e] = wp.float32(m[1])
                n += 1
            j += 1
    lists.counts[p] = n
    start = int(0)
    if n > 0:
        start = wp.atomic_add(reserved, 0, n)
    lists.offsets[p] = start
    if n > LOCAL_MATCHES:
        wp.atomic_add(reserved, 1, 1)
    elif start + n <= capacity:
        for e in range(n):
            lists.loc[start + e] = locs[e]
            lists.mu[start + e] = mus[e]
            lists.delta[start + e] = deltas[e]

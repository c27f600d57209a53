"""What a location's pixels say of a person beyond the mean field's lists, and eq. 13.

- The behind cost (model.behind_cost): each location's silhouette-core pixels whose reading lies
  behind its object beyond the mask test (the object would hide them), counted once a frame
  (`behind_points` gathers the lattice points, `behind_count` counts them).
- The top band (model.top_support): in the top of each box, the pixels that support the object,
  read behind it, are hidden in front of it or have no reading (`top_band`, `top_band_rows`,
  `top_band_clear`; `keep_better_top` for the shorter people of model.top_heights), into `Bands`
  (one array a count), the band chosen by a `BandQuery`.
- Eq. 13's soft threshold with the corrected sign, times the top-band factor (`soft_threshold`).

The NumPy reference of each: dpom_warp.reference_people.
"""

import warp as wp

from .masks import test_half_width
from .mean_field import sigmoid
from .pixel_model import (SHAPE_SOLID, GeometryArrays, PixelModel, f64, is_reading, object_depth, object_log_inlier,
                          object_sigma)

BandCounts = wp.types.vector(length=5, dtype=wp.int32)  # support, against, hidden, missing, seen


@wp.struct
class Bands:
    """Each location's top-band counts of a batch (top_band): the pixels that support its
    object, read behind it (against), in front of it (hidden), have no reading (missing), and
    those in the image (seen; -1: not counted)."""

    support: wp.array(dtype=wp.int32)
    against: wp.array(dtype=wp.int32)
    hidden: wp.array(dtype=wp.int32)
    missing: wp.array(dtype=wp.int32)
    seen: wp.array(dtype=wp.int32)


@wp.struct
class BandQuery:
    """Which band top_band counts: heights lo to hi (metres, world z) of each location's object,
    seen from a camera whose centre is at centre_z; the locations with rho >= min_rho; a pixel
    supports it within support_sigmas sigma (0: the mask test); a missing reading counts where
    the background is read (pi_inf < missing_read)."""

    centre_z: wp.float64
    lo: wp.float64
    hi: wp.float64
    min_rho: wp.float64
    support_sigmas: wp.float64
    missing_read: wp.float64


def band_query(centre_z: float, lo: float, hi: float, min_rho: float, support_sigmas: float,
               missing_read: float) -> BandQuery:
    q = BandQuery()
    q.centre_z, q.lo, q.hi, q.min_rho, q.support_sigmas, q.missing_read = (
        centre_z, lo, hi, min_rho, support_sigmas, missing_read)
    return q


def bands_of(arrays) -> Bands:
    """A Bands of five int32 arrays (support, against, hidden, missing, seen)."""
    out = Bands()
    out.support, out.against, out.hidden, out.missing, out.seen = arrays
    return out


@wp.func
def band_at(c: Bands, i: int) -> BandCounts:
    return BandCounts(c.support[i], c.against[i], c.hidden[i], c.missing[i], c.seen[i])


@wp.func
def set_band(c: Bands, i: int, n: BandCounts):
    c.support[i] = n[0]
    c.against[i] = n[1]
    c.hidden[i] = n[2]
    c.missing[i] = n[3]
    c.seen[i] = n[4]


SUPPORTS = wp.constant(0)
BEHIND = wp.constant(1)
IN_FRONT = wp.constant(2)


@wp.func
def reading_class(pm: PixelModel, z: wp.float64, mu: wp.float64, var: wp.float64,
                  support_sigmas: wp.float64) -> int:
    """What reading z says of an object at depth mu (its extra variance var) in the pixel:
    SUPPORTS (it passes the mask test, or with support_sigmas > 0 lies within that many sigma),
    else BEHIND (z > mu: the object would hide it) or IN_FRONT (hidden by something nearer);
    -1 for no reading."""
    if not is_reading(pm, z):
        return -1
    passes = False
    if support_sigmas > f64(0.0):
        passes = wp.abs(z - mu) <= support_sigmas * object_sigma(pm, mu, var)
    else:
        passes = object_log_inlier(pm, z, mu, var) > pm.log_outlier
    if passes:
        return SUPPORTS
    if z > mu:
        return BEHIND
    return IN_FRONT


@wp.func
def solid_depth_span(geo: GeometryArrays, k: int, forward: wp.vec3d) -> wp.vec2d:
    """The z-depths (ray parameters, t = (X - centre) . forward) that location k's solid's
    bounding box spans, the nearest floored at 0: every point of the solid lies between."""
    p = geo.location[k]
    reach = wp.max(wp.max(geo.body_radius, geo.depth_radius), wp.max(geo.head_radius, geo.leg_radius))
    t_lo = f64(1.0e30)
    t_hi = f64(0.0)
    for corner in range(8):
        dx = reach
        if corner % 2 == 0:
            dx = -reach
        dy = reach
        if (corner / 2) % 2 == 0:
            dy = -reach
        dz = geo.top
        if corner / 4 == 0:
            dz = geo.bottom
        t = wp.dot(wp.vec3d(p[0] + dx, p[1] + dy, p[2] + dz) - geo.centre, forward)
        t_lo = wp.min(t_lo, t)
        t_hi = wp.max(t_hi, t)
    return wp.vec2d(wp.max(t_lo, f64(0.0)), t_hi)


@wp.func
def row_may_reach(geo: GeometryArrays, v: int, u0: int, u1: int, step: int, centre_z: wp.float64,
                  span: wp.vec2d, low: wp.float64, high: wp.float64) -> bool:
    """Whether a point of the solid seen in image row v (columns u0 to u1 every `step`) can
    lie between heights `low` and `high`: its height is centre_z + t d_z for a z-depth t in
    `span` (solid_depth_span) and the vertical component d_z of one of the row's rays, so the
    products' extremes bound it (with a margin for rounding)."""
    z_lo = f64(1.0e30)  # the row's vertical ray components
    z_hi = f64(-1.0e30)
    for u in range(u0, u1 + 1, step):
        z_lo = wp.min(z_lo, geo.rays[v, u][2])
        z_hi = wp.max(z_hi, geo.rays[v, u][2])
    t_lo = span[0]
    t_hi = span[1]
    h_lo = centre_z + wp.min(wp.min(t_lo * z_lo, t_lo * z_hi), wp.min(t_hi * z_lo, t_hi * z_hi))
    h_hi = centre_z + wp.max(wp.max(t_lo * z_lo, t_lo * z_hi), wp.max(t_hi * z_lo, t_hi * z_hi))
    return not (h_hi + f64(1.0e-9) < low or h_lo - f64(1.0e-9) > high)


@wp.kernel(enable_backward=False)
def behind_points(
    geo: GeometryArrays,
    pm: PixelModel,
    centre_z: wp.float64,
    side: wp.float64,
    low: wp.float64,
    high: wp.float64,
    step: int,
    forward: wp.vec3d,
    fill: int,
    first: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    pixel: wp.array(dtype=wp.int32),
    mu: wp.array(dtype=wp.float64),
    var: wp.array(dtype=wp.float64),
    half: wp.array(dtype=wp.float64),
):
    """The static half of behind_count, once per camera and grid: the pixels of location k's
    silhouette (its solid's projection) counted in its core, on the lattice of pixels whose row
    and column are multiples of `step`: in each lattice row, the lattice pixels whose rays hit
    the solid run from column a to b, and the `side` share of that run at each end is left out
    (arms, a narrower body than the solid), as are object points below height `low` (the gap
    between the legs) or above `high` (heads: people are shorter or taller than the solid).
    With fill 0, counts[k] = how many; with fill 1 they are written from first[k] on: the
    pixel (v x width + u), the object's depth mu and extra variance var there (object_depth)
    and the mask test's half-width there (masks.test_half_width). One thread per location.
    `forward`: the camera's optical axis (a ray's parameter is its z-depth, d . forward = 1): a
    lattice row none of whose points can lie between `low` and `high` on the solid
    (row_may_reach) is skipped without walking it, which changes no point (other shapes walk
    every row: the bound is the solid's)."""
    k = wp.tid()
    width = geo.rays.shape[1]
    n = int(0)
    r = geo.rect[k]
    u0 = (r[0] + step - 1) / step * step  # the first lattice column and row in the rectangle
    v0 = (r[1] + step - 1) / step * step
    span = solid_depth_span(geo, k, forward)
    for v in range(v0, r[3] + 1, step):
        if geo.shape == SHAPE_SOLID and not row_may_reach(geo, v, u0, r[2], step, centre_z, span, low, high):
            continue
        first_u = int(-1)
        for u in range(u0, r[2] + 1, step):
            if object_depth(geo, k, geo.rays[v, u])[0] > f64(0.0):
                first_u = u
                break
        last_u = int(-1)
        if first_u >= 0:
            for u in range(r[2] / step * step, first_u - 1, -step):
                if object_depth(geo, k, geo.rays[v, u])[0] > f64(0.0):
                    last_u = u
                    break
            trim = side * f64(last_u - first_u)
            for u in range(first_u, last_u + 1, step):
                if f64(u) >= f64(first_u) + trim and f64(u) <= f64(last_u) - trim:
                    d = geo.rays[v, u]
                    o = object_depth(geo, k, d)
                    h = centre_z + o[0] * d[2]
                    if o[0] > f64(0.0) and h >= low and h <= high:
                        if fill != 0:
                            j = first[k] + n
                            pixel[j] = v * width + u
                            mu[j] = o[0]
                            var[j] = o[1]
                            half[j] = test_half_width(pm, object_sigma(pm, o[0], o[1]))
                        n += 1
    if fill == 0:
        counts[k] = n


@wp.kernel(enable_backward=False)
def behind_count(
    depth: wp.array3d(dtype=wp.float32),
    pm: PixelModel,
    first: wp.array(dtype=wp.int32),
    pixel: wp.array(dtype=wp.int32),
    mu: wp.array(dtype=wp.float64),
    var: wp.array(dtype=wp.float64),
    half: wp.array(dtype=wp.float64),
    step: int,
    entries: wp.array(dtype=wp.int32),
    behind: wp.array(dtype=wp.int32),
    add: int,
):
    """behind[i] (plus what it holds with `add`: the cameras of a rig after the first): the pixels
    of location i's silhouette core (behind_points' lattice: the
    table from first[k] to first[k + 1]) whose reading lies behind its object beyond the mask
    test (reading_class BEHIND: were the object there it would hide them), each standing for
    step^2 pixels. One thread per location of the batch; 0 for the locations in no list
    (entries[i], their entries in the lists, 0: no reading supports them), which stay where
    they start. Counted before the pruning bound, which subtracts it too (kernels.sparse
    update_bound). The mask test passes exactly where |z - mu| < W, the point's stored
    half-width (masks.test_half_width): a reading clearly inside or outside it (by 1e-9
    relative) is classed from W, one within rounding of it by the test itself (the same
    classes, without a logarithm and a square root a point)."""
    i = wp.tid()
    n_loc = first.shape[0] - 1
    b = i / n_loc
    k = i - b * n_loc
    width = depth.shape[2]
    n = int(0)
    if entries[i] > 0:
        for j in range(first[k], first[k + 1]):
            v = pixel[j] / width
            u = pixel[j] - v * width
            z = f64(depth[b, v, u])
            if is_reading(pm, z):
                gap = z - mu[j]
                w = half[j]
                if wp.abs(gap) > w * f64(1.000000001) + f64(1.0e-12):
                    if gap > f64(0.0):
                        n += step * step
                elif wp.abs(gap) >= w * f64(0.999999999) - f64(1.0e-12):  # at the edge: the test
                    if reading_class(pm, z, mu[j], var[j], f64(0.0)) == BEHIND:
                        n += step * step
    if add != 0:
        behind[i] += n
    else:
        behind[i] = n


@wp.func
def band_row(depth: wp.array3d(dtype=wp.float32), geo: GeometryArrays, pm: PixelModel,
             bg: wp.array2d(dtype=wp.float64), q: BandQuery, b: int, k: int, v: int, r: wp.vec4i,
             span: wp.vec2d) -> BandCounts:
    """top_band's counts (support, against, hidden, missing, seen) of row v of location k's
    rectangle r in frame b; with the solid, a row none of whose points can lie in the band
    (row_may_reach, `span` its solid_depth_span) counts nothing."""
    s = int(0)
    a = int(0)
    f = int(0)
    m = int(0)
    n = int(0)
    if geo.shape == SHAPE_SOLID and not row_may_reach(geo, v, r[0], r[2], 1, q.centre_z, span, q.lo, q.hi):
        return BandCounts(0, 0, 0, 0, 0)
    for u in range(r[0], r[2] + 1):
        d = geo.rays[v, u]
        o = object_depth(geo, k, d)
        mu = o[0]
        if mu > f64(0.0):
            h = q.centre_z + mu * d[2]
            z = f64(depth[b, v, u])
            if h >= q.lo and h <= q.hi:
                n += 1
                cls = reading_class(pm, z, mu, o[1], q.support_sigmas)
                if cls == SUPPORTS:
                    s += 1
                elif cls == BEHIND:
                    a += 1
                elif cls == IN_FRONT:
                    f += 1
                elif mu <= pm.z_max:
                    if bg[(b * depth.shape[1] + v) * depth.shape[2] + u, 2] < q.missing_read:
                        m += 1
    return BandCounts(s, a, f, m, n)


@wp.kernel(enable_backward=False)
def top_band(
    depth: wp.array3d(dtype=wp.float32),
    geo: GeometryArrays,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    q: BandQuery,
    rho: wp.array(dtype=wp.float64),
    out: Bands,
    forward: wp.vec3d,
):
    """The top band of a standing object (q: heights lo to hi where the pixels' rays meet it:
    its solid, or its facing plane): how many of its silhouette's pixels there pass the mask
    test (support), read behind the object (against: it would hide them, so nothing that tall
    stands there) or in front of it (hidden by something nearer); with q.support_sigmas > 0 a
    pixel supports it when within that many sigma of the object instead; `missing` counts the
    pixels without a reading where the object lies within the sensor's range (mu <= z_max: it
    would be read there) and the background (bg, kernels.background) is mostly read (pi_inf <
    q.missing_read: not a sensor's dead region); `seen` counts the band's pixels in the image,
    with a reading or not (a band outside the image has none). One thread per location of the
    batch, for those with rho >= q.min_rho (the others: 0, 0, 0, 0 and seen -1). With the
    solid, the rows of the rectangle that cannot reach the band (row_may_reach, `forward` the
    optical axis as in behind_points) are skipped: the same counts."""
    i = wp.tid()
    n_loc = geo.rect.shape[0]
    b = i / n_loc
    k = i - b * n_loc
    c = BandCounts(0, 0, 0, 0, -1)
    if rho[i] >= q.min_rho:
        c = BandCounts()
        r = geo.rect[k]
        span = solid_depth_span(geo, k, forward)
        for v in range(r[1], r[3] + 1):
            c = c + band_row(depth, geo, pm, bg, q, b, k, v, r, span)
    set_band(out, i, c)


@wp.kernel(enable_backward=False)
def top_band_clear(
    rho: wp.array(dtype=wp.float64),
    min_rho: wp.float64,
    out: Bands,
):
    """top_band_rows' start: each location's counts 0, and seen -1 where rho < min_rho (not
    counted), as top_band leaves them."""
    i = wp.tid()
    if rho[i] >= min_rho:
        set_band(out, i, BandCounts())
    else:
        set_band(out, i, BandCounts(0, 0, 0, 0, -1))


@wp.kernel(enable_backward=False)
def top_band_rows(
    depth: wp.array3d(dtype=wp.float32),
    geo: GeometryArrays,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    q: BandQuery,
    rho: wp.array(dtype=wp.float64),
    rows: int,
    out: Bands,
    forward: wp.vec3d,
):
    """top_band's counts with one thread per row of each location's rectangle (`rows`: the
    tallest rectangle's; top_band_clear first), added atomically: the same integers. For a
    GPU, where one thread walking a whole rectangle was the threshold step's longest kernel."""
    t = wp.tid()
    i = t / rows
    if rho[i] < q.min_rho:
        return
    n_loc = geo.rect.shape[0]
    b = i / n_loc
    k = i - b * n_loc
    r = geo.rect[k]
    v = r[1] + t - i * rows
    if v > r[3]:
        return
    c = band_row(depth, geo, pm, bg, q, b, k, v, r, solid_depth_span(geo, k, forward))
    if c[4] > 0:
        wp.atomic_add(out.support, i, c[0])
        wp.atomic_add(out.against, i, c[1])
        wp.atomic_add(out.hidden, i, c[2])
        wp.atomic_add(out.missing, i, c[3])
        wp.atomic_add(out.seen, i, c[4])


@wp.func
def band_out_of_view(seen: int, min_pixels: int, area: wp.float64, part: wp.float64) -> bool:
    """Whether a location's top band is out of view: counted (seen >= 0) with fewer than
    min_pixels, or fewer than part x |S_k| (area), of its pixels in the image."""
    return seen >= 0 and (seen < min_pixels or f64(seen) < part * area)


@wp.func
def top_factor(c: BandCounts, weight: wp.float64, missing_weight: wp.float64, share: wp.float64,
               slope: wp.float64, min_pixels: int, unseen: wp.float64, area: wp.float64, part: wp.float64) -> wp.float64:
    """sigmoid(slope ((s + weight f) / (s + a + f + missing_weight m) - share)) of a band's
    counts c = (s, a, f, m, seen); `unseen` where the band is out of view (band_out_of_view),
    else 1 with fewer than min_pixels judged in the band (read, or missing where
    missing_weight > 0)."""
    s = c[0]
    a = c[1]
    f = c[2]
    m = c[3]
    if band_out_of_view(c[4], min_pixels, area, part):
        return unseen
    n = s + a + f
    if missing_weight > f64(0.0):
        n = n + m
    if n < min_pixels or n == 0:
        return f64(1.0)
    return sigmoid(slope * ((f64(s) + weight * f64(f)) / (f64(s + a + f) + missing_weight * f64(m)) - share))


@wp.kernel(enable_backward=False)
def keep_better_top(
    mine: Bands,
    other: Bands,
    weight: wp.float64,
    missing_weight: wp.float64,
    share: wp.float64,
    slope: wp.float64,
    min_pixels: int,
    unseen: wp.float64,
    area: wp.array(dtype=wp.float64),
    part: wp.float64,
):
    """A location's top-band counts become those of another band (a shorter solid's,
    ModelParams.top_heights) where that band's top_factor is larger, except where its own band
    is out of view (band_out_of_view: top_unseen decides, as without). One thread per
    location of the batch (reference.mean_field); area holds the L locations of one frame."""
    k = wp.tid()
    a = area[k % area.shape[0]]
    if band_out_of_view(mine.seen[k], min_pixels, a, part):
        return
    own = band_at(mine, k)
    shorter = band_at(other, k)
    if top_factor(shorter, weight, missing_weight, share, slope, min_pixels, unseen, a, part) > top_factor(
            own, weight, missing_weight, share, slope, min_pixels, unseen, a, part):
        set_band(mine, k, shorter)


@wp.kernel(enable_backward=False)
def soft_threshold(
    alpha: wp.float64,
    beta: wp.float64,
    area: wp.array(dtype=wp.float64),
    visible: wp.array(dtype=wp.float64),
    rho: wp.array(dtype=wp.float64),
    top: Bands,
    top_hidden: wp.float64,
    top_missing: wp.float64,
    top_share: wp.float64,
    top_slope: wp.float64,
    top_min_pixels: int,
    top_unseen: wp.float64,
    unseen_share: wp.float64,
    unseen_part: wp.float64,
    unhidden: int,
    whole: Bands,
    share: wp.array(dtype=wp.float64),
    rho_star: wp.array(dtype=wp.float64),
):
    """Eq. 13 with the corrected sign: rho* = sigmoid(alpha e + beta) rho, e = visible / |S_k|
    (area holds the L locations of one frame; the arrays hold the frames of a batch), or with
    `unhidden` e = visible / (pixels of S_k reading at or behind the object: whole.support +
    whole.against, the top_band counts over the whole silhouette) where there are any; times
    the top-band factor (top_band, top_factor; top_share = 0: none), and where the band is out
    of view (band_out_of_view, unseen_part) by sigmoid(top_slope (e - unseen_share)) unless
    unseen_share is 0 (ModelParams.top_unseen_share)."""
    k = wp.tid()
    a = area[k % area.shape[0]]
    if a > f64(0.0):
        d = a
        if unhidden != 0 and whole.support[k] + whole.against[k] > 0:
            d = f64(whole.support[k] + whole.against[k])
        e = visible[k] / d
        share[k] = e
        rho_star[k] = sigmoid(alpha * e + beta) * rho[k]
        if top_share > f64(0.0):
            factor = top_factor(band_at(top, k), top_hidden, top_missing, top_share, top_slope, top_min_pixels,
                                top_unseen, a, unseen_part)
            if unseen_share > f64(0.0) and band_out_of_view(top.seen[k], top_min_pixels, a, unseen_part):
                factor = factor * sigmoid(top_slope * (e - unseen_share))
            rho_star[k] = rho_star[k] * factor
    else:
        share[k] = f64(0.0)
        rho_star[k] = f64(0.0)

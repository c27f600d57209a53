"""Plain NumPy reference of the DPOM maths (MODEL.md). Small, readable, slow.

The Warp kernels in `dpom_warp.kernels` implement exactly these steps; the tests compare the two.
The per-pixel model is in reference_pixels.py and the people-only tests in reference_people.py
(both importable from here, as the tests do).
List entries are stored as float32 (object depth and Delta) on the fast path, so the reference
rounds them the same way; everything else is float64.
"""

from __future__ import annotations

import warnings

import numpy as np

from .geometry import Geometry, neighbour_lists
from .model import AutoBackground, Background, ModelParams
from .reference_people import (band_out_of_view, behind_count, behind_evidence, rig_bands, top_band,  # noqa: F401
                               top_factor)
from .reference_pixels import (LOG_SQRT_2PI, gaussian_logpdf, kept_silhouette, log_outlier, log_theta,  # noqa: F401
                               object_sigma, reading_classes, sigmoid, silhouette, silhouettes, valid_reading)


def outside_objects(points, bounds):
    """True for world points outside the objects' reach (beside the grid or above objects)."""
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    return (x < bounds[0]) | (x > bounds[1]) | (y < bounds[2]) | (y > bounds[3]) | (z > bounds[5])


def floor_background(geom: Geometry, params: ModelParams, depth_m=None) -> Background:
    """Background without background frames: the floor plane z = 0 where the ray meets it,
    else broad; with `depth_m` and params.background_outside_grid, readings out of every
    object's reach are background at their own depth."""
    dz = geom.rays[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dz < -1e-12, -geom.centre[2] / dz, np.inf)
    floor = (t > 0) & (t <= params.z_max)
    mu = np.where(floor, t, 0.0)
    known = floor
    if depth_m is not None and params.background_outside_grid:
        z = np.asarray(depth_m, dtype=np.float64)
        static = valid_reading(z, params) & outside_objects(geom.centre + z[..., None] * geom.rays,
                                                            geom.bounds)
        mu = np.where(static, z, mu)
        known = known | static
    return Background(
        mu=mu,
        sigma=np.where(known, params.sensor_sigma(mu), 1.0),
        missing=np.full(mu.shape, params.missing_prob),
        outlier=np.where(known, params.outlier_prob, 1.0),
    )


def background_from_frames(frames_m: np.ndarray, params: ModelParams) -> Background:
    """Per-pixel background from (N, H, W) frames in metres (0 = no reading).

    pi_inf = share of frames with no reading (clipped), mu = median of readings,
    sigma = 1.4826 * MAD floored by the sensor noise, pi_out = outlier_prob.
    Pixels with no reading in any frame get a broad (uniform) distribution.
    """
    frames = np.asarray(frames_m, dtype=np.float64)
    ok = valid_reading(frames, params)
    n_ok = ok.sum(axis=0)
    data = np.where(ok, frames, np.nan)
    with warnings.catch_warnings():  # pixels never read are all-NaN slices: handled below
        warnings.simplefilter("ignore", RuntimeWarning)
        mu = np.nanmedian(data, axis=0)
        mad = np.nanmedian(np.abs(data - mu[None]), axis=0)
    seen = n_ok > 0
    mu = np.where(seen, mu, 0.0)
    sigma = np.where(seen, np.maximum(1.4826 * np.nan_to_num(mad), params.sensor_sigma(mu)), 1.0)
    c = params.missing_clip
    missing = np.clip(1.0 - n_ok / frames.shape[0], c, 1.0 - c)
    return Background(mu=mu, sigma=sigma, missing=missing,
                      outlier=np.where(seen, params.outlier_prob, 1.0))


def background_clusters(frames_m, params: ModelParams, auto: AutoBackground):
    """`input.background: auto` (model.AutoBackground): the background of each pixel from
    (N, H, W) frames in metres that show people, streamed in order.

    Returns:
        (Background, fallback): fallback (H, W) bool marks the pixels left to the floor-only
        model (their Background entries are broad placeholders).
    """
    frames = np.asarray(frames_m, dtype=np.float64)
    n, shape = len(frames), frames.shape[1:]
    S = auto.slots
    cnt = np.zeros(shape + (S,), np.int64)
    mean = np.zeros(shape + (S,))
    m2 = np.zeros(shape + (S,))
    n_read = np.zeros(shape, np.int64)
    for f in range(n):
        z = frames[f]
        ok = valid_reading(z, params)
        n_read += ok
        dist = np.where(cnt > 0, np.abs(z[..., None] - mean), np.inf)
        best = np.argmin(dist, axis=-1)
        best_mean = np.take_along_axis(mean, best[..., None], -1)[..., 0]
        tol = auto.cluster_sigmas * params.sensor_sigma(best_mean) + auto.cluster_floor
        join = ok & (np.take_along_axis(dist, best[..., None], -1)[..., 0] <= tol)
        # a new cluster: the first free slot, else the smallest other than the farthest (of
        # equal counts the nearest, then the first): people come and go in front of the
        # surface that is the background, which may show rarely
        free = cnt == 0
        others = np.ones(cnt.shape, bool)
        if S > 1:
            np.put_along_axis(others, np.argmax(mean, -1)[..., None], False, -1)
        c_other = np.where(others, cnt, np.iinfo(np.int64).max)
        smallest = c_other == c_other.min(-1, keepdims=True)
        slot = np.where(free.any(-1), np.argmax(free, -1),
                        np.argmin(np.where(smallest, mean, np.inf), -1))
        new = ok & ~join
        target = np.where(join, best, slot)
        c = np.take_along_axis(cnt, target[..., None], -1)[..., 0]
        m = np.take_along_axis(mean, target[..., None], -1)[..., 0]
        q = np.take_along_axis(m2, target[..., None], -1)[..., 0]
        c1 = np.where(new, 1, c + 1)
        d = z - np.where(new, 0.0, m)
        m1 = np.where(new, z, m + d / np.maximum(c1, 1))
        q1 = np.where(new, 0.0, q + d * (z - m1))
        for arr, val in ((cnt, c1), (mean, m1), (m2, q1)):
            cur = np.take_along_axis(arr, target[..., None], -1)[..., 0]
            np.put_along_axis(arr, target[..., None], np.where(ok, val, cur)[..., None], -1)
    stable = cnt >= auto.min_share * n
    pick = np.argmax(np.where(stable, mean, -np.inf), axis=-1)
    found = stable.any(-1) & (n >= auto.min_frames)
    mu = np.take_along_axis(mean, pick[..., None], -1)[..., 0]
    c = np.take_along_axis(cnt, pick[..., None], -1)[..., 0]
    q = np.take_along_axis(m2, pick[..., None], -1)[..., 0]
    spread = np.sqrt(np.where(c > 1, q / np.maximum(c - 1, 1), 0.0))
    gaps = n - n_read
    clip = params.missing_clip
    # missing share of the background alone: the frames with a reading in front are left out
    with np.errstate(divide="ignore", invalid="ignore"):
        bg_missing = np.clip(gaps / np.maximum(gaps + c, 1), clip, 1 - clip)
    absent = ~found & (n >= auto.min_frames) & (gaps >= auto.min_share * n)
    fallback = ~found & ~absent
    mu = np.where(found, mu, 0.0)
    bg = Background(
        mu=mu,
        sigma=np.where(found, np.maximum(spread, params.sensor_sigma(mu)), 1.0),
        missing=np.where(found, bg_missing, np.clip(gaps / max(n, 1), clip, 1 - clip)),
        outlier=np.where(found, params.outlier_prob, 1.0),
    )
    return bg, fallback


def background_delta(depth_m, bg: Background, params: ModelParams):
    """Delta_bg,i for every pixel (0 where there is no reading: such pixels are in no mask)."""
    z = np.asarray(depth_m, dtype=np.float64)
    ok = valid_reading(z, params)
    d = log_theta(np.where(ok, z, 1.0), bg.mu, bg.sigma, bg.missing, bg.outlier, params.z_max)
    return np.where(ok, d, 0.0)


def mask_entries(depth_m, geom: Geometry, params: ModelParams, bg: Background | None = None, which=None,
                 sils: dict | None = None):
    """All (pixel, location) pairs with i in M_k (eq. 12, corrected sign); with
    params.background_occludes, not where the known background is clearly in front of k.
    `which`: the locations to list (indices), with `sils` their silhouettes (silhouettes());
    None: all.

    Returns:
        pixel (int64 flat index), loc (int64), mu (float32 object depth), delta (float32 Delta_ki),
        sorted by pixel, then mu (near to far), then location id.
    """
    z_img = np.asarray(depth_m, dtype=np.float64)
    w = z_img.shape[1]
    outlier = log_outlier(params)
    out = []
    for k in (range(len(geom.rect)) if which is None else (int(j) for j in which)):
        sil = kept_silhouette(z_img, geom, k, params, sils)
        if sil is None:
            continue
        (v0, u0), _, z, mu, inlier = sil
        m = valid_reading(z, params) & (mu > 0) & (inlier > outlier)
        if params.background_occludes and bg is not None:
            rows, cols = slice(v0, v0 + z.shape[0]), slice(u0, u0 + z.shape[1])
            b_mu = bg.mu[rows, cols]
            known = bg.outlier[rows, cols] < 1
            m &= ~(known & (b_mu + params.occlusion_margin < mu))
        vv, uu = np.nonzero(m)
        delta = np.log1p(-params.missing_prob) + np.logaddexp(outlier, inlier[m])
        out.append(((vv + v0) * w + (uu + u0), np.full(len(vv), k), mu[m], delta))
    if not out:
        e = np.zeros(0, np.int64)
        return e, e, np.zeros(0, np.float32), np.zeros(0, np.float32)
    pixel, loc, mu, delta = (np.concatenate(c) for c in zip(*out))
    mu32, delta32 = mu.astype(np.float32), delta.astype(np.float32)
    order = np.lexsort((loc, mu32, pixel))
    return pixel[order].astype(np.int64), loc[order].astype(np.int64), mu32[order], delta32[order]


def table_window(start, mu, half):
    """The pixel table's walk keys (kernels.masks.table_window): for the pairs of each pixel
    (start[p] to start[p + 1], in table order), the running maximum of mu + W from the front
    and the running minimum of mu - W from the back, each moved outwards by 1e-6 (1 + |x|)
    and rounded to float32. Returns (n, 2) float32."""
    mu, half = np.asarray(mu, np.float64), np.asarray(half, np.float32).astype(np.float64)
    key = np.zeros((len(mu), 2), np.float32)
    for a, b in zip(start[:-1], start[1:]):
        if b > a:
            hi = np.maximum.accumulate(mu[a:b] + half[a:b])
            lo = np.minimum.accumulate((mu[a:b] - half[a:b])[::-1])[::-1]
            key[a:b, 0] = (hi + 1e-6 * (1 + np.abs(hi))).astype(np.float32)
            key[a:b, 1] = (lo - 1e-6 * (1 + np.abs(lo))).astype(np.float32)
    return key


def _padded_lists(pixel, loc, delta):
    """Per-pixel lists as (P_active, L) arrays padded with a transparent entry (rho = 0):
    (pixels, valid, L, D), from entries grouped by pixel, pixels ascending."""
    pix, count = np.unique(pixel, return_counts=True)
    width = int(count.max()) if len(count) else 0
    flat = np.arange(int(count.sum())) + np.repeat(np.arange(len(count)) * width - (np.cumsum(count) - count), count)
    valid = np.arange(width) < np.asarray(count)[:, None]
    L = np.zeros(len(count) * width, np.int64)
    D = np.zeros(len(count) * width)
    L[flat] = loc
    D[flat] = delta
    return pix, valid, L.reshape(len(count), width), D.reshape(len(count), width)


def front_transparency(r):
    """T_j = prod_{m<j} (1 - r_m) along axis 1."""
    t = np.ones_like(r)
    t[:, 1:] = np.cumprod(1.0 - r[:, :-1], axis=1)
    return t


def evidence_sums(valid, L, D, dbg, r, n_locations: int):
    """Each location's evidence, the sum over its entries of T_j (D_j - B_j) (MODEL.md,
    exclusive form), with r the entries' rho (0 where not `valid`: transparent)."""
    T = front_transparency(r)
    B = np.empty_like(D)
    b = dbg.copy()
    for j in range(D.shape[1] - 1, -1, -1):
        B[:, j] = b
        b = r[:, j] * D[:, j] + (1.0 - r[:, j]) * b
    contrib = np.where(valid, T * (D - B), 0.0)
    return np.bincount(L[valid], weights=contrib[valid], minlength=n_locations)


def joint_log_odds(depth_m, geom: Geometry, bg: Background, params: ModelParams, cells):
    """For each of `cells` (location indices), the log posterior odds of its object given the
    other cells' objects present and every other location empty: the logit of the mean-field
    update at that binary state, logit(prior) + evidence - behind_cost x readings behind -
    exclusion x the other cells closer than exclusion_radius (each neighbour's rho is 1), which
    is log P(Z, X) - log P(Z, X without it) for the binary configuration X of `cells` (the
    pixels of its masks where it is the nearest object present against what lies behind it
    then: the next cell's object or the background). Returns (len(cells),) float64."""
    cells = np.asarray(cells, np.int64)
    if not len(cells):
        return np.zeros(0)
    valid, L, D, dbg, _ = pixel_lists(depth_m, geom, bg, params)
    r = np.where(valid, np.isin(L, cells), 0.0)  # the binary state: the cells' objects present
    evidence = evidence_sums(valid, L, D, dbg, r, len(geom.rect))[cells]
    which = np.zeros(len(geom.rect), bool)
    which[cells] = True  # (a cell with no mask pixel in the lists still has readings behind it)
    behind = params.behind_cost * behind_count(depth_m, geom, params, which)[cells] if params.behind_cost > 0 else 0.0
    where = geom.locations[cells]
    close = (np.linalg.norm(where[:, None] - where[None], axis=-1) < params.exclusion_radius).sum(1) - 1
    return np.log(params.prior) - np.log1p(-params.prior) + evidence - behind - params.exclusion * close


def joint_log_odds_rig(depths, geoms: list[Geometry], bgs: list[Background], params: ModelParams, cells):
    """joint_log_odds for a rig (one depth, geometry and background a camera, over one grid):
    the prior and the exclusion once per location, every camera's evidence and behind cost
    added (each camera's pixels are independent given the binary state)."""
    cells = np.asarray(cells, np.int64)
    if not len(cells):
        return np.zeros(0)
    no_prior = params.replace(exclusion=0.0)  # each camera's evidence - behind, read off its own log odds
    own = [joint_log_odds(d, g, b, no_prior, cells) - (np.log(params.prior) - np.log1p(-params.prior))
           for d, g, b in zip(depths, geoms, bgs)]
    where = geoms[0].locations[cells]
    close = (np.linalg.norm(where[:, None] - where[None], axis=-1) < params.exclusion_radius).sum(1) - 1
    return np.log(params.prior) - np.log1p(-params.prior) + sum(own) - params.exclusion * close


def pixel_lists(depth_m, geom: Geometry, bg: Background, params: ModelParams):
    """The per-pixel lists of a frame as padded arrays: valid, L (locations), D (Delta) of
    shape (pixels with entries, longest list), each pixel's Delta_bg, and the entry count."""
    pixel, loc, _, delta = mask_entries(depth_m, geom, params, bg)
    pix, valid, L, D = _padded_lists(pixel, loc, delta.astype(np.float64))
    return valid, L, D, background_delta(depth_m, bg, params).ravel()[pix], len(pixel)


def evidence_bound(valid, L, D, dbg, rho0, params: ModelParams, behind=0.0):
    """Upper bounds u_k of rho_new_k over every state the iterations can reach from rho0
    (params.bound_rounds rounds; kernels.sparse.bound_pass): the pruning bound. `behind`
    ((K,) or 0): behind_cost x each location's readings behind its object (behind_count), a
    fixed part of its evidence for the frame, subtracted as rho_new subtracts it.

    Every rho stays at or below max(rho0_k, u_k) (a damped update is a convex combination of
    the start and of rho_new values), so with r_m <= rmax_m = max(rho0_m, u_m):
    T_j >= Tmin_j = prod_{m<j} (1 - rmax_m), and B_j >= Bmin_j (Bmin_n = Delta_bg,i,
    Bmin_j = Bmin_{j+1} + min(0, rmax_{j+1} (D_{j+1} - Bmin_{j+1}))); with x = D_j - Bmin_j
    pixel i adds to k_j's evidence at most x if x >= 0, else Tmin_j x. u_k = sigmoid(logit(prior)
    + those sums); each round starts from the last round's u (u = 1 before the first). A
    location already settled at a round's start (u below params.sparse_epsilon and at or below
    its rho0: pruned whatever follows, and its rmax is rho0 either way) keeps its u: the kernel
    skips the pixels holding settled locations alone (the others' sums are the same)."""
    K = len(rho0)
    logit_prior = np.log(params.prior) - np.log1p(-params.prior)
    upper = np.ones(K)
    for _ in range(params.bound_rounds):
        settled = (upper < params.sparse_epsilon) & (upper <= rho0)
        r = np.where(valid, np.maximum(rho0, upper)[L], 0.0)
        t_min = front_transparency(r)
        b_min = np.empty_like(D)
        b = dbg.copy()
        for j in range(D.shape[1] - 1, -1, -1):
            b_min[:, j] = b
            b = b + np.minimum(0.0, r[:, j] * (D[:, j] - b))
        x = D - b_min
        contrib = np.where(x >= 0, x, t_min * x)
        bound = np.bincount(L[valid], weights=contrib[valid], minlength=K)
        upper = np.where(settled, upper, np.minimum(upper, sigmoid(logit_prior + bound - behind)))
    return upper


def mean_field(depth_m, geom: Geometry, bg: Background, params: ModelParams, start=None,
               trace: list | None = None):
    """Mean-field inference of MODEL.md in exclusive form, with damping and soft threshold, for
    one camera (mean_field_rig with one camera; see there)."""
    return mean_field_rig([depth_m], [geom], [bg], params, start, trace)


def rig_lists(depths, geoms: list[Geometry], bgs: list[Background], params: ModelParams):
    """A rig's per-pixel lists: every camera's (pixel_lists) one after the other, padded to the
    longest list (a rig's pixels are its cameras' pixels together: the evidence sums of eq. 10
    add over them). Returns (valid, L, D, dbg, entries) as pixel_lists does."""
    parts = [pixel_lists(d, g, b, params) for d, g, b in zip(depths, geoms, bgs)]
    if len(parts) == 1:
        return parts[0]
    width = max(p[1].shape[1] for p in parts)

    def pad(a, fill):
        return np.pad(a, ((0, 0), (0, width - a.shape[1])), constant_values=fill)

    return (np.concatenate([pad(p[0], False) for p in parts]), np.concatenate([pad(p[1], 0) for p in parts]),
            np.concatenate([pad(p[2], 0.0) for p in parts]), np.concatenate([p[3] for p in parts]),
            sum(p[4] for p in parts))


def mean_field_rig(depths, geoms: list[Geometry], bgs: list[Background], params: ModelParams, start=None,
                   trace: list | None = None):
    """Mean-field inference of MODEL.md in exclusive form, with damping and soft threshold, over
    one grid seen by a rig of cameras (lists: depths, geoms, bgs, one a camera, the geometries
    over the same locations): each location's evidence sums its entries over every camera's
    pixels, its readings behind over every camera, its |S_k| (area) over the cameras, and the
    top band's counts over the cameras; the update, the prior and the threshold act once per
    location.

    With params.sparse_epsilon > 0, the pruning bound first (evidence_bound: a location whose
    bound is below epsilon leaves every list for good, rho = 0; a location in no list is idle:
    its rho_new is the prior whatever the others do, and it keeps its start), then the sparse
    iterations of kernels.sparse: full passes at params.full_pass(it), after which a location
    whose rho and rho_new are both below epsilon is dead until a later full pass; in between
    only live locations are in the lists (dead ones count as rho = 0, transparent) and only
    they move. With params.exclusion > 0 each location's evidence loses exclusion x the sum
    over its neighbours within exclusion_radius of max(0, rho - gate) / (1 - gate), from the
    rho before the update (kernels.mean_field.exclusion_pass). `start`: initial rho
    (warm start) instead of the prior. `trace`: a list that receives every iteration's
    rho_new (K,).

    Returns:
        dict with rho (K,), rho_star (K,), evidence_share e_k (K,), iterations, entries, live,
        pruned (locations the bound removed).
    """
    geom = geoms[0]
    K = len(geom.rect)
    valid, L, D, dbg, entries = rig_lists(depths, geoms, bgs, params)
    logit_prior = np.log(params.prior) - np.log1p(-params.prior)
    rho = np.full(K, params.prior) if start is None else np.array(start, dtype=np.float64)
    kept = np.ones(K, bool)
    behind = 0.0  # the readings behind, over every camera (the bound subtracts them too)
    if params.behind_cost > 0:
        listed = np.bincount(L[valid], minlength=K) > 0
        behind = params.behind_cost * sum(behind_count(d, g, params, listed) for d, g in zip(depths, geoms))
    if params.sparse_epsilon > 0 and params.bound_rounds > 0:
        kept = evidence_bound(valid, L, D, dbg, rho, params, behind) >= params.sparse_epsilon
        rho = np.where(kept, rho, 0.0)  # pruned: rho_new < epsilon at every iteration
        valid = valid & kept[L]
    pruned = int((~kept).sum())
    listed = np.bincount(L[valid], minlength=K) > 0  # in some list (after the bound)
    if params.sparse_epsilon > 0:  # in no list (idle): rho_new is the prior; left at its start
        kept = kept & listed
    live = kept.copy()
    if params.exclusion > 0:  # each location's neighbours within exclusion_radius
        start, neighbours = neighbour_lists(geom.locations, params.exclusion_radius)
        owner = np.repeat(np.arange(K), np.diff(start))
        neighbours = neighbours[:len(owner)]
    iterations = 0
    streak = np.zeros(K, np.int64)  # signed run of same-side targets (damping_streak)
    for it in range(params.max_iterations):
        full = params.full_pass(it)
        use = valid & (full | live[L])
        evidence = evidence_sums(use, L, D, dbg, np.where(use, rho[L], 0.0), K)
        if params.exclusion > 0:  # neighbours above the gate push a location down
            over = np.maximum(rho - params.exclusion_gate, 0.0) / (1.0 - params.exclusion_gate)
            # (not in place: bincount of an empty selection is an integer array)
            evidence = evidence - params.exclusion * np.bincount(owner, weights=over[neighbours], minlength=K)
        rho_new = sigmoid(logit_prior + evidence - behind)
        if trace is not None:
            trace.append(rho_new)
        moving = kept if full else live
        diff = float(np.max(np.abs(rho_new - rho)[moving])) if moving.any() else 0.0
        lam = params.damping_at(it)
        if params.damping_streak > 1.0:  # per-location lambda (ModelParams.damping_streak)
            step = np.where(rho_new < rho, -1, 1)
            run = np.where(streak * step > 0, np.abs(streak), 0)
            lam = np.maximum(lam, np.minimum(params.damping_streak_max, lam * params.damping_streak ** run))
            streak = np.where(moving, step * (run + 1), streak)
        damped = (1.0 - lam) * rho + lam * rho_new
        if full:
            live = kept & ((rho_new >= params.sparse_epsilon) | (damped >= params.sparse_epsilon))
            rho = np.where(kept, damped, rho)  # pruned ones hold 0, idle ones their start
            drop = live & (rho_new < params.sparse_epsilon) & (damped < params.sparse_drop)
            live, rho = live & ~drop, np.where(drop, 0.0, rho)  # (ModelParams.sparse_drop)
        else:
            rho = np.where(live, damped, rho)
        iterations = it + 1
        if (it + 1) % params.check_every == 0 and diff < params.tolerance:
            break
    rho_star, share, counts = rig_threshold(depths, geoms, bgs, params, rho, valid, L)
    support, against, hidden, missing, seen = counts
    return dict(rho=rho, rho_star=rho_star, evidence_share=share, iterations=iterations,
                entries=entries, live=int(live.sum()), pruned=pruned, top_support=support, top_against=against,
                top_hidden=hidden, top_missing=missing, top_seen=seen)


def rig_threshold(depths, geoms: list[Geometry], bgs: list[Background], params: ModelParams, rho, valid, L):
    """After the iterations (mean_field_rig): each location's evidence share e_k over every
    camera's pixels (the transparency sums, over |S_k| summed over the cameras, or over the
    unhidden pixels' counts with share_of 'unhidden'), rho* of eq. 13 and the top band's
    factor on the cameras' summed counts (with the shorter bands). Returns (rho_star, share,
    the top band's five counts)."""
    geom = geoms[0]
    K = len(geom.rect)
    r = np.where(valid, rho[L], 0.0)
    T = front_transparency(r)
    tsum = np.bincount(L[valid], weights=T[valid], minlength=K)
    area = sum(g.area.astype(np.float64) for g in geoms)
    denominator = area
    if params.share_of == "unhidden":
        s_all, a_all, *_ = rig_bands(depths, geoms, bgs, params, rho, whole=True)
        denominator = np.where(s_all + a_all > 0, s_all + a_all, denominator)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(area > 0, tsum / denominator, 0.0)
    rho_star = np.where(area > 0, sigmoid(params.alpha * share + params.beta) * rho, 0.0)
    # the top band is counted where rho* can still reach TOP_MIN_RHO (its factor is <= 1)
    gate = rho if params.share_of == "unhidden" else rho_star
    counts = rig_bands(depths, geoms, bgs, params, gate)
    if params.top_support > 0 and geom.height > 0:
        for height in params.top_heights:  # shorter people: the band whose factor is larger
            shorter = rig_bands(depths, [g.shorter(height) for g in geoms], bgs, params, gate)
            seen = counts[4]
            better = (top_factor(*shorter, params, area) > top_factor(*counts, params, area)) & ~(
                band_out_of_view(seen, area, params))  # out of view: top_unseen decides
            counts = tuple(np.where(better, b, a) for a, b in zip(counts, shorter))
        rho_star = rho_star * top_factor(*counts, params, area)
        if params.top_unseen_share > 0:  # band out of view: the share of eq. 13 must reach this
            unseen = band_out_of_view(counts[4], area, params)
            rho_star = np.where(unseen, rho_star * sigmoid(params.top_slope * (share - params.top_unseen_share)),
                                rho_star)
    return rho_star, share, counts



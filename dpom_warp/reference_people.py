"""The NumPy reference of the people-only tests (engine/people.py's prior): the top band and its
factor, the readings behind a location's object, and a rig's bands summed over its cameras. The
tests' oracle only."""

from __future__ import annotations

import numpy as np

from .geometry import Geometry
from .model import BAND_ALL, MISSING_READ, TOP_MIN_RHO, Background, ModelParams
from .reference_pixels import kept_silhouette, log_outlier, object_sigma, reading_classes, sigmoid, silhouette, valid_reading

def band_out_of_view(seen, area, params: ModelParams):
    """Where a location's top band is out of view: counted (seen >= 0), with fewer than
    top_min_pixels, or fewer than top_unseen_part x |S_k| (area), of its pixels in the image
    (kernels.people.band_out_of_view)."""
    seen = np.asarray(seen)
    return (seen >= 0) & ((seen < params.top_min_pixels) | (seen < params.top_unseen_part * np.asarray(area)))


def top_factor(support, against, hidden, missing, seen, params: ModelParams, area):
    """The top-band factor of each location from its counts (top_band):
    sigmoid(top_slope (u - top_support)), u = (s + top_hidden f) / (s + a + f + top_missing m);
    1 with fewer than top_min_pixels judged in the band (read, or missing where top_missing >
    0), top_unseen where the band is out of view (band_out_of_view;
    kernels.people.top_factor)."""
    n = support + against + hidden + (missing if params.top_missing > 0 else 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (support + params.top_hidden * hidden) / (support + against + hidden + params.top_missing * missing)
        factor = np.where(n >= max(params.top_min_pixels, 1),
                          sigmoid(params.top_slope * (u - params.top_support)), 1.0)
    return np.where(band_out_of_view(seen, area, params), params.top_unseen, factor)


def top_band(depth_m, geom: Geometry, params: ModelParams, rho, bg: Background, whole=False):
    """The top-band test of the soft threshold (ModelParams.top_support): for each location
    with rho >= TOP_MIN_RHO (mean_field gives rho* before the test) of a standing box, the silhouette pixels with a reading whose
    object point lies between top_band x height and the height that pass the mask test
    (support), and of the others those that read beyond the object (against) and in front
    of it (hidden); `missing`: those without a reading where the object lies within z_max (it
    would be read there) and the background `bg` is mostly read (missing < MISSING_READ: not a
    sensor's dead region, where nothing is ever read). `whole`: the same counts over the whole silhouette, any grid (the
    unhidden share of ModelParams.share_of). Also `seen`: the band's pixels in the image,
    with a reading or not (-1 where not counted). Returns five (K,) arrays: support, against,
    hidden, missing, seen."""
    K = len(geom.rect)
    support, against, hidden, missing = (np.zeros(K, np.int64) for _ in range(4))
    seen = np.full(K, -1, np.int64)
    if geom.height <= 0 and not whole:
        return support, against, hidden, missing, seen
    z_img = np.asarray(depth_m, dtype=np.float64)
    lo, hi = (-BAND_ALL, BAND_ALL) if whole else (params.top_band * geom.height, geom.height)
    bg_read = np.asarray(bg.missing) < MISSING_READ
    for k in np.flatnonzero(np.asarray(rho) >= TOP_MIN_RHO):
        seen[k] = 0
        sil = silhouette(z_img, geom, k, params)
        if sil is None:
            continue
        (v0, u0), rays, z, mu, inlier = sil
        read = bg_read[v0:v0 + z.shape[0], u0:u0 + z.shape[1]]
        h = geom.centre[2] + mu * rays[..., 2]
        in_band = (mu > 0) & (h >= lo) & (h <= hi)
        seen[k] = np.sum(in_band)
        if params.top_sigmas > 0 and not whole:  # within top_sigmas sigma instead of the mask test
            _, var = geom.object_depth(k, rays)
            passes = np.abs(z - mu) <= params.top_sigmas * object_sigma(mu, params, var)
        else:
            passes = inlier > log_outlier(params)
        supports, behind, in_front = reading_classes(z, mu, passes, params)
        support[k] = np.sum(in_band & supports)
        against[k] = np.sum(in_band & behind)
        hidden[k] = np.sum(in_band & in_front)
        missing[k] = np.sum(in_band & ~valid_reading(z, params) & (mu <= params.z_max) & read)
    return support, against, hidden, missing, seen


def behind_evidence(depth_m, geom: Geometry, params: ModelParams, valid, L):
    """behind_cost x behind_count of every location in a list (pixel_lists' valid, L), the
    evidence the lists leave out: fixed for the frame, subtracted by every update and by the
    pruning bound (evidence_bound's `behind`); 0.0 without the cost."""
    if params.behind_cost <= 0:
        return 0.0
    listed = np.bincount(L[valid], minlength=len(geom.rect)) > 0
    return params.behind_cost * behind_count(depth_m, geom, params, listed)


def behind_count(depth_m, geom: Geometry, params: ModelParams, which, sils: dict | None = None):
    """For each location in `which` (bool (K,)), its silhouette pixels whose reading lies
    behind its object beyond the mask test (z > mu_ki and not in M_k: the object would hide
    them), counted in its core on the pixels whose row and column are multiples of
    behind_step (each standing for behind_step^2): in each such row the lattice pixels whose
    rays hit the solid run from column a to b, and those before a + behind_side (b - a) or
    after b - behind_side (b - a) are left out, as are object points below behind_low or above
    behind_high x the height (ground grids; kernels.people.behind_count). `sils`: some of
    their silhouettes (silhouettes()). Returns (K,) int64."""
    n = np.zeros(len(geom.rect), np.int64)
    z_img = np.asarray(depth_m, dtype=np.float64)
    low, high = ((params.behind_low * geom.height, params.behind_high * geom.height) if geom.height > 0
                 else (-BAND_ALL, BAND_ALL))
    for k in np.flatnonzero(which):
        sil = kept_silhouette(z_img, geom, k, params, sils)
        if sil is None:
            continue
        (v0, u0), rays, z, mu, inlier = sil
        s = params.behind_step  # the lattice: absolute rows and columns that are multiples of s
        rs, cs = slice((-v0) % s, None, s), slice((-u0) % s, None, s)
        rays, z, mu, inlier = rays[rs, cs], z[rs, cs], mu[rs, cs], inlier[rs, cs]
        if mu.size == 0:
            continue
        cols = u0 + np.arange((-u0) % s, (-u0) % s + mu.shape[1] * s, s).astype(np.float64)
        hit = mu > 0
        rows = hit.any(axis=1)
        first = cols[np.argmax(hit, axis=1)]
        last = cols[hit.shape[1] - 1 - np.argmax(hit[:, ::-1], axis=1)]
        trim = params.behind_side * (last - first)
        core = (cols >= (first + trim)[:, None]) & (cols <= (last - trim)[:, None]) & rows[:, None] & hit
        h = geom.centre[2] + mu * rays[..., 2]
        _, behind, _ = reading_classes(z, mu, inlier > log_outlier(params), params)
        n[k] = s * s * np.sum(core & (h >= low) & (h <= high) & behind)
    return n


def rig_bands(depths, geoms: list[Geometry], bgs: list[Background], params: ModelParams, gate, whole=False):
    """top_band's five counts summed over a rig's cameras (each location is gated once, by
    `gate`: `seen` is -1 where it is not counted, else the cameras' band pixels together)."""
    counts = [top_band(d, g, params, gate, b, whole) for d, g, b in zip(depths, geoms, bgs)]
    total = [sum(c[i] for c in counts) for i in range(4)]
    seen = np.where(counts[0][4] < 0, -1, sum(np.maximum(c[4], 0) for c in counts))
    return (*total, seen)

"""Masks M_k and Delta_ki (MODEL.md eq. 11-12), written into per-pixel lists.

One kernel serves both passes of the list build: with `fill == 0` it counts each pixel's
entries; with `fill == 1` it writes them at `offsets[pixel] + atomic cursor`. With
`background_occludes`, a location does not claim a pixel whose known background is clearly
in front of it.
"""

import warp as wp

from .pixel_model import GeometryArrays, PixelModel, f64, facing_plane_depth, gaussian_logpdf, is_reading
from .pixel_model import logaddexp, object_sigma


@wp.func
def hidden_by_background(pm: PixelModel, bg: wp.array2d(dtype=wp.float64), p: int, mu: wp.float64) -> bool:
    """The known background (pi_out < 1) lies clearly in front of the object's depth mu."""
    return pm.background_occludes == 1 and bg[p, 3] < f64(1.0) and bg[p, 0] + pm.occlusion_margin < mu


@wp.kernel(enable_backward=False)
def mask_entries(
    depth: wp.array2d(dtype=wp.float32),
    geo: GeometryArrays,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    fill: int,
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    capacity: int,
    entry_loc: wp.array(dtype=wp.int32),
    entry_mu: wp.array(dtype=wp.float32),
    entry_delta: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    r = geo.rect[k]
    width = depth.shape[1]
    n = geo.normal[k]
    plane = geo.plane[k]
    for v in range(r[1], r[3] + 1):
        for u in range(r[0], r[2] + 1):
            z = f64(depth[v, u])
            if is_reading(pm, z):
                mu = facing_plane_depth(geo.rays[v, u], n, plane)
                if mu > f64(0.0):
                    inlier = pm.log_inlier_weight + gaussian_logpdf(z, mu, object_sigma(pm, mu))
                    p = v * width + u
                    if inlier > pm.log_outlier and not hidden_by_background(pm, bg, p, mu):
                        slot = wp.atomic_add(counts, p, 1)
                        if fill == 1:
                            e = offsets[p] + slot
                            if e < capacity:
                                entry_loc[e] = k
                                entry_mu[e] = wp.float32(mu)
                                entry_delta[e] = wp.float32(pm.log_reading + logaddexp(pm.log_outlier, inlier))

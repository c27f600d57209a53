"""Pixel distributions (MODEL.md eq. 11) and the structs that carry geometry and parameters."""

import warp as wp

f64 = wp.float64
LOG_SQRT_2PI = wp.constant(wp.float64(0.91893853320467274178))


@wp.struct
class GeometryArrays:
    """Per-pixel rays and per-location silhouettes and facing planes (see geometry.Geometry)."""

    rays: wp.array2d(dtype=wp.vec3d)
    rect: wp.array(dtype=wp.vec4i)
    normal: wp.array(dtype=wp.vec3d)
    plane: wp.array(dtype=wp.float64)


@wp.struct
class PixelModel:
    """Object pixel model and sensor range, as logs where the kernels use logs."""

    sigma_object2: wp.float64  # sigma_obj^2, m^2
    noise_a: wp.float64  # sensor sigma(z) = a + b z^2, metres
    noise_b: wp.float64
    log_outlier: wp.float64  # log(pi_out * U(z)) = log(pi_out) - log(z_max)
    log_inlier_weight: wp.float64  # log(1 - pi_out)
    log_reading: wp.float64  # log(1 - pi_inf) of objects
    z_max: wp.float64
    outlier_prob: wp.float64
    missing_prob: wp.float64
    missing_clip: wp.float64
    background_occludes: int  # 1: the known background in front of a location hides it
    occlusion_margin: wp.float64


@wp.func
def logaddexp(a: wp.float64, b: wp.float64) -> wp.float64:
    m = wp.max(a, b)
    return m + wp.log(wp.exp(a - m) + wp.exp(b - m))


@wp.func
def gaussian_logpdf(z: wp.float64, mu: wp.float64, sigma: wp.float64) -> wp.float64:
    r = (z - mu) / sigma
    return f64(-0.5) * r * r - wp.log(sigma) - LOG_SQRT_2PI


@wp.func
def sensor_sigma(pm: PixelModel, z: wp.float64) -> wp.float64:
    return pm.noise_a + pm.noise_b * z * z


@wp.func
def object_sigma(pm: PixelModel, mu: wp.float64) -> wp.float64:
    s = sensor_sigma(pm, mu)
    return wp.sqrt(pm.sigma_object2 + s * s)


@wp.func
def object_log_inlier(pm: PixelModel, z: wp.float64, mu: wp.float64) -> wp.float64:
    """log((1 - pi_out) N(z | mu, s^2)) of an object at depth mu; the mask test (eq. 12) is
    that it beats pm.log_outlier."""
    return pm.log_inlier_weight + gaussian_logpdf(z, mu, object_sigma(pm, mu))


@wp.func
def is_reading(pm: PixelModel, z: wp.float64) -> bool:
    return z > f64(0.0) and z <= pm.z_max


@wp.func
def facing_plane_depth(d: wp.vec3d, n: wp.vec3d, plane: wp.float64) -> wp.float64:
    """z-depth where ray d meets the plane n . (X - P) = 0; -1 if it never does in front."""
    denom = wp.dot(n, d)
    if denom < f64(-1.0e-12):
        return plane / denom
    return f64(-1.0)

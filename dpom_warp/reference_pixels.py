"""The NumPy reference's per-pixel model (MODEL.md, eq. 11): a reading's log densities, the
object's depth spread, a location's silhouette and what a reading says of its object. Shared by
the reference's lists and mean field (reference.py) and its people tests (reference_people.py);
like them, the tests' oracle only."""

from __future__ import annotations

import numpy as np

from .geometry import Geometry
from .model import ModelParams

LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)


def gaussian_logpdf(z, mu, sigma):
    return -0.5 * ((z - mu) / sigma) ** 2 - np.log(sigma) - LOG_SQRT_2PI


def log_theta(z, mu, sigma, missing, outlier, z_max):
    """Delta = log theta(z) of eq. 11 for a reading z (metres) in (0, z_max]."""
    with np.errstate(divide="ignore"):
        return np.log1p(-missing) + np.logaddexp(
            np.log(outlier) - np.log(z_max), np.log1p(-outlier) + gaussian_logpdf(z, mu, sigma))


def valid_reading(depth_m, params: ModelParams):
    return (depth_m > 0) & (depth_m <= params.z_max)


def object_sigma(mu, params: ModelParams, shape_var=0.0):
    """sqrt(sigma_obj^2 + var + sigma_sensor(mu)^2): `shape_var` is what the object's shape
    adds (geometry.Geometry.object_depth; 0 on a facing plane)."""
    return np.sqrt(params.sigma_object ** 2 + shape_var + params.sensor_sigma(mu) ** 2)


def log_outlier(params: ModelParams):
    """log(pi_out U(z)): the outlier term the mask test compares with."""
    return np.log(params.outlier_prob) - np.log(params.z_max)


def silhouette(z_img, geom: Geometry, k: int, params: ModelParams):
    """Location k's silhouette rectangle: ((v0, u0), rays, readings z, object depth mu
    (-1 where the ray misses the facing plane or the solid), log inlier term of the object at
    mu), or None when it has no silhouette."""
    u0, v0, u1, v1 = (int(x) for x in geom.rect[k])
    if u1 < u0 or v1 < v0:
        return None
    rays = geom.rays[v0:v1 + 1, u0:u1 + 1]
    z = z_img[v0:v1 + 1, u0:u1 + 1]
    mu, var = geom.object_depth(k, rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        inlier = np.log1p(-params.outlier_prob) + gaussian_logpdf(z, mu, object_sigma(mu, params, var))
    return (v0, u0), rays, z, mu, inlier


def silhouettes(z_img, geom: Geometry, which, params: ModelParams, sils: dict | None = None) -> dict:
    """{k: silhouette(z_img, geom, k, params)} for the locations `which` (indices), those in
    `sils` (the same frame's, computed before) taken from it; `sils` receives the others."""
    sils = {} if sils is None else sils
    for k in which:
        if int(k) not in sils:
            sils[int(k)] = silhouette(z_img, geom, int(k), params)
    return sils


def kept_silhouette(z_img, geom: Geometry, k: int, params: ModelParams, sils: dict | None):
    """silhouette(z_img, geom, k, params), taken from `sils` (silhouettes()) where it holds k."""
    return sils[k] if sils is not None and k in sils else silhouette(z_img, geom, k, params)


def sigmoid(x):
    x = np.asarray(x, dtype=np.float64)
    e = np.exp(-np.abs(x))
    return np.where(x >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


def reading_classes(z, mu, passes, params: ModelParams):
    """What each reading z says of an object at depth mu, given whether it passes the test:
    (supports, behind: z > mu, the object would hide it, in front: hidden by something nearer),
    three boolean arrays, all False without a reading (kernels.people.reading_class)."""
    valid = valid_reading(z, params)
    return valid & passes, valid & ~passes & (z > mu), valid & ~passes & (z <= mu)

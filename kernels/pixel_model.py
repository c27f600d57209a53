"""Pixel distributions (MODEL.md eq. 11) and the structs that carry geometry and parameters."""

import warp as wp

f64 = wp.float64
LOG_SQRT_2PI = wp.constant(wp.float64(0.91893853320467274178))


# the object's shapes (dpom_warp.shapes: SHAPE_PLANE, SHAPE_SOLID, the same codes): which branch of
# object_depth gives a ray's depth
SHAPE_PLANE = wp.constant(0)
SHAPE_SOLID = wp.constant(1)
# the shape's sizes in GeometryArrays (shapes.Shape.kernel_fields; 0 where a shape has none)
SHAPE_FIELDS = ("body_radius", "head_radius", "bottom", "shoulder", "top", "height_spread", "leg_radius", "hip",
                "depth_radius")


@wp.struct
class GeometryArrays:
    """Per-pixel rays and per-location silhouettes and facing planes, and the object's shape:
    which Warp function gives a ray's depth (`shape`, object_depth) and its sizes (those of
    shapes.Solid; 0 where a shape has none). See geometry.Geometry and shapes.py."""

    rays: wp.array2d(dtype=wp.vec3d)
    rect: wp.array(dtype=wp.vec4i)
    normal: wp.array(dtype=wp.vec3d)
    plane: wp.array(dtype=wp.float64)
    location: wp.array(dtype=wp.vec3d)
    centre: wp.vec3d  # camera centre
    shape: int  # SHAPE_PLANE: facing planes; SHAPE_SOLID: the solid below
    body_radius: wp.float64
    head_radius: wp.float64  # 0: no head
    bottom: wp.float64  # heights relative to the location centre
    shoulder: wp.float64
    top: wp.float64
    height_spread: wp.float64
    leg_radius: wp.float64  # the legs, from bottom to hip (hip = bottom: none)
    hip: wp.float64
    depth_radius: wp.float64  # the body's semi-axis along the line of sight (= body_radius: a circle)


@wp.struct
class PixelLists:
    """Per pixel of a batch, its list of entries in depth order (kernels.masks): pixel p's are
    entries offsets[p] to offsets[p] + counts[p] - 1 of loc (the location), mu (the object
    depth, float32) and delta (Delta_ki, eq. 12). The lists compacted to the live locations
    (kernels.sparse) are the same struct, without mu (empty)."""

    offsets: wp.array(dtype=wp.int32)
    counts: wp.array(dtype=wp.int32)
    loc: wp.array(dtype=wp.int32)
    mu: wp.array(dtype=wp.float32)
    delta: wp.array(dtype=wp.float32)


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
def gaussian_logpdf_from_log(z: wp.float64, mu: wp.float64, sigma: wp.float64, log_sigma: wp.float64) -> wp.float64:
    """gaussian_logpdf with log(sigma) given (kernels.masks' pixel table stores it)."""
    r = (z - mu) / sigma
    return f64(-0.5) * r * r - log_sigma - LOG_SQRT_2PI


@wp.func
def gaussian_logpdf(z: wp.float64, mu: wp.float64, sigma: wp.float64) -> wp.float64:
    return gaussian_logpdf_from_log(z, mu, sigma, wp.log(sigma))


@wp.func
def sensor_sigma(pm: PixelModel, z: wp.float64) -> wp.float64:
    return pm.noise_a + pm.noise_b * z * z


@wp.func
def object_sigma(pm: PixelModel, mu: wp.float64, shape_var: wp.float64) -> wp.float64:
    s = sensor_sigma(pm, mu)
    return wp.sqrt(pm.sigma_object2 + shape_var + s * s)


@wp.func
def object_log_inlier(pm: PixelModel, z: wp.float64, mu: wp.float64, shape_var: wp.float64) -> wp.float64:
    """log((1 - pi_out) N(z | mu, s^2)) of an object at depth mu whose shape adds shape_var
    to the variance; the mask test (eq. 12) is that it beats pm.log_outlier."""
    return pm.log_inlier_weight + gaussian_logpdf(z, mu, object_sigma(pm, mu, shape_var))


@wp.func
def object_delta(pm: PixelModel, inlier: wp.float64) -> wp.float64:
    """Delta of a mask entry (eq. 11), log(1 - pi_inf) + logaddexp(log_outlier, inlier), for an
    inlier above log_outlier (the mask test passed): logaddexp with its larger term known,
    exp(0) = 1 not computed (the same bits)."""
    return pm.log_reading + (inlier + wp.log(wp.exp(pm.log_outlier - inlier) + f64(1.0)))


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


MIN_TOP_SLOPE = wp.constant(wp.float64(0.3))  # shapes.MIN_TOP_SLOPE


@wp.func
def cylinder_entry(c: wp.vec3d, d: wp.vec3d, axis: wp.vec3d, radius: wp.float64, z0: wp.float64,
                   z1: wp.float64, spread: wp.float64, depth_radius: wp.float64) -> wp.vec2d:
    """(z-depth where ray d from c enters the vertical cylinder of `radius` about axis
    (x, y) between heights z0 and z1, -1 on a miss; the variance of that depth: through a
    flat top or bottom (spread / max(|d_z|, MIN_TOP_SLOPE |d|))^2, through the side 0). Its
    cross-section is the ellipse facing the camera of semi-axes `radius` across and
    `depth_radius` along the line from the axis to the camera (a circle: depth_radius =
    radius, or the camera right above the axis). geometry.cylinder_entry."""
    ox = c[0] - axis[0]
    oy = c[1] - axis[1]
    dist = wp.sqrt(ox * ox + oy * oy)
    ux = f64(1.0)
    uy = f64(0.0)
    rd = depth_radius
    if dist > f64(1.0e-9):
        ux = ox / dist
        uy = oy / dist
    else:
        rd = radius
    du = (d[0] * ux + d[1] * uy) / rd  # the ray in the ellipse's frame scaled to the unit circle
    dv = (d[1] * ux - d[0] * uy) / radius
    ou = dist / rd  # the camera there (v = 0)
    a = d[0] * d[0] + d[1] * d[1]
    a2 = du * du + dv * dv
    b = ou * du
    q = ou * ou - f64(1.0)
    disc = b * b - a2 * q
    t = f64(-1.0)
    var = f64(0.0)
    if q > f64(0.0) and a > f64(1.0e-18) and disc >= f64(0.0):
        ts = (-b - wp.sqrt(disc)) / a2
        hs = c[2] + ts * d[2]
        if ts > f64(0.0) and hs >= z0 and hs <= z1:
            t = ts
    if wp.abs(d[2]) > f64(1.0e-18):
        slope = wp.max(wp.abs(d[2]), MIN_TOP_SLOPE * wp.sqrt(a + d[2] * d[2]))
        zc = z1
        facing = c[2] > z1
        for side in range(2):
            if side == 1:
                zc = z0
                facing = c[2] < z0
            if facing:
                tc = (zc - c[2]) / d[2]
                pu = ou + tc * du
                pv = tc * dv
                if tc > f64(0.0) and pu * pu + pv * pv <= f64(1.0) and (t < f64(0.0) or tc < t):
                    t = tc
                    var = (spread / slope) * (spread / slope)
    return wp.vec2d(t, var)


@wp.func
def object_depth(geo: GeometryArrays, k: int, d: wp.vec3d) -> wp.vec2d:
    """(depth pixel ray d expects of location k, -1: not the object's; variance the shape
    adds): the facing plane's (variance 0), or the entry into the solid, the nearest of legs,
    body and head (geometry.Geometry.object_depth)."""
    if geo.shape == SHAPE_PLANE:
        return wp.vec2d(facing_plane_depth(d, geo.normal[k], geo.plane[k]), f64(0.0))
    p = geo.location[k]
    body = cylinder_entry(geo.centre, d, p, geo.body_radius, p[2] + geo.hip, p[2] + geo.shoulder,
                          geo.height_spread, geo.depth_radius)
    if geo.hip > geo.bottom:
        legs = cylinder_entry(geo.centre, d, p, geo.leg_radius, p[2] + geo.bottom, p[2] + geo.hip,
                              geo.height_spread, geo.leg_radius)
        if legs[0] > f64(0.0) and (body[0] < f64(0.0) or legs[0] < body[0]):
            body = legs
    if geo.head_radius > f64(0.0) and geo.top > geo.shoulder:
        head = cylinder_entry(geo.centre, d, p, geo.head_radius, p[2] + geo.shoulder, p[2] + geo.top,
                              geo.height_spread, geo.head_radius)
        if head[0] > f64(0.0) and (body[0] < f64(0.0) or head[0] < body[0]):
            return head
    return body

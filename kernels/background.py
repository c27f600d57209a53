"""Background pixel distributions theta_bg,i (MODEL.md) and their Delta_bg,i.

Parameters per pixel live in a (B*H*W, 4) float64 array, one block per frame of a batch:
mu, sigma, pi_inf, pi_out (pi_out = 1 is a broad, uniform distribution over the sensor range).
"""

import warp as wp

from .pixel_model import PixelModel, f64, gaussian_logpdf_from_log, is_reading, logaddexp, sensor_sigma


@wp.func
def background_logs(pm: PixelModel, sigma: wp.float64, missing: wp.float64, outlier: wp.float64) -> wp.vec4d:
    """The logarithms log theta_bg,i takes of a pixel's background: log(1 - pi_out),
    log(sigma), log(1 - pi_inf), log(pi_out) - log(z_max); the same from frame to frame while
    the background is (background_delta keeps them)."""
    return wp.vec4d(wp.log(f64(1.0) - outlier), wp.log(sigma), wp.log(f64(1.0) - missing),
                    wp.log(outlier) - wp.log(pm.z_max))


@wp.func
def log_theta_from_logs(z: wp.float64, mu: wp.float64, sigma: wp.float64, logs: wp.vec4d) -> wp.float64:
    """log theta_bg,i(z) (MODEL.md): log(1 - pi_inf) + logaddexp(log(pi_out / z_max),
    log(1 - pi_out) + log N(z | mu, sigma^2)), from the pixel's background_logs."""
    gauss = logs[0] + gaussian_logpdf_from_log(z, mu, sigma, logs[1])
    return logs[2] + logaddexp(logs[3], gauss)


@wp.func
def set_background(bg: wp.array2d(dtype=wp.float64), p: int, mu: wp.float64, sigma: wp.float64,
                   missing: wp.float64, outlier: wp.float64):
    bg[p, 0] = mu
    bg[p, 1] = sigma
    bg[p, 2] = missing
    bg[p, 3] = outlier


@wp.func
def set_broad(bg: wp.array2d(dtype=wp.float64), p: int, missing: wp.float64):
    """No idea of the depth: uniform over the sensor range (pi_out = 1)."""
    set_background(bg, p, f64(0.0), f64(1.0), missing, f64(1.0))


@wp.kernel(enable_backward=False)
def background_delta(
    depth: wp.array3d(dtype=wp.float32),
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    fresh: int,
    logs: wp.array(dtype=wp.vec4d),
    delta_bg: wp.array(dtype=wp.float64),
):
    """Delta_bg,i = log theta_bg,i(z_i) of every pixel's reading (0 without one). The
    background's logarithms (background_logs) are kept in `logs`: written with `fresh` (the
    background changed since the last frame), read otherwise: the same values, without four
    logarithms a pixel a frame."""
    b, v, u = wp.tid()
    p = (b * depth.shape[1] + v) * depth.shape[2] + u
    if fresh != 0:
        logs[p] = background_logs(pm, bg[p, 1], bg[p, 2], bg[p, 3])
    z = f64(depth[b, v, u])
    if is_reading(pm, z):
        delta_bg[p] = log_theta_from_logs(z, bg[p, 0], bg[p, 1], logs[p])
    else:
        delta_bg[p] = f64(0.0)


@wp.kernel(enable_backward=False)
def floor_background(
    rays: wp.array2d(dtype=wp.vec3d),
    centre: wp.vec3d,
    depth: wp.array3d(dtype=wp.float32),
    bounds: wp.array(dtype=wp.float64),
    outside_is_static: int,
    pm: PixelModel,
    where: wp.array(dtype=wp.int32),
    bg: wp.array2d(dtype=wp.float64),
):
    """Floor-only background, at the pixels with where[v * W + u] = 1 (all of them, or those
    an auto background left to it): the ray's hit on z = 0 within range, else broad; with
    `outside_is_static`, a reading whose point no object box can reach is background there."""
    b, v, u = wp.tid()
    if where[v * rays.shape[1] + u] == 0:
        return
    p = (b * rays.shape[0] + v) * rays.shape[1] + u
    d = rays[v, u]
    t = f64(-1.0)
    if d[2] < f64(-1.0e-12):
        t = -centre[2] / d[2]
    z = f64(depth[b, v, u])
    if outside_is_static == 1 and is_reading(pm, z):
        x = centre + z * d
        if x[0] < bounds[0] or x[0] > bounds[1] or x[1] < bounds[2] or x[1] > bounds[3] or x[2] > bounds[5]:
            t = z
    if t > f64(0.0) and t <= pm.z_max:
        set_background(bg, p, t, sensor_sigma(pm, t), pm.missing_prob, pm.outlier_prob)
    else:
        set_broad(bg, p, pm.missing_prob)


@wp.func
def sort_row(a: wp.array2d(dtype=wp.float64), p: int, n: int):
    for i in range(1, n):
        x = a[p, i]
        j = i - 1
        while j >= 0 and a[p, j] > x:
            a[p, j + 1] = a[p, j]
            j -= 1
        a[p, j + 1] = x


@wp.func
def sorted_median(a: wp.array2d(dtype=wp.float64), p: int, n: int) -> wp.float64:
    h = n / 2
    if n % 2 == 1:
        return a[p, h]
    return f64(0.5) * (a[p, h - 1] + a[p, h])


@wp.kernel(enable_backward=False)
def background_from_frames(
    frames: wp.array3d(dtype=wp.float32),
    pm: PixelModel,
    scratch: wp.array2d(dtype=wp.float64),
    copies: int,
    bg: wp.array2d(dtype=wp.float64),
):
    """mu = median of readings, sigma = max(1.4826 MAD, sensor noise), pi_inf = missing share;
    written into the first `copies` blocks of bg (the frames of a batch share it)."""
    v, u = wp.tid()
    n_frames = frames.shape[0]
    p = v * frames.shape[2] + u
    n = int(0)
    for f in range(n_frames):
        z = f64(frames[f, v, u])
        if is_reading(pm, z):
            scratch[p, n] = z
            n += 1
    missing = wp.clamp(f64(1.0) - f64(n) / f64(n_frames), pm.missing_clip, f64(1.0) - pm.missing_clip)
    pixels = frames.shape[1] * frames.shape[2]
    if n == 0:
        for c in range(copies):
            set_broad(bg, c * pixels + p, missing)
        return
    sort_row(scratch, p, n)
    mu = sorted_median(scratch, p, n)
    for i in range(n):
        scratch[p, i] = wp.abs(scratch[p, i] - mu)
    sort_row(scratch, p, n)
    sigma = wp.max(f64(1.4826) * sorted_median(scratch, p, n), sensor_sigma(pm, mu))
    for c in range(copies):
        set_background(bg, c * pixels + p, mu, sigma, missing, pm.outlier_prob)


@wp.kernel(enable_backward=False)
def cluster_frames(
    frames: wp.array3d(dtype=wp.float32),
    pm: PixelModel,
    sigmas: wp.float64,
    floor: wp.float64,
    count: wp.array2d(dtype=wp.int32),
    mean: wp.array2d(dtype=wp.float64),
    m2: wp.array2d(dtype=wp.float64),
    n_read: wp.array(dtype=wp.int32),
):
    """`input.background: auto`, streamed: each pixel's readings of `frames`, in order, join
    the nearest of its clusters (count, running mean, sum of squared deviations; Welford)
    when within sigmas * sensor sigma + floor of its mean, else start one in the first free
    slot or in place of the smallest other than the farthest (of equals, the nearest): people
    come and go in front of the surface that is the background, which may show rarely and
    must not be pushed out by them. One thread per pixel; the state persists across calls."""
    v, u = wp.tid()
    p = v * frames.shape[2] + u
    slots = count.shape[1]
    for f in range(frames.shape[0]):
        z = f64(frames[f, v, u])
        if is_reading(pm, z):
            n_read[p] = n_read[p] + 1
            best = int(-1)
            best_d = f64(1.0e300)  # (Warp: loop-mutated variables are declared dynamic)
            for s in range(slots):
                if count[p, s] > 0:
                    d = wp.abs(z - mean[p, s])
                    if d < best_d:
                        best = s
                        best_d = d
            join = False
            if best >= 0:
                join = best_d <= sigmas * sensor_sigma(pm, mean[p, best]) + floor
            if join:
                c = count[p, best] + 1
                d = z - mean[p, best]
                m = mean[p, best] + d / f64(c)
                m2[p, best] = m2[p, best] + d * (z - m)
                mean[p, best] = m
                count[p, best] = c
            else:
                slot = int(-1)
                far = int(0)
                for s in range(slots):
                    if slot < 0 and count[p, s] == 0:
                        slot = s
                    if mean[p, s] > mean[p, far]:
                        far = s
                if slot < 0:  # full: the smallest, never the farthest (when there is a choice)
                    smallest = int(-1)
                    for s in range(slots):
                        if s != far or slots == 1:
                            if smallest < 0:
                                smallest = s
                            elif count[p, s] < count[p, smallest] or (
                                    count[p, s] == count[p, smallest] and mean[p, s] < mean[p, smallest]):
                                smallest = s
                    slot = smallest
                count[p, slot] = 1
                mean[p, slot] = z
                m2[p, slot] = f64(0.0)


@wp.kernel(enable_backward=False)
def cluster_background(
    count: wp.array2d(dtype=wp.int32),
    mean: wp.array2d(dtype=wp.float64),
    m2: wp.array2d(dtype=wp.float64),
    n_read: wp.array(dtype=wp.int32),
    n_frames: int,
    min_frames: int,
    min_share: wp.float64,
    pm: PixelModel,
    bg: wp.array2d(dtype=wp.float64),
    fallback: wp.array(dtype=wp.int32),
):
    """The background of each pixel from its clusters (cluster_frames): the farthest holding
    at least min_share of the frames; else broad where readings are missing in at least
    min_share of the frames; else (and with fewer than min_frames frames) fallback = 1, the
    floor-only model's pixel."""
    p = wp.tid()
    need = min_share * f64(n_frames)
    pick = int(-1)
    for s in range(count.shape[1]):
        if f64(count[p, s]) >= need:
            if pick < 0:
                pick = s
            elif mean[p, s] > mean[p, pick]:
                pick = s
    gaps = n_frames - n_read[p]
    clip = pm.missing_clip
    fallback[p] = 0
    if n_frames >= min_frames and pick >= 0:
        c = count[p, pick]
        mu = mean[p, pick]
        spread = f64(0.0)
        if c > 1:
            spread = wp.sqrt(m2[p, pick] / f64(c - 1))
        missing = wp.clamp(f64(gaps) / f64(wp.max(gaps + c, 1)), clip, f64(1.0) - clip)
        set_background(bg, p, mu, wp.max(spread, sensor_sigma(pm, mu)), missing, pm.outlier_prob)
        return
    missing = wp.clamp(f64(gaps) / f64(wp.max(n_frames, 1)), clip, f64(1.0) - clip)
    set_broad(bg, p, missing)
    if n_frames < min_frames or f64(gaps) < need:
        fallback[p] = 1

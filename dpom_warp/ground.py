"""The floor plane from depth frames, with Open3D: back-projection, RANSAC plane segmentation,
a least-squares refinement, and the camera pose in the project's world frame.

World frame built from the plane: z up (the floor normal), floor at z = 0, origin on the
floor right below the camera, y = the camera's forward direction projected on the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import Field, model_validator

from ._open3d import o3d

from .geometry import Camera
from .planes import least_squares_plane, segment_plane
from .values import Int, Node, Num, Pair, Up, _fail


class GroundFitError(ValueError):
    """No floor plane could be found; the message says why in one line."""


class GroundOptions(Node):  # the config's `camera.ground` section (config.camera adds its frames)
    """How to look for the floor.

    Attributes:
        up: the prior for "up" in the camera frame (OpenCV: -y is up in the image), or "auto":
            any floor that a camera pitched from level to straight down would see (see
            `fit_ground`).
        max_angle_deg: a floor candidate's normal is at most this far from `up` (with "auto":
            the largest roll, the in-image direction of the floor normal from the image's up).
        distance_threshold: RANSAC inlier distance, metres.
        depth_max: points farther than this are not used (noise grows with depth), metres.
        min_inliers: a floor candidate needs at least this many (downsampled) points.
        max_planes: how many planes to peel off the cloud, largest first.
        voxel: voxel size of the downsampling before RANSAC, metres.
        stride: use every `stride`-th pixel in each direction.
        noise: (a, b) of the depth noise sigma(z) = a + b z^2 used by the refinement, metres.
    """

    up: Up = Field(
        "auto", description="up direction in the camera frame (the floor normal's prior); "
                            "auto: the floor of any camera from level to looking straight "
                            "down (a recording's accelerometer gives it where it has one)")
    max_angle_deg: Num = Field(45.0, gt=0, le=90,
                               description="largest angle between the floor normal and `up` (auto: the "
                                           "largest roll)")
    distance_threshold: Num = Field(0.03, gt=0, description="RANSAC inlier distance, metres")
    depth_max: Num = Field(6.0, gt=0, description="readings beyond are not used, metres")
    min_inliers: Int = Field(300, ge=3, description="a floor candidate needs this many downsampled points")
    max_planes: Int = Field(6, ge=1, description="planes peeled off, largest first")
    voxel: Num = Field(0.04, gt=0, description="downsampling voxel, metres")
    stride: Int = Field(2, ge=1, description="every stride-th pixel")
    noise: Pair = Field((0.002, 0.0015), description="depth noise a + b z^2 of the refinement, metres")

    @model_validator(mode="after")
    def _up(self):
        if not isinstance(self.up, str) and np.linalg.norm(self.up) == 0:
            raise _fail(f"expected a non-zero direction, found {list(self.up)}", "up")
        return self


@dataclass(frozen=True)
class GroundFit:
    """The fitted floor and the camera pose it implies.

    Attributes:
        normal: unit floor normal in the camera frame, pointing to the camera's side.
        offset: d of the plane normal . X + d = 0 (camera frame); equals the camera height.
        T_world_from_camera: (4, 4) pose in the world frame described in the module.
        camera_height: metres above the floor.
        pitch_deg: optical axis below the horizon, degrees (over 90: past straight down).
        roll_deg: rotation about the optical axis, degrees (as geometry.pose_from_angles).
        inlier_count: points within the inlier distance of the refined plane (full cloud).
        rms_m: root mean square distance of those inliers to the plane, metres.
        ambiguity: with `up: auto`, one line when another plane would also have been a floor
            to a camera mounted otherwise (a level camera facing a wall sees what a camera
            looking straight down beside a wall sees), else None.
        floor_xy: (x_min, x_max, y_min, y_max) of the floor in view, world metres: the 1st
            and 99th percentiles of the inliers (within depth_max), outward to 0.1 m (where a
            ground grid goes; people nearer than its near edge may still be in view).
        noise: the depth noise the floor's readings show (floor_noise), or None.
    """

    normal: np.ndarray
    offset: float
    T_world_from_camera: np.ndarray
    camera_height: float
    pitch_deg: float
    roll_deg: float
    inlier_count: int
    rms_m: float
    ambiguity: str | None = None
    floor_xy: tuple[float, float, float, float] | None = None
    noise: dict | None = None

    def report(self) -> dict:
        """The pose as written by `dpom-warp fit-ground` (pastable into camera.extrinsics)."""
        return {"T_world_from_camera": [[round(float(x), 9) for x in row]
                                        for row in self.T_world_from_camera],
                "camera_height": round(float(self.camera_height), 4),
                "pitch_deg": round(float(self.pitch_deg), 3), "roll_deg": round(float(self.roll_deg), 3),
                "inlier_count": int(self.inlier_count)}


def backproject(depth_m: np.ndarray, camera: Camera, depth_max: float, stride: int = 1) -> np.ndarray:
    """Camera-frame points (N, 3) of the readings of a depth frame (metres, 0 = no reading).

    x = (u - cx) z / fx with pixel centres at integer u as in the rest of the project (no
    half-pixel shift), every `stride`-th row and column from 0; with lens distortion the
    normalised coordinates are then undistorted. Points come in pixel order (Open3D's
    back-projection returns them in a different order each call, which made the fit's sums,
    and so its rms, differ in their last bits between two runs of the same frames).
    """
    z = np.asarray(depth_m, dtype=np.float64)[::stride, ::stride]
    v, u = np.nonzero(np.isfinite(z) & (z > 0) & (z < depth_max))
    z = z[v, u]
    pts = np.stack([(u * stride - camera.cx) * z / camera.fx, (v * stride - camera.cy) * z / camera.fy, z], 1)
    if camera.distortion is not None and len(pts):
        z = pts[:, 2]
        x, y = camera.undistort(pts[:, 0] / z, pts[:, 1] / z)
        pts = np.stack([x * z, y * z, z], 1)
    return pts


STEEP_DEG = 10.0  # within this of straight down the world's y turns to the image's up


def steep_share(pitch_deg: float) -> float:
    """How far the world's y follows the image's up rather than the camera's forward: 0 up to
    STEEP_DEG short of straight down, 1 straight down, back to 0 STEEP_DEG past it."""
    return float(np.clip(1.0 - abs(pitch_deg - 90.0) / STEEP_DEG, 0.0, 1.0))


def pose_from_plane(normal: np.ndarray, offset: float) -> np.ndarray:
    """T_world_from_camera for the floor normal . X + offset = 0 (camera frame, offset > 0).
    The world's y is the camera's forward direction on the floor, as pose_from_angles places
    it; near straight down, where that direction is lost in the fit's noise (a camera at
    pitch 89.99 had its world turned 19 degrees by it), it turns smoothly to the image's up
    on the floor (pose_from_angles(h, 90) straight down)."""
    z_w = normal / np.linalg.norm(normal)

    def on_floor(v):
        v = v - (v @ z_w) * z_w
        n = np.linalg.norm(v)
        return v / n if n > 1e-9 else np.zeros(3)

    forward, up = on_floor(np.array([0.0, 0.0, 1.0])), on_floor(np.array([0.0, -1.0, 0.0]))
    t = steep_share(implied_pitch_roll(z_w)[0])
    if t > 0 and forward @ up < 0:  # past straight down the forward direction points back
        forward = -forward
    y_w = (1.0 - t) * forward + t * up
    if np.linalg.norm(y_w) < 1e-9:  # (no forward and no up on the floor: cannot happen)
        y_w = up if np.any(up) else forward
    y_w /= np.linalg.norm(y_w)
    x_w = np.cross(y_w, z_w)
    r_wc = np.stack([x_w, y_w, z_w])  # rows: world axes in camera coordinates
    t = np.eye(4)
    t[:3, :3] = r_wc
    t[:3, 3] = [0.0, 0.0, offset]
    return t


def _refine(points, normal, offset, options: GroundOptions, max_turn_deg: float | None = None):
    """Weighted least squares of the floor on the points near (normal, offset), iterated to
    its fixed point and rounded to 1e-10, so that slightly different starting planes that reach
    one fixed point give the same pose bit for bit (the planes themselves: planes.segment_plane,
    seeded).

    Only depth is noisy; a pixel's direction r = (x/z, y/z, 1) is exact. On the plane
    n . X + d = 0 a point z r satisfies 1/z = -(n . r) / d, which is linear in r, so the
    plane is the linear regression of 1/z on r, with no error in the regressors (a plain
    orthogonal fit would tilt the plane towards the rays when noise runs along them).
    Weights are 1 / var(1/z) = z^4 / sigma(z)^2 with sigma(z) = a + b z^2 taken at the
    plane's depth z_p, times Tukey's biweight of the depth residual (z - z_p) / (3 sigma)
    along the ray: things standing on the floor (feet, furniture legs, the foot of a wall)
    lie just in front of it along grazing rays, and a plain least-squares fit would lean
    towards them. Only points whose z_p is within depth_max count: a cut or a weight on the
    measured depth would favour the points that noise brought nearer. With `max_turn_deg`, a
    fit that turns the plane further than that has left it (a wall seen edge-on beside the
    floor: the band along its grazing rays takes in the floor by the corner) and the plane is
    kept as it came.
    """
    a, b = options.noise
    z = points[:, 2]
    rays = points / z[:, None]

    def inliers(normal, offset):
        plane_depth = floor_depth(rays, normal, offset)
        zp = np.minimum(plane_depth, z.max())
        sigma = a + b * zp ** 2
        band = np.maximum(0.5 * options.distance_threshold, 3.0 * sigma)
        near = (np.abs(z - zp) < band) & (plane_depth <= options.depth_max)
        return near, zp[near], sigma[near], band[near]

    start = normal, offset
    for _ in range(100):
        near, zp, sigma, band = inliers(normal, offset)
        if near.sum() < 3:
            break
        biweight = (1.0 - ((z[near] - zp) / band) ** 2) ** 2
        w = np.sqrt(biweight * zp ** 4 / sigma ** 2)
        coef, *_ = np.linalg.lstsq(rays[near] * w[:, None], w / z[near], rcond=None)
        scale = np.linalg.norm(coef)  # coef = -n / d
        previous = normal, offset
        normal, offset = -coef / scale, float(1.0 / scale)
        if np.abs(normal - previous[0]).max() < 1e-13 and abs(offset - previous[1]) < 1e-13:
            break
    if max_turn_deg is not None and float(normal @ start[0]) < math.cos(math.radians(max_turn_deg)):
        normal, offset = start  # it left the plane: seen edge-on, a wall's band takes in the floor
    normal = np.round(normal, 10)
    normal /= np.linalg.norm(normal)
    offset = round(float(offset), 10)
    near = inliers(normal, offset)[0]
    rms = float(np.sqrt(np.mean((points[near] @ normal + offset) ** 2))) if near.any() else float("nan")
    return normal, offset, int(near.sum()), rms


def floor_depth(rays: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Where each ray (x/z, y/z, 1) meets the plane n . X + d = 0: its depth z = -d / (n . r),
    inf for a ray that does not go down to it (n . r >= 0)."""
    ray_dot = rays @ normal
    with np.errstate(divide="ignore"):
        return np.where(ray_dot < 0, -offset / ray_dot, np.inf)


AUTO_TURN_DEG = 10.0  # up: auto judges a candidate by its refined plane unless that turned further
AUTO_MARGIN_DEG = 10.0  # up: auto takes floors seen from a camera pitched -10 to 100 degrees
AUTO_TIE_DEG = 0.5  # a pitch this close to 0 to 90 degrees counts as in it
AUTO_WARN_DEG = 3.0  # a rival floor whose pitch is within this of 0 to 90 degrees is reported


def implied_pitch_roll(normal: np.ndarray) -> tuple[float, float]:
    """Pitch and roll (degrees) of the camera to which `normal` (camera frame, towards the
    camera) is the floor's normal: pitch 0 looks level, 90 straight down, over 90 past the
    vertical (the image's up then points backwards, so the floor normal shows towards the
    image's bottom); roll is the direction of the normal in the image from the image's up
    (0 where that direction is undefined, looking exactly straight down)."""
    n = normal / np.linalg.norm(normal)
    elevation = math.degrees(math.asin(float(np.clip(-n[2], -1, 1))))
    if math.hypot(n[0], n[1]) < 1e-9:
        return elevation, 0.0
    roll = math.degrees(math.atan2(-n[0], -n[1]))
    if abs(roll) > 90:
        return 180.0 - elevation, roll - math.copysign(180.0, roll)
    return elevation, roll


def _auto_penalty(normal: np.ndarray, options: GroundOptions) -> float | None:
    """up: auto. None if no usual mounting sees this plane as its floor (pitch outside -10 to
    100 degrees, or roll over `max_angle_deg` for a camera not near straight down); else how
    far, in degrees, its pitch lies outside 0 to 90 (0 within)."""
    pitch, roll = implied_pitch_roll(normal)
    steep = math.hypot(normal[0], normal[1]) <= math.sin(math.radians(AUTO_MARGIN_DEG))
    if not -AUTO_MARGIN_DEG <= pitch <= 90.0 + AUTO_MARGIN_DEG or (abs(roll) > options.max_angle_deg
                                                                   and not steep):
        return None
    return max(0.0, -pitch - AUTO_TIE_DEG, pitch - 90.0 - AUTO_TIE_DEG)


def _perpendicular(a: np.ndarray, b: np.ndarray) -> bool:
    """Two plane normals more than 45 degrees apart (a wall and a floor, not a table top)."""
    return abs(float(a @ b)) < math.cos(math.radians(45))


HINT = ("set camera.ground.up ([0, -1, 0]: the floor towards the image's bottom, [0, 0, -1]: a camera "
        "looking down)")


def _choose(candidates):
    """up: auto. The floor among candidates (penalty, d, normal, ...), and a warning or None.

    Of the candidates with the least penalty, the most level reading's plane and those
    parallel to it compete, and the lowest (largest camera height) wins, so table tops lose.
    Two perpendicular planes that are both within `AUTO_TIE_DEG` of a usual mounting (one a
    level camera's floor, the other a floor seen from straight down: a level camera facing a
    wall, or a camera looking straight down beside a wall along the image's bottom) are an
    error: the depth is the same for both. A perpendicular plane that a camera within
    `AUTO_WARN_DEG` of level or of straight down would see as its floor is a warning.

    Raises:
        GroundFitError: the two readings tie.
    """
    best = min(c[0] for c in candidates)
    pool = [c for c in candidates if c[0] == best]
    level = min(pool, key=lambda c: implied_pitch_roll(c[2])[0])
    chosen = max((c for c in pool if not _perpendicular(c[2], level[2])), key=lambda c: c[1])
    d, n = chosen[1], chosen[2]

    def near(normal, tolerance):  # read as a camera within `tolerance` of level or of straight down
        pitch = implied_pitch_roll(normal)[0]
        return min(abs(pitch), abs(pitch - 90.0)) <= tolerance

    rivals = [c for c in candidates if _perpendicular(c[2], n) and near(c[2], AUTO_WARN_DEG)]
    if not rivals:
        return chosen, None
    rival = max(rivals, key=lambda c: c[1])
    rd, rn = rival[1], rival[2]
    (p, r), (rp, rr) = implied_pitch_roll(n), implied_pitch_roll(rn)
    if near(n, AUTO_TIE_DEG) and any(near(c[2], AUTO_TIE_DEG) for c in rivals):
        raise GroundFitError(
            f"two planes could be the floor and the depth cannot tell which: the plane {d:.2f} m away is "
            f"the floor of a camera pitched {p:.1f} deg (roll {r:.1f} deg), the plane {rd:.2f} m away that "
            f"of a camera pitched {rp:.1f} deg (roll {rr:.1f} deg); {HINT}")
    return chosen, (f"camera.ground.up: auto took the floor {d:.2f} m below the camera (pitch {p:.1f} "
                    f"deg, roll {r:.1f} deg), but the plane {rd:.2f} m away is what a camera pitched "
                    f"{rp:.1f} deg (roll {rr:.1f} deg) sees of its floor; {HINT} if the pose is wrong")


def fit_ground(points: np.ndarray, options: GroundOptions = GroundOptions(), seed: int = 0) -> GroundFit:
    """Find the floor in camera-frame points (several frames may be stacked).

    Planes are peeled off the cloud downsampled by Open3D with RANSAC, largest first
    (planes.segment_plane, seeded: Open3D's own gave other planes from call to call on a
    loaded machine, and _refine does not always bring them to one pose). Floor
    candidates have enough inliers, the camera on their upper side, and a normal within
    `max_angle_deg` of `up`, or with `up: auto` a normal that a camera pitched -10 to 100
    degrees (roll up to `max_angle_deg`, any near straight down) would see as its floor's;
    among them the lowest (largest camera height) wins, so table tops and shelves lose to the
    floor. With auto (`_choose`), a wall is such a candidate only for a camera near level (a
    wall ahead is the floor of a camera looking straight down) or near straight down (the wall
    behind it, along the image's bottom, is the floor of a level camera): the reading whose
    pitch is within 0 to 90 degrees wins (so a level camera tilted down facing a wall, and one
    looking down beside a wall short of the vertical, are read right), then the more level
    one; within `AUTO_TIE_DEG` of both it is an error, within `AUTO_WARN_DEG` a warning (the
    fit's `ambiguity`). With auto every candidate is refined before it is judged; else the
    winner is refined on the full cloud by the regression of `_refine`.

    Raises:
        GroundFitError: no candidate (too little floor visible, or none near `up`), or with
            auto two readings that tie.
    """
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(1)]
    in_range = pts[pts[:, 2] <= options.depth_max]
    if len(in_range) < options.min_inliers:
        raise GroundFitError(f"too few depth readings for a floor ({len(in_range)} points within "
                             f"{options.depth_max} m, need at least {options.min_inliers})")
    cloud = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(in_range))
                       .voxel_down_sample(options.voxel).points)
    auto = isinstance(options.up, str)
    if not auto:
        up = np.asarray(options.up, dtype=np.float64)
        up /= np.linalg.norm(up)
    candidates, best_other = [], 0
    for _ in range(options.max_planes):
        if len(cloud) < options.min_inliers:
            break
        _, idx = segment_plane(cloud, options.distance_threshold, 1000, seed)
        if len(idx) < 3:
            break
        # the inliers' least-squares plane (as Open3D's segment_plane gives it): a three-point
        # hypothesis is poorly placed on a wall seen edge-on, which _refine cannot correct
        n, d = least_squares_plane(cloud[idx])
        if d < 0:  # orient the normal towards the camera (origin): n . 0 + d > 0
            n, d = -n, -d
        if auto:
            penalty = _auto_penalty(n, options)
        else:
            angle = math.degrees(math.acos(float(np.clip(n @ up, -1, 1))))
            penalty = 0.0 if angle <= options.max_angle_deg else None
        if len(idx) >= options.min_inliers and penalty is not None and d > 0.05:
            candidates.append((penalty, d, n))
        else:
            best_other = max(best_other, len(idx))
        rest = np.ones(len(cloud), bool)
        rest[idx] = False
        cloud = cloud[rest]
    if not candidates:
        which = (f"is the floor of a camera pitched {-AUTO_MARGIN_DEG:g} to {90 + AUTO_MARGIN_DEG:g} deg "
                 f"(roll up to {options.max_angle_deg:g} deg)" if auto else
                 f"lies within {options.max_angle_deg:g} deg of up [{', '.join(f'{x:.3f}' for x in up)}] "
                 f"(camera coordinates: x right, y down, z forward)")
        raise GroundFitError(
            f"no floor plane found: no plane of at least {options.min_inliers} points below the "
            f"camera {which} (largest other plane: {best_other} points); is enough floor in view?")
    if auto:  # judge each candidate by its refined plane: a raw RANSAC plane can be a layer of
        # a far wall's quantised depths, exactly square to the optical axis
        refined = []
        for _, d, n in candidates:
            n, d, count, rms = _refine(pts, n, d, options, max_turn_deg=AUTO_TURN_DEG)
            penalty = _auto_penalty(n, options)
            if penalty is not None:
                refined.append((penalty, d, n, count, rms))
        if not refined:
            raise GroundFitError(f"no floor plane found: the planes below the camera, fitted on all the "
                                 f"points, are the floor of no camera pitched {-AUTO_MARGIN_DEG:g} to "
                                 f"{90 + AUTO_MARGIN_DEG:g} deg; is enough floor in view?")
        (_, d, n, count, rms), ambiguity = _choose(refined)
    else:  # every candidate is within max_angle_deg of up: the lowest
        _, d, n = max(candidates, key=lambda c: c[1])
        n, d, count, rms = _refine(pts, n, d, options)
        ambiguity = None
    pitch, roll = implied_pitch_roll(n)
    roll *= 1.0 - steep_share(pitch)  # straight down the pose has the image's up as y: no roll
    pose = pose_from_plane(n, d)
    return GroundFit(normal=n, offset=d, T_world_from_camera=pose, camera_height=d, pitch_deg=pitch,
                     roll_deg=roll, inlier_count=count, rms_m=rms, ambiguity=ambiguity,
                     floor_xy=floor_extent(in_range, n, d, pose, options.distance_threshold),
                     noise=floor_noise(pts, n, d, options.noise[0], options.depth_max))


NOISE_BIN_M = 0.5  # floor_noise's range bins, metres
NOISE_MIN_POINTS = 200  # readings a bin needs
NOISE_GRAZING_DEG = 15.0  # rays meeting the floor at less than this are left out
NOISE_BAND = 0.05  # readings farther from the floor along the ray than this share of its depth are not its


def floor_noise(points: np.ndarray, normal: np.ndarray, offset: float, a: float, depth_max: float) -> dict | None:
    """The depth noise the floor's readings show: along each ray that meets the floor (n, d)
    within depth_max at NOISE_GRAZING_DEG or more, the reading's depth z minus the floor's z_p
    (readings within NOISE_BAND z_p of it); in NOISE_BIN_M bins of z_p with NOISE_MIN_POINTS
    readings or more, sigma = 1.4826 x the median absolute deviation (what stands on the floor,
    within the band, moves it little) at their median z_p (the floor's near edge fills only the
    far end of its bin), and b of sigma(z) = a + b z^2 with `a` given, least
    squares weighted by the bins' readings. Returns {"a", "b", "bins": [[z, sigma, readings],
    ...]} (metres), or None with fewer than two such bins. A single frame's noise (a median of
    several frames, auto's background, has less)."""
    pts = np.asarray(points, dtype=np.float64)
    z = pts[:, 2]
    rays = pts / z[:, None]
    zp = floor_depth(rays, normal, offset)
    grazing = np.abs(rays @ normal) / np.linalg.norm(rays, axis=1)
    near = ((zp <= depth_max) & (grazing >= math.sin(math.radians(NOISE_GRAZING_DEG)))
            & (np.abs(z - zp) < NOISE_BAND * zp))
    r, zp = (z - zp)[near], zp[near]
    if not len(zp):
        return None
    bins = []
    for lo in np.arange(np.floor(zp.min() / NOISE_BIN_M) * NOISE_BIN_M, depth_max, NOISE_BIN_M):
        inside = (zp >= lo) & (zp < lo + NOISE_BIN_M)
        if inside.sum() >= NOISE_MIN_POINTS:
            rr = r[inside]
            bins.append([round(float(np.median(zp[inside])), 3),
                         round(1.4826 * float(np.median(np.abs(rr - np.median(rr)))), 5), int(inside.sum())])
    if len(bins) < 2:
        return None
    return {"a": a, "b": noise_b(bins, a), "bins": bins}


def noise_words(noise: dict, bins: int = 4) -> str:
    """floor_noise's first `bins` bins in words: "18 mm at 2.5 m, 21 mm at 2.7 m, ..."."""
    return ", ".join(f"{1000 * s:.0f} mm at {z:.1f} m" for z, s, _ in noise["bins"][:bins])


def noise_b(bins: list, a: float) -> float:
    """b of sigma(z) = a + b z^2 through floor_noise's bins ([z, sigma, readings]) with `a`
    given: least squares weighted by their readings, at least 0, to 1e-5."""
    zc, sigma, n = (np.array(c, float) for c in zip(*bins))
    return round(max(float(np.sum(n * (sigma - a) * zc ** 2) / np.sum(n * zc ** 4)), 0.0), 5)


def noise_ratio(bins: list, a: float, b: float) -> float:
    """How many times sigma(z) = a + b z^2 the floor_noise bins' sigmas are, over the bins
    weighted by their readings: sum(n sigma) / sum(n (a + b z^2))."""
    zc, sigma, n = (np.array(c, float) for c in zip(*bins))
    return float(np.sum(n * sigma) / np.sum(n * (a + b * zc ** 2)))


def floor_extent(points: np.ndarray, normal: np.ndarray, offset: float, pose: np.ndarray,
                 distance: float) -> tuple[float, float, float, float] | None:
    """(x_min, x_max, y_min, y_max) in world metres of the camera-frame `points` within
    `distance` of the floor: their 1st and 99th percentiles, outward to 0.1 m."""
    on = points[np.abs(points @ normal + offset) < distance]
    if len(on) < 2:
        return None
    xy = on @ pose[:2, :3].T + pose[:2, 3]
    lo, hi = np.percentile(xy, 1, axis=0), np.percentile(xy, 99, axis=0)
    lo, hi = np.floor(lo * 10 + 1e-9) / 10, np.ceil(hi * 10 - 1e-9) / 10
    return (round(float(lo[0]), 1), round(float(hi[0]), 1), round(float(lo[1]), 1), round(float(hi[1]), 1))


def fit_ground_frames(frames_m, camera: Camera, options: GroundOptions = GroundOptions()) -> GroundFit:
    """Floor from several depth frames (metres), their points stacked for a steadier fit."""
    # beyond depth_max too: the refinement selects points by the plane's depth, not theirs
    pts = [backproject(f, camera, 1.5 * options.depth_max, options.stride) for f in frames_m]
    return fit_ground(np.concatenate(pts) if pts else np.zeros((0, 3)), options)


def fit_ground_files(files, camera: Camera, depth_scale: float,
                     options: GroundOptions = GroundOptions(), names: list[str] | None = None) -> GroundFit:
    """`fit_ground_frames` on depth files; `names`: what to call them in messages (a
    recording's frames: the recording and the frame, not the cache's files).

    Raises:
        InputError: a bad file, or no floor in the files (the message names them).
    """
    from .io import read_depth

    depths = [read_depth(f, depth_scale, (camera.height, camera.width)) for f in files]
    return fit_ground_named(depths, camera, options, frames_named(files, names), depth_scale)


def fit_ground_named(frames_m, camera: Camera, options: GroundOptions, named: str,
                     depth_scale: float | None = None) -> GroundFit:
    """fit_ground_frames, its GroundFitError an InputError that starts with `named` (the
    frames, as frames_named says them) and, where the first frame's readings are no depth
    camera's, ends with io.depth_scale_hint."""
    from .io import InputError, depth_scale_hint

    try:
        return fit_ground_frames(frames_m, camera, options)
    except GroundFitError as e:
        hint = depth_scale_hint(frames_m[0], depth_scale) if depth_scale and len(frames_m) else None
        raise InputError(f"{named}: {e}" + (f" ({hint})" if hint else "")) from None


def frames_named(files, names: list[str] | None = None) -> str:
    """How messages name the frames a floor is fitted on: the first (by `names`, else its
    path) and how many more."""
    first = names[0] if names else str(files[0])
    return first if len(files) == 1 else f"{first} and {len(files) - 1} more frames"

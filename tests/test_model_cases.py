"""Hand-computed cases of the model: one visible object, one object hiding another, an empty
scene. Expected values come from the formulas of MODEL.md written out here, not from the code."""

import math

import numpy as np
import pytest

from dpom_warp import reference as ref
from dpom_warp.engine import Engine
from dpom_warp.geometry import Geometry
from dpom_warp.model import Background, ModelParams

H, W = 4, 6


def toy_geometry(depths, rects):
    """Camera at the origin looking along +z with every ray (0, 0, 1); location k is a plane
    z = depths[k] facing the camera with silhouette rects[k]."""
    rays = np.zeros((H, W, 3))
    rays[..., 2] = 1.0
    n = len(depths)
    rect = np.array(rects, dtype=np.int32)
    area = (rect[:, 2] - rect[:, 0] + 1) * (rect[:, 3] - rect[:, 1] + 1)
    normal = np.tile([0.0, 0.0, -1.0], (n, 1))
    locs = np.array([[0.0, 0.0, d] for d in depths])
    return Geometry(rays=rays, centre=np.zeros(3), locations=locs, rect=rect, rect_area=area,
                    normal=normal, plane=-np.array(depths, dtype=float),
                    bounds=np.array([-1.0, 1.0, -1.0, 1.0, 0.0, 10.0]))


def wall_background(z=5.0):
    return Background(mu=np.full((H, W), z), sigma=np.full((H, W), 0.05),
                      missing=np.full((H, W), 0.05), outlier=np.full((H, W), 0.05))


def log_theta(z, mu, s, p: ModelParams, missing):
    g = math.exp(-0.5 * ((z - mu) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    return math.log((1 - missing) * (p.outlier_prob / p.z_max + (1 - p.outlier_prob) * g))


def sigmoid(x):
    return 1 / (1 + math.exp(-x))


def run_both(device, depth, geom, bg, params):
    engine = Engine(geom, params, device)
    engine.set_background(bg)
    got = engine.infer(depth.astype(np.float32))
    want = ref.mean_field(depth, geom, bg, params)
    np.testing.assert_allclose(got.rho, want["rho"], atol=1e-6)
    assert got.entries == want["entries"]
    return got


def test_single_visible_object(device):
    params = ModelParams(prior=0.02, sigma_object=0.1, damping=0.2, damping_growth=1.0, tolerance=1e-4,
                         max_iterations=200, check_every=1, damping_streak=1.0)
    geom = toy_geometry([2.0], [(1, 1, 3, 2)])  # 3 x 2 pixels
    depth = np.full((H, W), 5.0)
    depth[1:3, 1:4] = 2.0
    got = run_both(device, depth, geom, wall_background(), params)

    s = math.hypot(0.1, params.sensor_sigma(2.0))
    d_obj = log_theta(2.0, 2.0, s, params, params.missing_prob)
    d_bg = log_theta(2.0, 5.0, 0.05, params, 0.05)
    target = sigmoid(math.log(0.02 / 0.98) + 6 * (d_obj - d_bg))  # evidence does not depend on rho
    # rho_t = target - (1 - lam)^t (target - prior); stop at the first t with
    # |target - rho_{t-1}| = (1 - lam)^(t-1) |target - prior| < tol
    t = next(t for t in range(1, 200) if 0.8 ** (t - 1) * abs(target - 0.02) < 1e-4)
    assert got.iterations == t
    assert got.rho[0] == pytest.approx(target - 0.8 ** t * (target - 0.02), abs=1e-9)
    assert got.evidence_share[0] == pytest.approx(1.0)  # every silhouette pixel supports it
    assert got.rho_star[0] == pytest.approx(sigmoid(100 * 1.0 - 8) * got.rho[0], abs=1e-9)
    assert got.entries == 6


def test_per_location_damping_grows_while_the_target_stays_on_one_side(device):
    """The single object with damping_streak: its target is constant and above its rho, so its
    t-th update (0-based) takes lambda = max(0.2, min(0.7, 0.2 x 1.5^t)): 0.2, 0.3, 0.45,
    0.675, then 0.7, and rho_t = target - prod(1 - lambda_i) (target - prior)."""
    params = ModelParams(prior=0.02, sigma_object=0.1, damping=0.2, damping_growth=1.0, tolerance=1e-4,
                         max_iterations=200, check_every=1, damping_streak=1.5, damping_streak_max=0.7)
    geom = toy_geometry([2.0], [(1, 1, 3, 2)])
    depth = np.full((H, W), 5.0)
    depth[1:3, 1:4] = 2.0
    got = run_both(device, depth, geom, wall_background(), params)
    s = math.hypot(0.1, params.sensor_sigma(2.0))
    target = sigmoid(math.log(0.02 / 0.98) + 6 * (log_theta(2.0, 2.0, s, params, params.missing_prob)
                                                   - log_theta(2.0, 5.0, 0.05, params, 0.05)))
    lams = [max(0.2, min(0.7, 0.2 * 1.5 ** t)) for t in range(200)]
    assert lams[:5] == pytest.approx([0.2, 0.3, 0.45, 0.675, 0.7])
    gap = [target - 0.02]  # target - rho_t
    for lam in lams:
        gap.append(gap[-1] * (1 - lam))
    t = next(t for t in range(1, 200) if abs(gap[t - 1]) < 1e-4)
    assert got.iterations == t < 12  # over 40 with lambda 0.2 throughout (the test above)
    assert got.rho[0] == pytest.approx(target - gap[t], abs=1e-9)


def test_object_hiding_another_one_step(device):
    """A at 2.0 m and B at 2.1 m share a silhouette; pixels read 2.0 m. One damped step."""
    params = ModelParams(prior=0.05, sigma_object=0.15, damping=0.3, max_iterations=1)
    geom = toy_geometry([2.0, 2.1], [(1, 1, 3, 2), (1, 1, 3, 2)])
    depth = np.full((H, W), 5.0)
    depth[1:3, 1:4] = 2.0
    got = run_both(device, depth, geom, wall_background(), params)

    sa = math.hypot(0.15, params.sensor_sigma(2.0))
    sb = math.hypot(0.15, params.sensor_sigma(2.1))
    da = log_theta(2.0, 2.0, sa, params, params.missing_prob)
    db = log_theta(2.0, 2.1, sb, params, params.missing_prob)
    dbg = log_theta(2.0, 5.0, 0.05, params, 0.05)
    r = 0.05
    ev_a = 6 * (da - (r * db + (1 - r) * dbg))  # A in front: T = 1, behind it B then bg
    ev_b = 6 * (1 - r) * (db - dbg)  # B seen through A with transparency 1 - rho_A
    lp = math.log(0.05 / 0.95)
    assert got.rho[0] == pytest.approx(0.7 * r + 0.3 * sigmoid(lp + ev_a), abs=1e-9)
    assert got.rho[1] == pytest.approx(0.7 * r + 0.3 * sigmoid(lp + ev_b), abs=1e-9)
    assert got.entries == 12


def test_hidden_object_is_explained_away_not_penalised(device):
    """With the paper's independent prior (no exclusion), at convergence the front object
    takes the pixels; the one behind it returns to its prior (it is hidden, not absent), and
    its soft-thresholded rho* vanishes: eq. 13 leaves it sigmoid(alpha e + beta) of its rho,
    e the share of its silhouette that A lets through (at most 1 - rho_A), under 5 % of the
    prior."""
    params = ModelParams(prior=0.05, sigma_object=0.15, damping=0.2, max_iterations=300, exclusion=0.0)
    geom = toy_geometry([2.0, 2.1, 4.0], [(1, 1, 3, 2), (1, 1, 3, 2), (1, 1, 3, 2)])
    depth = np.full((H, W), 5.0)
    depth[1:3, 1:4] = 2.0
    got = run_both(device, depth, geom, wall_background(), params)
    assert got.rho[0] > 0.999
    assert got.rho[1] == pytest.approx(0.05, abs=1e-3)  # evidence x (1 - rho_A) -> 0
    assert got.rho[2] == pytest.approx(0.05, abs=1e-12)  # 2 m in front of its plane: no mask
    e = got.evidence_share
    assert e[1] <= 1 - got.rho[0] + 1e-12 and e[2] == 0
    for k in (1, 2):
        assert got.rho_star[k] == pytest.approx(sigmoid(params.alpha * e[k] + params.beta) * got.rho[k], rel=1e-9)
        assert got.rho_star[k] < 0.05 * params.prior
    assert got.rho_star[0] > 0.99


def test_exclusion_pushes_the_hidden_neighbour_below_its_prior(device):
    """The same scene with the exclusion prior: B stands 0.1 m behind A, within the radius,
    so with rho_A ~ 1 its rho_new tends to sigmoid(logit(prior) + ~0 - exclusion); the far
    location, 2 m away, keeps its prior; A is unchanged."""
    params = ModelParams(prior=0.05, sigma_object=0.15, damping=0.2, max_iterations=300, exclusion=6.0,
                         tolerance=1e-9)  # B's limit is ~1e-4: converge well past it
    geom = toy_geometry([2.0, 2.1, 4.0], [(1, 1, 3, 2), (1, 1, 3, 2), (1, 1, 3, 2)])
    depth = np.full((H, W), 5.0)
    depth[1:3, 1:4] = 2.0
    got = run_both(device, depth, geom, wall_background(), params)
    lp = math.log(0.05 / 0.95)
    assert got.rho[0] > 0.999
    assert got.rho[1] == pytest.approx(sigmoid(lp - 6.0), rel=0.05)  # its own evidence x (1 - rho_A) -> 0
    assert got.rho[2] == pytest.approx(0.05, abs=1e-12)


def test_empty_scene_stays_at_or_below_prior(device):
    """Depth equal to the background everywhere: nothing is occupied."""
    from scenes import random_scene

    geom, params, _, frames = random_scene(2)
    engine = Engine(geom, params, device)
    engine.set_background_frames(frames)
    bg = ref.background_from_frames(frames, params)
    depth = np.where(bg.outlier < 1, bg.mu, 0.0).astype(np.float32)
    got = engine.infer(depth)
    assert got.entries > 0
    assert got.rho.max() <= params.prior + 1e-9
    assert got.rho_star.max() < 0.01


@pytest.mark.parametrize("legs, leg_radius", [(None, 0.2), (0.14, 0.14), (0.2, 0.2)])
def test_solid_depth_of_legs_body_and_head(legs, leg_radius):
    """Where rays enter the people solid standing at (0, 3): 1.8 m high, a round body of radius 0.2 m up
    to the shoulders (0.8 x 1.8 = 1.44 m), head radius 0.11 m above; below the hip (0.45 x 1.8
    = 0.81 m) legs of `leg_radius` (None, the default, or 0.2: the body reaches the floor)."""
    from dpom_warp.shapes import ObjectBox, solid_depth

    solid = ObjectBox(0.4, 1.8, leg_radius=legs, depth_radius=None).build("ground")  # round body
    at = np.array([0.0, 3.0, 0.0])
    level = np.array([[0.0, 1.0, 0.0]])
    down = np.array([[0.0, 0.0, -1.0]])
    cases = [((0.0, 0.0, 0.4), level, 3.0 - leg_radius),  # the legs' height
             ((0.0, 0.0, 1.2), level, 3.0 - 0.2),  # the body
             ((0.0, 0.0, 1.6), level, 3.0 - 0.11),  # the head
             ((0.0, 3.1, 3.0), down, 3.0 - 1.8),  # the head's top from above
             ((0.17, 3.0, 3.0), down, 3.0 - 1.44)]  # the shoulders' top beside it
    for centre, ray, want in cases:
        t, _ = solid_depth(np.array(centre), ray, at, solid)
        assert t[0] == pytest.approx(want, abs=1e-9), (centre, legs)
    # a ray that passes beside the legs but would have hit the body's radius
    t, _ = solid_depth(np.array([0.17, 0.0, 0.4]), level, at, solid)
    assert (t[0] < 0) == (leg_radius < 0.17)


def test_solid_depth_of_an_elliptic_body_facing_the_camera():
    """object.depth_radius 0.12: the body at (0, 3) is an ellipse 0.2 m across the line of
    sight and 0.12 m along it, facing the camera wherever the camera is. From (0, 0, 1.2),
    level rays (s, 1, 0) meet x^2 / 0.2^2 + (y - 3)^2 / 0.12^2 = 1 where (s t)^2 / 0.04 +
    (t - 3)^2 / 0.0144 = 1 (the smaller root; the axis' ray at 3 - 0.12); s = 0.07 misses
    (inside the circle's rect). From (3, 3, 1.2), looking along -x: the same narrow depth."""
    from dpom_warp.shapes import ObjectBox, solid_depth

    solid = ObjectBox(0.4, 1.8, head_radius=0.0, depth_radius=0.12).build("ground")
    assert ObjectBox(0.4, 1.8, depth_radius=0.12).build("voxel").depth_radius == 0.2  # a drone stays a disc
    at = np.array([0.0, 3.0, 0.0])
    for s in (0.0, 0.03, 0.06, 0.07):
        roots = np.roots([s * s / 0.04 + 1 / 0.0144, -6 / 0.0144, 9 / 0.0144 - 1])
        want = min(roots.real) if np.isreal(roots).all() else -1.0
        t, var = solid_depth(np.array([0.0, 0.0, 1.2]), np.array([[s, 1.0, 0.0]]), at, solid)
        assert t[0] == pytest.approx(want, abs=1e-9) and var[0] == 0.0, s
        assert (want < 0) == (s == 0.07)
    t, _ = solid_depth(np.array([3.0, 3.0, 1.2]), np.array([[-1.0, 0.0, 0.0]]), at, solid)
    assert t[0] == pytest.approx(3.0 - 0.12, abs=1e-9)
    # from (0, 0, 3), rays d = P - C to the top (z = 1.8) 0.15 m from the axis: across the line
    # of sight inside the 0.2 m semi-axis (the top, at t = 1), along it beyond the 0.12 m one:
    # the ray goes on to the front side, y = 2.88, at t = 2.88 / 2.85 (the circle's top at t = 1)
    centre = np.array([0.0, 0.0, 3.0])
    circle = ObjectBox(0.4, 1.8, head_radius=0.0, depth_radius=None).build("ground")
    for p, want, want_circle in (((0.15, 3.0, 1.8), 1.0, 1.0), ((0.0, 2.85, 1.8), 2.88 / 2.85, 1.0)):
        d = np.array([p]) - centre
        assert solid_depth(centre, d, at, solid)[0][0] == pytest.approx(want, abs=1e-9), p
        assert solid_depth(centre, d, at, circle)[0][0] == pytest.approx(want_circle, abs=1e-9), p


def test_the_iteration_schedule_by_hand():
    """The schedule the engine and the NumPy reference share (ModelParams.full_pass, damping_at),
    against values written by hand, so a bug in it cannot hide behind their agreement (issue 63).
    Sparse iterations with check_every 5 and 12 iterations: full passes at the first, at each
    check (iterations 5 and 10, 0-based 4 and 9) and at the last (11); the exact path
    (sparse_epsilon 0): every pass full. lambda = 0.1 x 1.03^i up to 0.4: 1.03^46 = 3.8950, so
    0.38950 at i = 46, and 1.03^47 = 4.0119 passes the cap at i = 47; without a cap (damping_max
    null in ModelParams) lambda stays at damping."""
    from dpom_warp.model import ModelParams

    p = ModelParams(max_iterations=12, check_every=5, sparse_epsilon=1e-4)
    assert [i for i in range(12) if p.full_pass(i)] == [0, 4, 9, 11]
    assert all(p.replace(sparse_epsilon=0.0).full_pass(i) for i in range(12))
    assert [i for i in range(10) if ModelParams(max_iterations=10, check_every=3).full_pass(i)] == [0, 2, 5, 8, 9]
    p = ModelParams(damping=0.1, damping_growth=1.03, damping_max=0.4)
    assert p.damping_at(0) == pytest.approx(0.1, abs=1e-15)
    assert p.damping_at(1) == pytest.approx(0.103, abs=1e-15)
    assert p.damping_at(46) == pytest.approx(0.38950, abs=5e-5)
    assert p.damping_at(47) == 0.4 and p.damping_at(90) == 0.4
    assert ModelParams(damping=0.1, damping_max=None).damping_at(30) == 0.1


def test_a_shape_is_one_class_and_one_warp_function():
    """shapes.py and the kernels agree on the code that picks a shape's Warp function
    (kernels.pixel_model.object_depth) and on the shape's fields in GeometryArrays; the config's
    object section builds the shape a geometry carries; the facing plane's depth and box by hand
    (a plane through (0, 3, 0) facing a camera at the origin: normal (0, -1, 0), n . (P - C) = -3,
    so a ray d with d_y = 1 meets it at z-depth 3 and a ray pointing away misses)."""
    import typing
    from types import SimpleNamespace

    from dpom_warp import kernels as K
    from dpom_warp.geometry import Camera, Grid, build_geometry, pose_from_angles
    from dpom_warp.shapes import SHAPE_PLANE, SHAPE_SOLID, SHAPES, FacingPlane, ObjectBox, Solid

    assert (FacingPlane.code, Solid.code) == (SHAPE_PLANE, SHAPE_SOLID) == (K.SHAPE_PLANE, K.SHAPE_SOLID)
    assert SHAPES == {"plane": FacingPlane, "solid": Solid}
    assert typing.get_args(ObjectBox.model_fields["shape"].annotation) == tuple(SHAPES)  # object.shape's values
    fields = list(K.GeometryArrays.vars)
    assert fields[fields.index("shape") + 1:] == list(K.SHAPE_FIELDS)  # the shape's fields, after its code
    solid = ObjectBox(0.4, 1.8).build("ground")
    assert isinstance(solid, Solid) and list(solid.kernel_fields()) == list(K.SHAPE_FIELDS)
    assert (solid.bottom, solid.shoulder, solid.top, solid.hip) == pytest.approx((0.0, 1.44, 1.8, 0.0))
    plane = ObjectBox(0.4, 1.8, depth=0.3, shape="plane").build("voxel")
    assert isinstance(plane, FacingPlane) and plane.kernel_fields() == {}
    assert plane.half_extent() == (0.2, 0.15) and (plane.bottom, plane.top) == (-0.9, 0.9)
    corners = plane.corners(np.array([[1.0, 2.0, 3.0]]))[0]
    np.testing.assert_allclose(corners.min(0), [0.8, 1.85, 2.1])
    np.testing.assert_allclose(corners.max(0), [1.2, 2.15, 3.9])
    facing = SimpleNamespace(normal=np.array([[0.0, -1.0, 0.0]]), plane=np.array([-3.0]))
    mu, var = plane.depth(facing, 0, np.array([[0.1, 1.0, 0.0], [0.0, 1.0, 0.2], [0.0, -1.0, 0.0]]))
    np.testing.assert_allclose(mu, [3.0, 3.0, -1.0])
    assert not var.any()
    cam = Camera(32, 24, 20.0, 20.0, 15.5, 11.5, pose_from_angles(2.0, 30.0))
    for name, cls in SHAPES.items():
        geom = build_geometry(cam, Grid(x=(-1, 1, 0.5), y=(2, 4, 0.5)), ObjectBox(0.4, 1.8, shape=name))
        assert type(geom.shape) is cls and geom.shape == ObjectBox(0.4, 1.8, shape=name).build("ground")
        seen = geom.rect_area > 0
        assert (geom.area[seen] < geom.rect_area[seen]).any() == cls.counted_area  # a solid misses corners


def test_sensor_sigma_by_hand():
    """model.sensor_noise [a, b]: a reading's noise at depth z is a + b z^2 (MODEL.md): with a
    = 0.01 and b = 0.002, 0.01 at 0 m, 0.012 at 1 m, 0.028 at 3 m, 0.04528 at 4.2 m; arrays
    and scalars alike (mutation testing found no test holding it)."""
    p = ModelParams(sensor_noise=(0.01, 0.002))
    np.testing.assert_allclose(p.sensor_sigma(np.array([0.0, 1.0, 3.0, 4.2])), [0.01, 0.012, 0.028, 0.04528],
                               rtol=0, atol=1e-12)
    assert float(p.sensor_sigma(3.0)) == pytest.approx(0.028, abs=1e-12)

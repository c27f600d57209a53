"""Floor-only scenes: the top-band test of the soft threshold (ModelParams.top_support), its
Warp counts against the reference, and what it is for: furniture lower than a person
rejected, a person whose legs that furniture hides kept; and two people side by side."""

import dataclasses

import numpy as np
import pytest

from dpom_warp import reference as ref
from dpom_warp.detect import detect
from dpom_warp.engine import Engine
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
from dpom_warp.model import MISSING_READ, TOP_MIN_RHO, ModelParams

from conftest import assert_top_counts
from scenes import draw_slab, random_scene


def with_low_slabs(seed):
    """random_scene plus 'tables': facing-plane slabs drawn only below 40 % of the box
    height, the floor behind them above."""
    geom, params, depth, _ = random_scene(seed)
    rng = np.random.default_rng(100 + seed)
    depth = depth.copy()
    for k in rng.choice(len(geom.rect), size=3, replace=False):
        draw_slab(depth, geom, k, below=0.4 * geom.height)
    return geom, params, depth


@pytest.mark.parametrize("sigmas", [0.0, 1.5])
@pytest.mark.parametrize("seed", [0, 1, 2, 9])  # scenes where bands are judged both ways
@pytest.mark.parametrize("by_row", [False, True])  # a thread a location (the CPU's) or a row (a GPU's)
def test_top_band_matches_reference(device, seed, sigmas, by_row):
    geom, params, depth = with_low_slabs(seed)
    params = params.replace(sparse_epsilon=0.0, top_support=0.3, top_sigmas=sigmas)
    engine = Engine(geom, params, device)
    engine.top_band_by_row = by_row
    got = engine.infer(depth)
    want = ref.mean_field(depth, geom, ref.floor_background(geom, params, depth), params)
    assert_top_counts(engine, want)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    assert (want["top_missing"] > 0).any() and (want["top_seen"] == -1).any()  # every count exercised
    judged = want["top_support"] + want["top_against"] + want["top_hidden"]
    assert np.all(judged[want["rho"] < TOP_MIN_RHO] == 0)
    # exercised: some bands judged for and some against (share above and below top_support)
    ok = judged >= params.top_min_pixels
    share = want["top_support"][ok] / judged[ok]
    assert share.max() > params.top_support and share.min() < params.top_support, share


def test_top_sigmas_is_a_stricter_support_than_the_mask_test():
    """model.top_sigmas 1 (within one sigma; the mask test passes ~3.5 sigma here): every band
    pixel it counts as support the mask test does too, and somewhere it counts fewer; the
    pixels it no longer counts become against or hidden (the band's readings are the same)."""
    geom, params, depth = with_low_slabs(1)
    gate = np.ones(len(geom.rect))
    bg = ref.floor_background(geom, params, depth)
    mask = ref.top_band(depth, geom, params.replace(top_sigmas=0.0), gate, bg)
    strict = ref.top_band(depth, geom, params.replace(top_sigmas=1.0), gate, bg)
    assert np.all(strict[0] <= mask[0]) and np.any(strict[0] < mask[0])
    np.testing.assert_array_equal(sum(strict[:3]), sum(mask[:3]))
    np.testing.assert_array_equal(strict[3:], mask[3:])


def test_off_and_voxel_grids_leave_rho_star_alone():
    geom, params, depth = with_low_slabs(1)
    params = params.replace(sparse_epsilon=0.0, top_support=0.0)
    bg = ref.floor_background(geom, params, depth)
    off = ref.mean_field(depth, geom, bg, params)
    on = ref.mean_field(depth, geom, bg, params.replace(top_support=0.3))
    np.testing.assert_array_equal(off["rho"], on["rho"])  # only the soft threshold changes
    assert np.any(on["rho_star"] < off["rho_star"] - 0.1)
    flat = ref.mean_field(depth, dataclasses.replace(geom, height=0.0), bg,
                          params.replace(top_support=0.3))
    np.testing.assert_array_equal(flat["rho_star"], off["rho_star"])


def rendered_room(with_person_behind_table=True):
    """A 160 x 120 camera 2.2 m high, 20 deg down, looking at a room: a table (0.75 m) and a
    cabinet (1.2 m) inside the grid, a person standing in the open, and (optionally) a
    person behind the table, legs hidden by it. Returns camera, depth, people's (x, y)."""
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    meshes = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((12, 0.1, 3), (0, 7.05, 1.5))]
    meshes.append(_box((1.2, 0.7, 0.04), (-1.0, 3.2, 0.73)))  # table top
    for sx in (-0.55, 0.55):
        for sy in (-0.3, 0.3):
            meshes.append(_box((0.05, 0.05, 0.71), (-1.0 + sx, 3.2 + sy, 0.355)))
    meshes.append(_box((0.9, 0.5, 1.2), (1.6, 4.5, 0.6)))  # cabinet
    people = [(0.3, 2.6)] + ([(-1.0, 3.85)] if with_person_behind_table else [])
    for x, y in people:
        meshes.append(person_mesh(1.75, np.pi / 2 + 0.3, 0.5).translate((x, y, 0.0)))
    t, _ = render(_scene(meshes)[0], cam)
    depth = sensor_noise(t, SceneSpec(), np.random.default_rng(0)).astype(np.float32)
    return cam, depth, np.array(people)


@pytest.mark.parametrize("behind_table", [True, False])
def test_furniture_rejected_person_behind_it_kept(behind_table):
    """Floor-only model, one frame: with the top-band test the detections are the people
    (also the one whose legs the table hides), not the table nor the cabinet; without it the
    furniture is detected too."""
    cam, depth, people = rendered_room(behind_table)
    grid = Grid(x=(-2.5, 2.5, 0.1), y=(1.5, 5.5, 0.1))
    geom = build_geometry(cam, grid, ObjectBox(0.5, 1.8))

    def found(params):
        engine = Engine(geom, params, "cpu")
        res = engine.infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        return np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)

    def matched(dets, xy):
        return np.any(np.hypot(*(dets - xy).T) < 0.5) if len(dets) else False

    furniture = np.array([(-1.0, 3.2), (1.6, 4.5)])
    dets = found(ModelParams())
    assert all(matched(dets, p) for p in people)
    assert len(dets) == len(people), dets
    plain = found(ModelParams(top_support=0.0))
    assert all(matched(plain, p) for p in people)
    assert sum(matched(plain, f) for f in furniture) >= 1  # what the test removes


def test_side_by_side_pair_is_two_maxima():
    """Two people 0.45 m apart, side by side, both fully visible (floor-only, one frame): the
    map holds a maximum for each, but the 0.5 m box pulls them together (a box centred on one
    person also covers the other's near half), so they sit closer than 0.4 m and the default
    non-maximum suppression keeps one; at 0.25 m both are detected (README: side by side).
    The facing-plane model (object.shape: plane); the solid finds one here too, in one frame
    without background frames (README, known behaviour)."""
    from dpom_warp.detect import local_maxima
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    people = np.array([(-0.225, 3.5), (0.225, 3.5)])
    meshes = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((12, 0.1, 3), (0, 7.05, 1.5))]
    meshes += [person_mesh(1.75, np.pi / 2, 0.5 + i).translate((x, y, 0.0))
               for i, (x, y) in enumerate(people)]
    t, _ = render(_scene(meshes)[0], cam)
    depth = sensor_noise(t, SceneSpec(), np.random.default_rng(1)).astype(np.float32)
    grid = Grid(x=(-2.0, 2.0, 0.1), y=(1.5, 5.5, 0.1))
    geom = build_geometry(cam, grid, ObjectBox(0.5, 1.8, shape="plane"))
    res = Engine(geom, ModelParams(top_support=0.05), "cpu").infer(depth)
    rho_map = res.rho_star.reshape(grid.shape)
    peaks = geom.locations[(local_maxima(rho_map) & (rho_map > 0.5)).ravel(), :2]
    near = [np.hypot(*(peaks - p).T) for p in people]
    assert len(peaks) == 2 and all(d.min() < 0.3 for d in near), peaks
    assert np.hypot(*(peaks[0] - peaks[1])) < 0.4  # pulled together by the box
    for radius, found in ((0.4, 1), (0.25, 2)):
        assert len(detect(rho_map, geom.locations, geom.rect, 0.5, radius)) == found


def ceiling_room_table_at_the_edge():
    """A 160 x 120 camera 2.6 m up, 45 deg down: a table (0.75 m) at the image's left edge,
    where a person standing there would have their head outside the image, and a person in
    the open. Returns camera, depth, the person's and the table's (x, y)."""
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.6, 45.0))
    table, person = (-2.2, 1.5), (0.3, 2.4)
    meshes = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((12, 0.1, 3), (0, 7.05, 1.5)),
              _box((1.2, 0.7, 0.04), (*table, 0.73))]
    for sx in (-0.55, 0.55):
        for sy in (-0.3, 0.3):
            meshes.append(_box((0.05, 0.05, 0.71), (table[0] + sx, table[1] + sy, 0.355)))
    meshes.append(person_mesh(1.75, np.pi / 2 + 0.3, 0.5).translate((*person, 0.0)))
    t, _ = render(_scene(meshes)[0], cam)
    depth = sensor_noise(t, SceneSpec(), np.random.default_rng(0)).astype(np.float32)
    return cam, depth, np.array(person), np.array(table)


def test_band_out_of_view_counts_like_the_reference(device):
    """The top band's pixels in the image (`seen`), counted by the kernel for every location
    of the ceiling room, equal the reference's, and some locations have none (their top is
    out of view) while their silhouette is in the image."""
    import warp as wp

    from dpom_warp import kernels as K

    cam, depth, _, _ = ceiling_room_table_at_the_edge()
    grid = Grid(x=(-3.0, 1.0, 0.1), y=(0.5, 3.0, 0.1))
    geom = build_geometry(cam, grid, ObjectBox(0.4, 1.8))
    params = ModelParams()
    engine = Engine(geom, params, device)
    engine.infer(depth)
    gate = np.ones(len(geom.rect))
    gate[::7] = 0.0  # not counted: seen -1
    counts = [wp.zeros(len(gate), dtype=wp.int32, device=device) for _ in range(5)]
    h = geom.height
    wp.launch(K.top_band, dim=len(gate), device=device,
              inputs=[engine.views[0].depth, engine.views[0].geo, engine.pm, engine.views[0].bg,
                      K.band_query(float(geom.centre[2]), params.top_band * h, h, TOP_MIN_RHO, params.top_sigmas,
                                   MISSING_READ),
                      wp.array(gate, dtype=wp.float64, device=device),
                      K.bands_of(counts), engine.views[0].forward])
    want = ref.top_band(depth, geom, params, gate, ref.floor_background(geom, params, depth))
    for got, w in zip(counts, want):
        np.testing.assert_array_equal(got.numpy(), w)
    seen = want[4]
    assert np.all(seen[::7] == -1)
    out_of_view = (seen >= 0) & (seen < params.top_min_pixels) & (geom.area > 0)
    assert out_of_view.sum() > 20 and (seen >= params.top_min_pixels).sum() > 20


def test_table_whose_top_would_be_out_of_view_is_not_a_person():
    """Floor-only model, a ceiling camera: a table at the image's edge supports the lower
    part of a cell's solid whose head lies outside the image, so no top band judges it; with
    `model.top_unseen` 0 (the default) such a cell is not a detection, with 1 (not judged)
    the table is detected. The person in the open is found either way."""
    cam, depth, person, table = ceiling_room_table_at_the_edge()
    grid = Grid(x=(-3.0, 3.0, 0.1), y=(0.5, 4.5, 0.1))
    geom = build_geometry(cam, grid, ObjectBox(0.4, 1.8))

    def found(params):
        res = Engine(geom, params, "cpu").infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        return np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)

    dets = found(ModelParams())
    assert len(dets) == 1 and np.hypot(*(dets[0] - person)) < 0.5, dets
    plain = found(ModelParams(top_unseen=1.0))
    assert np.any(np.hypot(*(plain - person).T) < 0.5)
    assert np.any(np.hypot(*(plain - table).T) < 0.8), plain  # what top_unseen removes


@pytest.mark.parametrize("seed", [1, 2, 9])  # scenes with missing readings in judged bands
def test_missing_band_readings_count_against(device, seed):
    """model.top_missing: a band pixel without a reading where the object lies within z_max
    counts as that much of one reading behind. On the Warp path rho* equals the reference
    with it on (1) and off (0); the band counts are the same both ways (only the factor
    changes), the factor only lowers rho*, and somewhere it lowers it by more than 0.1."""
    geom, params, depth = with_low_slabs(seed)
    params = params.replace(sparse_epsilon=0.0, top_support=0.3)
    got = {}
    for weight in (0.0, 1.0):
        p = params.replace(top_missing=weight)
        engine = Engine(geom, p, device)
        res = engine.infer(depth)
        want = ref.mean_field(depth, geom, ref.floor_background(geom, p, depth), p)
        np.testing.assert_allclose(res.rho_star, want["rho_star"], rtol=0, atol=1e-6)
        np.testing.assert_array_equal(engine.prior.top_counts[3].numpy(), want["top_missing"])
        got[weight] = want
    off, on = got[0.0], got[1.0]
    for key in ("top_support", "top_against", "top_hidden", "top_missing", "top_seen"):
        np.testing.assert_array_equal(off[key], on[key], err_msg=key)
    assert off["top_missing"].sum() > 0
    assert np.all(on["rho_star"] <= off["rho_star"] + 1e-12)
    assert np.any(on["rho_star"] < off["rho_star"] - 0.1)


def test_missing_readings_count_only_where_the_object_would_be_read():
    """top_band's `missing`: a band pixel with no reading counts where the object's depth is
    within z_max, not beyond it (the sensor would not read the object there either)."""
    geom, params, depth = with_low_slabs(9)
    gate = np.ones(len(geom.rect))
    bg = ref.floor_background(geom, params, depth)
    counts = ref.top_band(depth, geom, params, gate, bg)
    assert counts[3].sum() > 0
    near = ref.top_band(depth, geom, params.replace(z_max=0.5), gate, bg)
    assert near[3].sum() == 0  # every object lies beyond 0.5 m


@pytest.mark.parametrize("seed", [1, 9])
def test_a_sensors_dead_region_is_not_missing(device, seed):
    """A sensor that never reads a part of its image (an Azure Kinect's corners, a RealSense's
    left band): with background frames, which never read it either, a band pixel there is
    not counted as missing (ModelParams.top_missing); with the floor-only background, which
    knows no such region, it is. The Warp counts equal the reference with either background."""
    from scenes import random_scene

    geom, params, depth, bg_frames = random_scene(seed)
    params = params.replace(sparse_epsilon=0.0, top_support=0.3)
    w = depth.shape[1] // 3
    depth, bg_frames = depth.copy(), bg_frames.copy()
    depth[:, :w] = 0.0  # the dead region
    bg_frames[:, :, :w] = 0.0
    gate = np.ones(len(geom.rect))
    frames_bg, floor_bg = ref.background_from_frames(bg_frames, params), ref.floor_background(geom, params, depth)
    with_frames = ref.top_band(depth, geom, params, gate, frames_bg)[3]
    floor_only = ref.top_band(depth, geom, params, gate, floor_bg)[3]
    inside = geom.rect[:, 2] < w  # silhouette rectangles wholly in the dead region
    assert inside.any() and floor_only[inside].sum() > 0
    assert np.all(with_frames[inside] == 0) and np.all(with_frames <= floor_only)
    for set_background, bg in ((lambda e: e.set_background_frames(bg_frames), frames_bg),
                               (lambda e: e.set_floor_background(), floor_bg)):
        engine = Engine(geom, params, device)
        set_background(engine)
        got = engine.infer(depth)
        want = ref.mean_field(depth, geom, bg, params)
        np.testing.assert_array_equal(engine.prior.top_counts[3].numpy(), want["top_missing"])
        np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)

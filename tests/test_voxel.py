"""Voxel mode: 3D grids, background occlusion, drones hiding each other, and agreement with
the ground mode where the two must agree."""

import dataclasses
import json

import numpy as np
import pytest
import yaml

from dpom_warp import reference as ref
from dpom_warp.cli import main
from dpom_warp.engine import Engine
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
from dpom_warp.model import ModelParams

from test_model_cases import H, W, run_both, toy_geometry, wall_background
from paths import CONFIGS
from pictures import assert_picture


def cupboard_background():
    """Known background: a cupboard 3.0 m away over columns 0-2, a wall at 5 m elsewhere."""
    bg = wall_background(5.0)
    bg.mu[:, :3] = 3.0
    return bg


def test_voxel_behind_a_cupboard_is_hidden_not_penalised(device):
    # a drone at 3.3 m whose silhouette spans columns 1-4: columns 1-2 are behind the
    # cupboard, column 3 shows the drone, column 4 the wall behind it
    geom = toy_geometry([3.3, 3.0], [(1, 1, 4, 2), (0, 1, 2, 2)])
    depth = np.full((H, W), 5.0)
    depth[:, :3] = 3.0
    depth[1:3, 3] = 3.3  # the drone's visible part
    params = ModelParams(prior=0.01, sigma_object=0.15, damping_growth=1.0, max_iterations=200)
    without = run_both(device, depth, geom, cupboard_background(), params)
    occl = params.replace(background_occludes=True, occlusion_margin=0.1)
    with_rule = run_both(device, depth, geom, cupboard_background(), occl)
    # the cupboard's pixels (3.0 m, within 3 sigma of 3.3 m) count against the drone unless
    # the background is allowed to hide it
    assert without.rho[0] < 0.1  # contradicted by the cupboard in front of it
    assert with_rule.rho[0] > 0.99  # hidden by it: only its visible part counts
    assert with_rule.entries < without.entries
    # a voxel at the cupboard's own depth is explained by the background, not a drone
    assert without.rho[1] < 0.01 and with_rule.rho[1] < 0.01


def test_two_drones_one_behind_the_other(device):
    # B (4 m) spans columns 1-4; A (2 m) in front covers columns 1-2 of it
    geom = toy_geometry([2.0, 4.0], [(1, 1, 2, 2), (1, 1, 4, 2)])
    depth = np.full((H, W), 6.0)
    depth[1:3, 1:3] = 2.0
    depth[1:3, 3:5] = 4.0
    params = ModelParams(prior=0.01, sigma_object=0.1, max_iterations=200)
    got = run_both(device, depth, geom, wall_background(6.0), params)
    assert got.rho[0] > 0.99 and got.rho[1] > 0.99
    assert got.evidence_share[1] == pytest.approx(0.5, abs=0.01)  # half of B is visible
    assert got.rho_star[1] > 0.99  # enough to pass the soft threshold


def test_one_layer_voxel_grid_equals_ground_grid(device):
    """With the camera at half the object height the facing planes of both modes coincide."""
    h = 1.8
    cam = Camera(64, 48, 50.0, 50.0, 31.5, 23.5, pose_from_angles(h / 2, 3.0))
    box = ObjectBox(0.5, h, shape="plane")
    ground = build_geometry(cam, Grid(x=(-1.5, 1.5, 0.25), y=(1.0, 5.0, 0.25)), box)
    voxel = build_geometry(cam, Grid(x=(-1.5, 1.5, 0.25), y=(1.0, 5.0, 0.25), mode="voxel",
                                     z=(h / 2 - 0.05, h / 2 + 0.05, 0.1)), box)
    np.testing.assert_array_equal(ground.rect, voxel.rect)
    np.testing.assert_allclose(ground.normal, voxel.normal, atol=1e-12)
    np.testing.assert_allclose(ground.plane, voxel.plane, atol=1e-12)
    rng = np.random.default_rng(0)
    params = ModelParams()
    depth = ref.floor_background(ground, params).mu
    u0, v0, u1, v1 = ground.rect[20]
    depth[v0:v1 + 1, u0:u1 + 1] = 3.0
    depth = (depth + rng.normal(0, 0.01, depth.shape) * (depth > 0)).astype(np.float32)
    a, b = Engine(ground, params, device).infer(depth), Engine(voxel, params, device).infer(depth)
    np.testing.assert_allclose(a.rho, b.rho, atol=1e-9)
    # with the camera elsewhere they differ: voxel planes tilt towards the camera
    cam2 = dataclasses.replace(cam, T_world_from_camera=pose_from_angles(2.5, 20.0))
    g2 = build_geometry(cam2, Grid(x=(-1.5, 1.5, 0.25), y=(1.0, 5.0, 0.25)), box)
    v2 = build_geometry(cam2, Grid(x=(-1.5, 1.5, 0.25), y=(1.0, 5.0, 0.25), mode="voxel",
                                   z=(h / 2 - 0.05, h / 2 + 0.05, 0.1)), box)
    assert np.abs(g2.normal - v2.normal).max() > 0.1


def test_background_occlusion_matches_reference_on_random_scenes(device):
    from scenes import random_scene

    for seed in range(3):
        geom, params, depth, frames = random_scene(seed)
        params = params.replace(background_occludes=True, occlusion_margin=0.05)
        engine = Engine(geom, params, device)
        engine.set_background_frames(frames)
        got = engine.infer(depth)
        want = ref.mean_field(depth, geom, ref.background_from_frames(frames, params), params)
        assert got.entries == want["entries"]
        np.testing.assert_allclose(got.rho, want["rho"], atol=1e-6)


def small_drone_config(tmp_path):
    cfg = yaml.safe_load(open(CONFIGS / "demo_drones.yaml"))
    cache = tmp_path / "scene"
    cfg["device"] = "cpu"
    cfg["input"].update(frames=f"{cache}/frames/*.png", background=f"{cache}/background/*.png")
    cfg["camera"].update(width=160, height=132, intrinsics={"fx": 114.0, "fy": 114.0, "cx": 79.5, "cy": 65.5})
    cfg["grid"].update(x=[-2.0, 2.0, 0.2], y=[1.5, 6.0, 0.2], z=[0.4, 2.4, 0.2])
    cfg["evaluation"]["ground_truth"] = f"{cache}/ground_truth.json"
    cfg["output"].update(dir=str(tmp_path / "out"), ply=True)
    cfg["synthetic"].update(cache=str(cache), frames=3, background_frames=3, people=3)
    path = tmp_path / "drones.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def check_ply(out, frame, dets, size):
    """ply/0000_points.ply holds a point for each pixel of the frame with a reading, and
    ply/0000_boxes.ply one box (8 corners) of the object's size per detection, centred on it
    (read back with Open3D's reader, not the writer's code)."""
    import open3d as o3d
    from PIL import Image

    pts = np.asarray(o3d.io.read_point_cloud(str(out / "ply" / "0000_points.ply")).points)
    assert len(pts) == np.count_nonzero(np.asarray(Image.open(frame))) > 1000
    corners = np.asarray(o3d.io.read_triangle_mesh(str(out / "ply" / "0000_boxes.ply")).vertices)
    assert len(dets) >= 1 and corners.shape == (8 * len(dets), 3)
    boxes = corners.reshape(len(dets), 8, 3)
    got = sorted(tuple(np.round(b.mean(0), 4)) for b in boxes)
    want = sorted(tuple(np.round([float(d[1]), float(d[2]), float(d[3])], 4)) for d in dets)
    np.testing.assert_allclose(got, want, atol=1e-4)
    np.testing.assert_allclose(np.ptp(boxes, axis=1), np.tile(size, (len(dets), 1)), atol=1e-9)


def test_drone_run_end_to_end(tmp_path, capsys):
    path = small_drone_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    out = tmp_path / "out"
    truth = json.load(open(tmp_path / "scene" / "ground_truth.json"))
    for t in truth:
        for o in t["objects"]:
            assert 0.6 <= o["z"] <= 2.1 and 0 < o["visibility"] <= 1
    m = np.load(out / "maps" / "0000.npy")
    assert m.shape == (10, 23, 20)  # (nz, ny, nx)
    rows = (out / "detections.csv").read_text().splitlines()[1:]
    assert rows and all(0.4 <= float(r.split(",")[3]) <= 2.4 for r in rows)  # z is filled
    check_ply(out, tmp_path / "scene" / "frames" / "0000.png", [r.split(",") for r in rows if r.startswith("0000")],
              (0.4, 0.4, 0.12))  # the drone config's object: 0.4 x 0.4 x 0.12 m
    ev = json.load(open(out / "eval.json"))[0]
    assert ev["distance"] == "space" and ev["cube_size"] == [0.4, 0.4, 0.12]
    assert "moda_cube" in ev["penalise_hidden"]
    assert_picture(out / "plots" / "moda_cube.png", (300, 200), plot=True)
    summary = json.load(open(out / "summary.json"))
    assert summary["scores"]["tp"] >= 1


def test_voxel_config_errors(tmp_path, capsys):
    path = small_drone_config(tmp_path)
    assert main(["run", str(path), "--set", "grid.z=null"]) == 2
    assert "grid.z: required key is missing" in capsys.readouterr().err
    assert main(["run", str(path), "--set", "grid.mode=ground"]) == 2
    assert "grid.z: expected no z axis in ground mode" in capsys.readouterr().err
    assert main(["run", str(path), "--set", "object.height=3"]) == 2
    assert "object.height: expected at most the grid's z extent 2 m, found 3" in capsys.readouterr().err

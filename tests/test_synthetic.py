"""Synthetic scenes: reproducible, with ground truth that matches what is rendered."""

import json

import numpy as np

from dpom_warp.geometry import Camera, pose_from_angles
from dpom_warp.io import read_depth
from dpom_warp.synthetic import SceneSpec, generate, render, _scene, room_meshes, sensor_noise

CAM = Camera(128, 106, 91.25, 91.25, 63.5, 52.5, pose_from_angles(2.2, 20.0))


def test_same_seed_same_bytes_and_cache_reuse(tmp_path):
    spec = SceneSpec(seed=5, frames=2, background_frames=2, people=3)
    generate(spec, CAM, tmp_path / "a")
    generate(spec, CAM, tmp_path / "b")
    for sub in ("frames/0000.png", "frames/0001.png", "background/0001.png", "ground_truth.json"):
        assert (tmp_path / "a" / sub).read_bytes() == (tmp_path / "b" / sub).read_bytes()
    stamp = (tmp_path / "a" / "frames" / "0000.png").stat().st_mtime_ns
    generate(spec, CAM, tmp_path / "a")  # same spec: reused, not rendered again
    assert (tmp_path / "a" / "frames" / "0000.png").stat().st_mtime_ns == stamp
    generate(SceneSpec(seed=6, frames=2, background_frames=2, people=3), CAM, tmp_path / "a")
    assert (tmp_path / "a" / "frames" / "0000.png").read_bytes() != (tmp_path / "b" / "frames" / "0000.png").read_bytes()


def test_rendering_again_with_fewer_frames_leaves_none_of_the_old(tmp_path):
    """A scene's folder rendered again with fewer frames holds those frames only: the old
    ones would be globbed by input.frames with no ground truth for them."""
    generate(SceneSpec(seed=5, frames=3, background_frames=3, people=2), CAM, tmp_path)
    generate(SceneSpec(seed=5, frames=2, background_frames=2, people=2), CAM, tmp_path)
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["0000.png", "0001.png"]
    assert sorted(p.name for p in (tmp_path / "background").iterdir()) == ["0000.png", "0001.png"]
    assert [t["frame"] for t in json.loads((tmp_path / "ground_truth.json").read_text())] == ["0000.png", "0001.png"]


def test_ground_truth_matches_rendering(tmp_path):
    spec = SceneSpec(seed=1, frames=3, background_frames=3, people=4, dropout=0.0, edge_holes=0.0)
    generate(spec, CAM, tmp_path)
    truth = json.loads((tmp_path / "ground_truth.json").read_text())
    assert [t["frame"] for t in truth] == ["0000.png", "0001.png", "0002.png"]
    bg = np.median(np.stack([read_depth(p, 0.001) for p in sorted((tmp_path / "background").glob("*.png"))]), 0)
    for t in truth:
        depth = read_depth(tmp_path / "frames" / t["frame"], 0.001)
        assert len(t["objects"]) == 4
        for o in t["objects"]:
            assert 0 < o["visibility"] <= 1 and 1.55 <= o["height"] <= 1.95
            u0, v0, u1, v1 = o["bbox"]
            box = (slice(v0, v1 + 1), slice(u0, u1 + 1))
            # inside the person's box, where the person is visible, depth is nearer than the room
            changed = (depth[box] > 0) & (depth[box] < bg[box] - 0.2)
            if o["visibility"] > 0.5:
                assert changed.mean() > 0.1
            # the person stands on the floor at (x, y): project the foot point into the box
            u, v, _ = CAM.project(np.array([o["x"], o["y"], 0.0]))
            assert u0 - 15 <= u <= u1 + 15 and v0 - 15 <= v <= v1 + 15
        xy = np.array([[o["x"], o["y"]] for o in t["objects"]])
        d = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 9
        assert d.min() > 0.6  # people keep their distance


def test_noise_grows_with_depth_and_edges_lose_readings():
    rng = np.random.default_rng(0)
    room, _ = room_meshes(SceneSpec(furniture=0), rng)
    scene, _ = _scene(room)
    clean, _ = render(scene, CAM)
    spec = SceneSpec(dropout=0.0, edge_holes=1.0)
    noisy = np.stack([sensor_noise(clean, spec, rng) for _ in range(20)])
    ok = np.all(noisy > 0, axis=0) & np.isfinite(clean)
    spread = noisy.std(axis=0)
    near, far = ok & (clean < 3), ok & (clean > 6)
    assert spread[far].mean() > 3 * spread[near].mean()
    a, b = spec.noise
    assert abs(spread[near].mean() / np.mean(a + b * clean[near] ** 2) - 1) < 0.2
    assert np.all(noisy[:, clean > spec.range_m[1]] == 0)

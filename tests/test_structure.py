"""Static structure as background (structure.py, input.structure): large planes other than the
floor, found in the run's first frames, explain the pixels where they are seen when there are no
background frames; people against a wall or half hidden in front of one are still found."""

import csv
import json

import numpy as np
import pytest
import yaml

from dpom_warp.cli import main
from dpom_warp.geometry import Camera, pose_from_angles
from dpom_warp.io import write_depth_png
import paths

CAM = dict(width=160, height=120, intrinsics={"fx": 114.0, "fy": 114.0, "cx": 79.5, "cy": 59.5})
WALL_Y = 4.25  # the wall's face is at y = 4.2
PEOPLE = [(0.6, 3.95), (-1.0, 3.45)]  # against the wall; behind a desk, its legs hidden


def rendered(people=PEOPLE, seed=0):
    """One frame of a 160 x 120 camera 2.2 m high, 20 deg down: the floor, a wall across the
    grid at y = 4.2 (6 m wide, 3 m high), a desk (0.75 m) at y = 2.95 and `people`."""
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    meshes = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((6, 0.1, 3), (0, WALL_Y, 1.5)),
              _box((1.2, 0.7, 0.04), (-1.0, 2.95, 0.73))]
    for sx in (-0.55, 0.55):
        for sy in (-0.3, 0.3):
            meshes.append(_box((0.05, 0.05, 0.71), (-1.0 + sx, 2.95 + sy, 0.355)))
    for x, y in people:
        meshes.append(person_mesh(1.75, np.pi / 2, 0.5).translate((x, y, 0.0)))
    t, _ = render(_scene(meshes)[0], cam)
    return sensor_noise(t, SceneSpec(), np.random.default_rng(seed)).astype(np.float32)


def run(tmp_path, name, frames, workers=1, **input_changes):
    """`dpom-warp run` floor-only on `frames` (written as PNGs), the pose given, in `workers`
    processes: (detections (n, 2), summary)."""
    folder = tmp_path / name
    (folder / "frames").mkdir(parents=True)
    for i, depth in enumerate(frames):
        write_depth_png(folder / "frames" / f"{i:04d}.png", depth)
    cfg = {"device": "cpu", "input": {"frames": str(folder / "frames"), "background": None, **input_changes},
           "camera": {**CAM, "extrinsics": {"height": 2.2, "pitch_deg": 20.0}},
           "grid": {"x": [-2.5, 2.5, 0.1], "y": [1.5, 5.0, 0.1]},
           "output": {"dir": str(folder / "out"), "images": False}, "tracking": {"method": "off"}}
    (folder / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(folder / "c.yaml"), "--no-progress", "--workers", str(workers)]) == 0
    rows = list(csv.reader(open(folder / "out" / "detections.csv")))[1:]
    dets = np.array([[float(r[1]), float(r[2])] for r in rows]).reshape(-1, 2)
    return dets, json.loads((folder / "out" / "summary.json").read_text())


def near(dets, xy, r=0.5):
    return len(dets) > 0 and bool(np.any(np.hypot(*(dets - np.asarray(xy)).T) < r))


def test_a_wall_in_the_grid_is_background_and_people_by_it_are_found(tmp_path):
    """Floor-only, three frames: the wall is found (a vertical plane at y = 4.2 within 3 cm,
    at least 4 m wide) and made background; the person standing against it and the person
    behind the desk in front of it are found and nothing else is. Without it
    (input.structure.planes: false) the wall itself is taken for people."""
    frames = [rendered(seed=s) for s in range(3)]
    dets, summary = run(tmp_path, "planes", frames)
    structure = summary["inference"]["structure"]
    walls = [p for p in structure["planes"] if abs(p["normal"][1]) > 0.99]
    assert len(walls) >= 1 and structure["pixels"] > 0
    wall = walls[0]
    assert abs(abs(wall["d"]) - (WALL_Y - 0.05)) < 0.03 and wall["size_m"][0] >= 4.0
    assert all(near(dets, p) for p in PEOPLE), dets
    per_frame = len(dets) / len(frames)
    assert per_frame == len(PEOPLE), dets
    plain, _ = run(tmp_path, "plain", frames, structure={"planes": False})
    extra = [d for d in plain if not any(np.hypot(*(d - p)) < 0.5 for p in PEOPLE)]
    assert len(extra) >= 1, plain  # what the planes remove
    # --workers 2: the helper process is handed the background with the planes, the same maps
    pooled, _ = run(tmp_path, "pooled", frames, workers=2)
    for i in range(len(frames)):
        name = f"maps/{i:04d}.npy"
        assert (tmp_path / "pooled" / "out" / name).read_bytes() == (tmp_path / "planes" / "out" / name).read_bytes()


def test_no_wall_is_no_plane_and_the_same_run(tmp_path):
    """People on an open floor (no wall, no desk): no plane is structure (a person's front is no
    plane a metre wide), so the run is the run without the key, byte for byte."""
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    meshes = [_box((12, 14, 0.1), (0, 3, -0.05))]
    for x, y in [(-0.3, 2.5), (0.15, 2.55), (0.6, 2.5), (-1.2, 3.5)]:  # three side by side
        meshes.append(person_mesh(1.75, np.pi / 2, 0.5).translate((x, y, 0.0)))
    t, _ = render(_scene(meshes)[0], cam)
    depth = sensor_noise(t, SceneSpec(), np.random.default_rng(3)).astype(np.float32)
    dets, summary = run(tmp_path, "open", [depth])
    assert summary["inference"]["structure"]["planes"] == []
    plain, _ = run(tmp_path, "open_plain", [depth], structure={"planes": False})
    assert np.array_equal(dets, plain)
    assert (tmp_path / "open" / "out" / "maps" / "0000.npy").read_bytes() == (
        tmp_path / "open_plain" / "out" / "maps" / "0000.npy").read_bytes()


def test_real_office_wall_faced_level_is_no_one(tmp_path):
    """The RealSense recording (an office wall 1.83 m away, nobody in the room) with a level pose
    1.2 m up: the wall is background, no detection (it was 4 "people" a frame)."""
    cfg = {"device": "cpu", "input": {"frames": str(paths.REAL / "realsense_d435" / "single_depth_color_640x480.bag")},
           "camera": {"extrinsics": {"height": 1.2, "pitch_deg": 0.0, "roll_deg": 0.0}},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    (tmp_path / "rs.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(tmp_path / "rs.yaml"), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 2 and summary["detections"] == 0
    assert summary["inference"]["structure"]["pixels"] > 0.9 * 106 * 80


@pytest.mark.parametrize("planes", [True, False])
def test_five_people_walls(tmp_path, planes):
    """The real five-people frame with the README's recipe (grid x -2 to 2, y 1 to 6): with the
    planes, the corridor's end wall (y = 6) and left wall (x = -1.9) hold no detection and the
    five people (1.8 to 3.1 m away) are found; without them both walls do."""
    real = paths.REAL / "five_people"
    cfg = {"device": "cpu", "input": {"frames": str(real / "depth_mm.png"), "structure": {"planes": planes}},
           "camera": str(real / "camera.yaml"), "grid": {"x": [-2, 2, 0.1], "y": [1, 6, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(tmp_path / "c.yaml"), "--no-progress"]) == 0
    rows = list(csv.reader(open(tmp_path / "out" / "detections.csv")))[1:]
    xy = np.array([[float(r[1]), float(r[2])] for r in rows])
    on_walls = (xy[:, 1] > 5.7) | (xy[:, 0] < -1.7)
    people = (xy[:, 1] > 1.7) & (xy[:, 1] < 3.2)
    assert people.sum() >= 5
    assert (on_walls.sum() == 0) if planes else (on_walls.sum() >= 2), xy

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


def run(tmp_path, name, frames, workers=1, camera=CAM, **input_changes):
    """`dpom-warp run` floor-only on `frames` (written as PNGs) of `camera`, the pose given, in
    `workers` processes: (detections (n, 2), summary)."""
    folder = tmp_path / name
    (folder / "frames").mkdir(parents=True)
    for i, depth in enumerate(frames):
        write_depth_png(folder / "frames" / f"{i:04d}.png", depth)
    cfg = {"device": "cpu", "input": {"frames": str(folder / "frames"), "background": None, **input_changes},
           "camera": {**camera, "extrinsics": {"height": 2.2, "pitch_deg": 20.0}},
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
    # the Python API finds the same planes in the config's frames: the run's detections
    from dpom_warp.api import Detector
    from dpom_warp.io import read_depth

    det = Detector.from_config(tmp_path / "planes" / "c.yaml")
    found = [[d.x, d.y] for i in range(len(frames)) for d in det.detect(
        read_depth(tmp_path / "planes" / "frames" / f"{i:04d}.png", 0.001, (120, 160))).detections]
    assert np.allclose(np.array(found).reshape(-1, 2), dets, atol=1e-4), (found, dets)
    plain, _ = run(tmp_path, "plain", frames, structure={"planes": False})
    extra = [d for d in plain if not any(np.hypot(*(d - p)) < 0.5 for p in PEOPLE)]
    assert len(extra) >= 1, plain  # what the planes remove
    # --workers 2: the helper process is handed the background with the planes, the same maps
    pooled, _ = run(tmp_path, "pooled", frames, workers=2)
    for i in range(len(frames)):
        name = f"maps/{i:04d}.npy"
        assert (tmp_path / "pooled" / "out" / name).read_bytes() == (tmp_path / "planes" / "out" / name).read_bytes()


def test_the_api_finds_the_planes_in_frames_it_is_given(tmp_path):
    """Detector.find_static_planes: a floor-only config with no input.frames (a camera's frames
    come later) takes the wall for people until it is given the first frames; then the wall is
    background and each frame's detections are the recorded run's (which found the planes in
    its first files). Background frames, planes off and no frame are one-line errors."""
    from dpom_warp.api import Detector
    from dpom_warp.config import ConfigError
    from dpom_warp.io import InputError, read_depth

    frames = [rendered(seed=s) for s in range(3)]
    dets, summary = run(tmp_path, "planes", frames)
    cfg = yaml.safe_load((tmp_path / "planes" / "c.yaml").read_text())
    del cfg["input"]["frames"]
    det = Detector.from_config(cfg)
    given = [read_depth(tmp_path / "planes" / "frames" / f"{i:04d}.png", 0.001, (120, 160)) for i in range(3)]
    before = [[d.x, d.y] for d in det.detect(given[0]).detections]
    assert not all(near(np.array([d]), PEOPLE[0]) or near(np.array([d]), PEOPLE[1]) for d in before), before
    report = det.find_static_planes(given)
    assert report["pixels"] == summary["inference"]["structure"]["pixels"]
    assert [p["normal"] for p in report["planes"]] == [p["normal"] for p in summary["inference"]["structure"]["planes"]]
    found = [[d.x, d.y] for g in given for d in det.detect(g).detections]
    assert np.allclose(np.array(found).reshape(-1, 2), dets, atol=1e-4), (found, dets)
    with pytest.raises(InputError, match="expected at least one frame"):
        det.find_static_planes([])
    with pytest.raises(ConfigError, match="input.structure.planes: expected true"):
        Detector.from_config(cfg, {"input.structure.planes": False}).find_static_planes(given)
    bg = tmp_path / "bg"
    bg.mkdir()
    write_depth_png(bg / "0000.png", frames[0])
    with pytest.raises(ConfigError, match="input.background: expected null or auto"):
        Detector.from_config(cfg, {"input.background": str(bg / "*.png")}).find_static_planes(given)


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


def flat_points(width, height, fill=1.0, bottom=0.1, y=3.0, spacing=0.02, seed=0):
    """Points on an upright rectangle facing the camera (the plane y = `y`), x from 0 to
    `width`, z from `bottom` up `height`, every `spacing` metres, a random share 1 - `fill` of
    its 0.1 m cells left empty (a person's gappy front)."""
    rng = np.random.default_rng(seed)
    x, z = np.meshgrid(np.arange(0, width, spacing), np.arange(bottom, bottom + height, spacing))
    pts = np.stack([x.ravel(), np.full(x.size, y), z.ravel()], 1)
    cells = np.floor(pts[:, [0, 2]] / 0.1).astype(int)
    empty = {tuple(c) for c in np.unique(cells, axis=0) if rng.random() > fill}
    return pts[[tuple(c) not in empty for c in cells]]


def kind_of(points, normal=(0.0, 1.0, 0.0), taller=1.95, in_view=None):
    from dpom_warp.structure import StructureOptions, _kind, _patches

    n = np.asarray(normal, float) / np.linalg.norm(normal)
    patches = _patches(np.array([*n, -n @ points.mean(0)]), points, (-5, 5, 0, 8), 0.2, 50, in_view=in_view)
    return (_kind(patches[0], StructureOptions(), taller), patches[0]) if patches else (None, None)


def test_flat_solid_faces_are_structure_and_peoples_fronts_are_not():
    """The rules by hand (defaults: solid_width 0.5, solid_height 1.0, solid_fill 0.85, faces
    from the floor up; structure.py): a cabinet's front 0.7 x 1.6 m standing on the floor is
    "solid"; the same front 0.3 m above the floor (a real person's flat chest and thighs), 0.45 m
    wide (a face, structure only beside a solid one), with 30 % of its cells empty, or tilted 20
    degrees (a plane through a crowd) is not; a wall 3 x 2.5 m is "large"; a desk top 0.8 x 0.6 m
    at 0.75 m is "solid", the same at 1.5 m (heads from a ceiling camera) a face at most; a
    level plane 1.8 m square 0.1 m up is the floor misread (nothing), 0.4 m up "solid" (a level
    plane is never "large": a third filled, it was as often slices of people)."""
    assert kind_of(flat_points(0.7, 1.6))[0] == "solid"
    assert kind_of(flat_points(0.7, 1.6, bottom=0.4))[0] is None
    assert kind_of(flat_points(0.45, 1.6))[0] == "face"
    assert kind_of(flat_points(0.7, 1.6, fill=0.7))[0] is None
    tilt = np.radians(20)
    pts = flat_points(0.7, 1.6)
    tilted = pts.copy()
    tilted[:, 1] = 3.0 + (pts[:, 2] - 0.9) * np.tan(tilt)
    assert kind_of(tilted, (0.0, 1.0, -np.tan(tilt)))[1] is None
    assert kind_of(flat_points(3.0, 2.5))[0] == "large"
    desk = flat_points(0.8, 0.6, bottom=2.7)[:, [0, 2, 1]] * [1, 1, 0] + [0, 0, 0.75]
    assert kind_of(desk, (0, 0, 1))[0] == "solid"
    assert kind_of(desk + [0, 0, 0.75], (0, 0, 1))[0] in ("face", None)
    floor = flat_points(1.8, 1.8, bottom=2.0)[:, [0, 2, 1]] * [1, 1, 0] + [0, 0, 0.1]
    assert kind_of(floor, (0, 0, 1))[0] is None  # the floor read 0.1 m high by a drifting frame
    assert kind_of(floor + [0, 0, 0.3], (0, 0, 1))[0] == "solid"  # a low stage 0.4 m high


def test_a_face_the_images_edge_cuts_is_judged_on_its_part_in_view():
    """A cabinet's front 0.7 x 1.6 m whose right part the image's edge cuts on a slant (in view:
    x up to 0.2 m at its top, 0.6 m at the floor; as a shelf's front against a side wall, seen at
    the image's edge in the robustness row with walls and cabinets): each column is filled over the rows in view, so it is
    "solid", 0.6 m of it; judged on the whole rectangle's height, the columns past 0.2 m are
    short and it was a narrow face at most (a "person" floor-only). A person's gappy front (30 %
    of its cells empty) cut the same way is not solid (a narrow face at most, in 27 of 40 draws:
    its columns with few rows in view fill by chance, structure only where it meets a solid face);
    with the whole front in view, in_view changes nothing."""
    def in_view(points):
        return points[:, 0] <= 0.2 + 0.4 * (1.7 - points[:, 2]) / 1.6

    front = flat_points(0.7, 1.6)
    cut = front[in_view(front)]
    assert kind_of(cut)[0] == "face"  # (structure only where it meets a solid face)
    kind, patch = kind_of(cut, in_view=in_view)
    assert kind == "solid"
    from dpom_warp.structure import StructureOptions
    lo, hi = patch.solid_span(StructureOptions().solid_fill)
    assert hi - lo == pytest.approx(0.6, abs=0.1)
    gappy = flat_points(0.7, 1.6, fill=0.7)
    assert kind_of(gappy[in_view(gappy)], in_view=in_view)[0] != "solid"
    everywhere = kind_of(front, in_view=lambda p: np.ones(len(p), bool))
    assert everywhere[0] == "solid" and everywhere[1].solid_span(0.85) == kind_of(front)[1].solid_span(0.85)


def test_a_face_meeting_a_solid_at_its_edge_is_structure():
    """A shelf's end (0.3 m deep) is a face: structure where two of its corners lie within
    0.2 m of the corners of a solid face at 90 degrees (the shelf's front), not when 0.5 m
    away, nor beside a parallel solid."""
    from dpom_warp.structure import _meet

    _, front = kind_of(flat_points(0.9, 1.7))  # x 0 to 0.9 on y = 3
    end_pts = flat_points(0.3, 1.7)[:, [1, 0, 2]] * [0, 1, 1] + [0.9, 3.0, 0]  # on x = 0.9, y 3 to 3.3
    kind, end = kind_of(end_pts, (1, 0, 0))
    assert kind == "face"
    assert _meet(end, front, 0.2)
    _, far = kind_of(end_pts + [0.5, 0, 0], (1, 0, 0))
    assert not _meet(far, front, 0.2)
    _, parallel = kind_of(flat_points(0.3, 1.7, y=3.1) + [0.9, 0, 0])
    assert not _meet(parallel, front, 0.2)


def test_a_ray_that_saw_beyond_a_plane_is_not_given_it():
    """plane_depths: a ray through a plane's rectangle meets it at t; where the frames read
    farther than t + tolerance the ray passed it (past a cabinet's edge, in the margin) and the
    plane behind it is taken; where they read it, or nearer (a person in front), or nothing, the
    plane is."""
    from dpom_warp.structure import StaticPlane, plane_depths

    near = StaticPlane(np.array([0.0, -1.0, 0.0]), 2.0, np.array([0.0, 2.0, 0.0]), np.array([1.0, 0, 0]),
                       np.array([0, 0, 1.0]), (-1.0, 1.0, -1.0, 3.0), 100)  # y = 2
    far = StaticPlane(np.array([0.0, -1.0, 0.0]), 5.0, np.array([0.0, 5.0, 0.0]), np.array([1.0, 0, 0]),
                      np.array([0, 0, 1.0]), (-3.0, 3.0, -1.0, 3.0), 100)  # y = 5
    rays = np.tile(np.array([0.0, 1.0, 0.0]), (1, 4, 1))  # straight ahead: t is y
    centre = np.array([0.0, 0.0, 1.0])
    seen = np.array([[2.0, 1.2, 0.0, 5.0]])
    out = plane_depths([near, far], rays, centre, 0.1, seen, 0.09)
    assert np.allclose(out, [[2.0, 2.0, 2.0, 5.0]])
    assert np.allclose(plane_depths([near, far], rays, centre, 0.1), 2.0)


@pytest.mark.parametrize("cabinet, person", [((0.9, 3.5), (-0.05, 3.4)), ((-1.2, 3.5), (-0.75, 3.4))],
                         ids=["apart", "flush"])
def test_a_cabinet_in_the_grid_is_background_and_the_person_beside_it_is_found(tmp_path, cabinet, person):
    """Floor-only, three frames of a 320 x 240 camera: a cabinet 0.8 x 0.5 x 1.7 m inside the
    grid and a person beside it, 0.45 m apart or flush with its front (the person's front and the
    cabinet's are one plane within 3 cm): the cabinet's front is structure (its solid columns
    only, not the person's), the cabinet holds no detection and the person is found; without the
    solid rule (solid_width 100 m) the cabinet is taken for people. (At 160 x 120 the cabinet's
    top and end are a few pixels, too few to find as planes, and a person behind the cabinet is
    still detected: a limit.)"""
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(320, 240, 228.0, 228.0, 159.5, 119.5, pose_from_angles(2.2, 20.0))
    camera = dict(width=320, height=240, intrinsics={"fx": 228.0, "fy": 228.0, "cx": 159.5, "cy": 119.5})
    frames = []
    for seed in range(3):
        meshes = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((0.8, 0.5, 1.7), (*cabinet, 0.85)),
                  person_mesh(1.75, np.pi / 2, 0.5).translate((*person, 0.0))]
        t, _ = render(_scene(meshes)[0], cam)
        frames.append(sensor_noise(t, SceneSpec(), np.random.default_rng(seed)).astype(np.float32))
    dets, summary = run(tmp_path, "cabinet", frames, camera=camera)
    fronts = [p for p in summary["inference"]["structure"]["planes"] if abs(p["normal"][1]) > 0.98]
    assert len(fronts) == 1, fronts
    (nx, ny, _), d = fronts[0]["normal"], fronts[0]["d"]
    for x in (cabinet[0] - 0.4, cabinet[0] + 0.4):  # its front, y = 3.25, within 5 cm from end to end
        assert abs(-(d + nx * x) / ny - 3.25) < 0.05, fronts
    assert abs(fronts[0]["size_m"][0] - 0.8) <= 0.1, fronts  # not the person's front beside it
    assert near(dets, person, 0.3) and len(dets) == len(frames), dets
    plain, _ = run(tmp_path, "cabinet_plain", frames, camera=camera, structure={"solid_width": 100.0})
    assert any(np.hypot(*(d - np.array(cabinet))) < 0.5 for d in plain), plain


def test_two_cabinets_in_one_plane_are_two_patches():
    """Two cabinet fronts 0.7 x 1.6 m in the plane y = 3, 1 m apart, are one RANSAC plane: each
    is its own patch, each "solid", its rectangle its own (0.7 m wide, not 2.4 m)."""
    from dpom_warp.structure import StructureOptions, _kind, _patches

    pts = np.concatenate([flat_points(0.7, 1.6), flat_points(0.7, 1.6) + [1.7, 0, 0]])
    patches = _patches(np.array([0.0, 1.0, 0.0, -3.0]), pts, (-5, 5, 0, 8), 0.2, 50)
    assert len(patches) == 2
    for p in patches:
        assert _kind(p, StructureOptions(), 1.95) == "solid"
        assert abs(p.size()[0] - 0.7) < 0.05


def test_ransac_finds_the_plane_with_most_points_the_same_on_every_call():
    """planes.segment_plane on a 2 x 1.5 m wall (y = 3, points every 5 cm, +-1 cm of noise) with
    a person-sized cloud in front of it and scattered points: the wall's plane (normal +-y, at
    y = 3 within 5 mm) and exactly the wall's points within 3 cm; the same plane and indices on a
    second call (Open3D's segment_plane changed from call to call); a wall whose right half sits
    8 cm behind its left is not one plane within 3 cm, and is within 3 cm on the left and 10 cm
    on the right (each point's own distance: a sensor's noise grows with range)."""
    from dpom_warp.planes import segment_plane

    rng = np.random.default_rng(1)
    x, z = np.meshgrid(np.arange(-1, 1, 0.05), np.arange(0, 1.5, 0.05))
    wall = np.stack([x.ravel(), 3 + rng.uniform(-0.01, 0.01, x.size), z.ravel()], 1)
    person = rng.normal([0.2, 2.4, 0.9], [0.15, 0.1, 0.4], (300, 3))
    scatter = rng.uniform([-2, 1, 0], [2, 5, 2], (200, 3))
    scatter = scatter[np.abs(scatter[:, 1] - 3) > 0.05]
    points = np.concatenate([wall, person, scatter])
    model, idx = segment_plane(points, 0.03)
    assert abs(abs(model[1]) - 1) < 1e-3 and abs(model[3] / model[1] + 3) < 0.005
    assert np.array_equal(idx, np.arange(len(wall)))
    again = segment_plane(points, 0.03)
    assert np.array_equal(again[0], model) and np.array_equal(again[1], idx)

    far = wall[:, 0] > 0.025  # 19 of the 40 columns
    bent = wall + np.where(far[:, None], [0, 0.08, 0], [0, 0, 0])
    assert len(segment_plane(bent, 0.03)[1]) < len(wall)
    assert np.array_equal(segment_plane(bent, np.where(far, 0.1, 0.03))[1], np.arange(len(wall)))
    with pytest.raises(ValueError, match="at least 3 points"):
        segment_plane(points[:2], 0.03)


@pytest.mark.parametrize("frames", [1, 3, 5, 9, 25])
def test_the_medians_noise_is_that_of_a_median_of_normal_readings_never_under_it(frames):
    """The plane finder's tolerance for the frames' median (median_noise): against the spread
    of the median of `frames` normal readings drawn here, it is never under it (a tolerance
    tighter than the noise cuts a wall into bands) and within 10 % of it; one reading is sigma."""
    from dpom_warp.structure import median_noise

    sigma = 0.05
    rng = np.random.default_rng(frames)
    drawn = np.median(rng.normal(3.0, sigma, (200_000, frames)), axis=1).std()
    a, b = median_noise((sigma, 0.0), frames)
    assert b == 0.0 and drawn <= a * 1.01 and a <= drawn * 1.1
    assert median_noise((0.002, 0.0015), 1) == (0.002, 0.0015)


def test_a_plane_beside_the_grid_takes_its_noise_band_with_it():
    """structure._peeled by hand: a wall at y = 8 beyond a grid that ends at y = 7 (its points
    1, 4 and 10 cm off the plane, the inlier distance 3 cm): its inliers go, and so does the
    reading 4 cm off (within 3 inlier distances, 9 cm), not the one 10 cm off (a thing of its own);
    over the grid the same plane takes its inliers only (a person 4 cm in front of a wall in
    the grid stays for the planes after)."""
    from dpom_warp.structure import _peeled

    cloud = np.array([[0.0, 8.01, 1.0], [0.5, 7.96, 1.0], [1.0, 7.90, 1.0],  # beyond the grid
                      [0.0, 6.99, 1.0], [0.5, 6.96, 1.0]])  # over it, by a plane at y = 7
    tol = np.full(len(cloud), 0.03)
    wall = np.array([0.0, 1.0, 0.0, -8.0])
    left, left_tol = _peeled(cloud, tol, wall, np.array([0]), (-3.0, 3.0, 0.5, 7.0))
    assert np.array_equal(left, cloud[[2, 3, 4]]) and len(left_tol) == 3
    inside = np.array([0.0, 1.0, 0.0, -7.0])
    left, _ = _peeled(cloud, tol, inside, np.array([3]), (-3.0, 3.0, 0.5, 7.0))
    assert np.array_equal(left, cloud[[0, 1, 2, 4]])

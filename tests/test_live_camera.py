"""A live camera's identity and pose: `realsense:SERIAL` picks that camera, its accelerometer
gives the floor fit its up (and a height its tilt), and a pose left out is fitted on the first
frames it sends (the run, `fit-ground` and the API); SoftwareCamera (pyrealsense2's
software_device) stands in for the RealSense."""

import json

import pytest
import yaml

from dpom_warp.cli import main
from test_live import assert_plain_maps_in_stream_order, on_the_live_camera, plain_maps


def test_realsense_serial_picks_that_camera():
    """README: `input.frames: realsense:SERIAL` runs on that camera. Two cameras connected
    (software ones, of different sizes and intrinsics): `realsense` is the first, each
    `realsense:SERIAL` brings its own size, intrinsics and serial, and a serial no camera has
    is a one-line error naming it and the serials found."""
    import numpy as np

    from dpom_warp.io import InputError
    from dpom_warp.sources import open_source
    from dpom_warp.sources.software import SoftwareCamera

    first = SoftwareCamera([np.zeros((48, 64), np.uint16)], 50.0, 51.0, 31.5, 23.5, serial="111").register()
    second = SoftwareCamera([np.zeros((24, 32), np.uint16)], 25.0, 26.0, 15.5, 11.5, serial="222").register()
    try:
        infos = {spec: open_source(spec).info() for spec in ("realsense", "realsense:222",
                                                                               "realsense:111")}
        assert (infos["realsense"].width, infos["realsense"].height) == (64, 48)
        assert infos["realsense"].intrinsics == infos["realsense:111"].intrinsics == {
            "fx": 50.0, "fy": 51.0, "cx": 31.5, "cy": 23.5}
        two = infos["realsense:222"]
        assert (two.width, two.height, two.intrinsics) == (32, 24, {"fx": 25.0, "fy": 26.0, "cx": 15.5, "cy": 11.5})
        assert "serial 222" in two.kind and "serial 111" in infos["realsense"].kind
        with pytest.raises(InputError) as err:
            open_source("realsense:333")
        assert str(err.value) == "input.frames: realsense:333: no RealSense camera with serial 333; found 111, 222"
    finally:
        first.unregister()
        second.unregister()


@pytest.fixture(scope="module")
def tilted(tmp_path_factory):
    """A small scene rendered from a camera 2.2 m up at pitch 25 deg, roll 4 deg (3 frames, no
    camera registered: each test plays it on its own camera, `tilted_camera`): (folder, the
    folder config's mapping, the live config's mapping with the pose left out, the up the
    camera's accelerometer reads, R^T (0, 0, 1) of the rendered pose, the ground truth)."""
    from test_cli import small_config

    from dpom_warp.frames import render_synthetic
    from dpom_warp.loading import load_config

    tmp = tmp_path_factory.mktemp("tilted")
    path = small_config(tmp, frames=3)
    cfg = yaml.safe_load(path.read_text())
    cfg["camera"]["extrinsics"] = {"height": 2.2, "pitch_deg": 25.0, "roll_deg": 4.0}
    path.write_text(yaml.safe_dump(cfg))
    rendered = load_config(path)
    render_synthetic(rendered, lambda *_: None)
    up = rendered.camera.T_world_from_camera[:3, :3].T @ [0.0, 0.0, 1.0]
    live = on_the_live_camera(json.loads(json.dumps(cfg)))
    live["output"]["images"] = False
    del live["camera"]["extrinsics"]
    truth = json.loads((tmp / "scene" / "ground_truth.json").read_text())
    return tmp, cfg, live, up, truth


def tilted_camera(tilted):
    """The tilted scene on a registered SoftwareCamera whose motion module reads what that camera
    reads at rest: +9.81 m/s^2 along the world's up seen from it."""
    from dpom_warp.sources import expand
    from dpom_warp.sources.software import SoftwareCamera
    from dpom_warp.geometry import Camera

    tmp, cfg, _, up, _ = tilted
    c, i = cfg["camera"], cfg["camera"]["intrinsics"]
    frames = expand(str(tmp / "scene" / "frames" / "*.png"), "input.frames")
    return SoftwareCamera.of_files(frames, Camera(c["width"], c["height"], i["fx"], i["fy"], i["cx"], i["cy"]),
                                   accel=9.81 * up).register()


def found_where_rendered(got: list, objects: list) -> bool:
    """Every person at least half in view has a detection within 0.3 m, and there is no other."""
    import numpy as np

    people = [(o["x"], o["y"]) for o in objects if o["visibility"] > 0.5]
    return len(got) == len(people) and all(min(np.hypot(x - a, y - b) for a, b in got) < 0.3 for x, y in people)


def test_a_live_cameras_accelerometer_gives_the_floor_its_up_and_a_height_its_tilt(tilted, tmp_path, capsys,
                                                                                   monkeypatch):
    """README: a live RealSense with an accelerometer (D435i, D455) is read as a recording's IMU
    is: `dpom-warp info` shows its up, extrinsics left out take that up as camera.ground.up, and
    `{height: H}` takes its pitch and roll from it. On the tilted scene's camera (its
    accelerometer reading the rendered pose's up): the live run given only the height infers
    every frame as the plain run with the rendered pose does, bit for bit, reading the
    accelerometer once (with the config; the run's start does not read it again); a camera
    without an accelerometer gives no up."""
    import numpy as np

    from dpom_warp.loading import load_config
    from dpom_warp.sources import open_source, realsense
    from dpom_warp.sources.base import gravity_direction
    from dpom_warp.sources.software import SoftwareCamera

    tmp, plain, cfg, up, _ = tilted
    cfg = json.loads(json.dumps(cfg))
    cam = tilted_camera(tilted)
    try:
        assert main(["info", "realsense"]) == 0
        imu = next(x for x in capsys.readouterr().out.splitlines() if "IMU" in x)
        assert imu.startswith("  IMU: yes (up in the depth camera's frame: [") and "pitch 25.00 deg, roll 4.00 deg" in imu
        path = tmp_path / "live.yaml"
        path.write_text(yaml.safe_dump(cfg))  # extrinsics left out: auto, the floor fit's up is the accelerometer's
        np.testing.assert_allclose(load_config(path).ground.up, up, atol=1e-6)
        cfg["camera"]["extrinsics"] = {"height": 2.2}
        cfg["output"]["dir"] = str(tmp_path / "out")
        path.write_text(yaml.safe_dump(cfg))
        loaded = load_config(path)
        assert loaded.imu_tilt == {"pitch_deg": 25.0, "roll_deg": 4.0}  # to the 3 decimals they are kept to
        (tmp_path / "plain.yaml").write_text(yaml.safe_dump(plain))
        want = plain_maps(tmp_path, 3)
        capsys.readouterr()
        reads = []  # the readings of each time the accelerometer is read (made an up)
        monkeypatch.setattr(realsense, "gravity_direction", lambda r: reads.append(len(r)) or gravity_direction(r))
        cam.start()
        try:
            assert main(["run", str(path), "--no-progress", "--max-frames", "4", "--workers", "1"]) == 0
        finally:
            cam.stop()
        assert len(reads) == 1 and reads[0] == realsense.ACCEL_SAMPLES
        assert ("camera pitch 25.00 deg, roll 4.00 deg from the camera's accelerometer (camera.extrinsics leaves "
                "pitch_deg and roll_deg out)") in capsys.readouterr().out.splitlines()
        assert_plain_maps_in_stream_order(tmp_path / "out", want, 4)
    finally:
        cam.unregister()
    level = SoftwareCamera([np.zeros((24, 32), np.uint16)], 25.0, 26.0, 15.5, 11.5, serial="333").register()
    try:
        info = open_source("realsense:333").info()
        assert not info.imu and info.gravity_up is None
    finally:
        level.unregister()


def test_a_live_camera_with_its_pose_left_out_fits_the_floor_on_its_first_frames(tilted, tmp_path, capsys):
    """README: extrinsics left out and no background frames, a live run fits the floor on the
    camera's first camera.ground.frames frames (the accelerometer's up its guide), which are
    also the static planes' and are not inferred; on the tilted scene the pose is the rendered
    one within 0.3 deg and 0.02 m and every person in view is found where the renderer put them,
    by both processes. A floor that leaves the grid out of view is one line, and the camera is
    let go. `dpom-warp track` poses the camera from summary.json's ground_fit."""
    import csv

    from dpom_warp.sources.realsense import RealSenseLive

    _, _, cfg, _, truth = tilted
    cfg = {**cfg, "input": {**cfg["input"], "background": None}, "output": {**cfg["output"], "dir": str(tmp_path / "fitted")}}
    path = tmp_path / "fitted.yaml"
    path.write_text(yaml.safe_dump(cfg))
    beside = {**cfg, "grid": {**cfg["grid"], "y": [-6.0, -4.0, 0.2]},  # behind the camera
              "output": {**cfg["output"], "dir": str(tmp_path / "beside")}}
    (tmp_path / "beside.yaml").write_text(yaml.safe_dump(beside))
    cam = tilted_camera(tilted)
    try:
        cam.start()
        try:
            assert main(["run", str(path), "--no-progress", "--max-frames", "3", "--workers", "2"]) == 0
        finally:
            cam.stop()
        capsys.readouterr()
        cam.start()
        try:
            assert main(["run", str(tmp_path / "beside.yaml"), "--no-progress", "--max-frames", "3"]) == 2
        finally:
            cam.stop()
        assert capsys.readouterr().err.startswith("dpom-warp: error: grid: none of its ")
        assert not RealSenseLive("realsense").sensor.get_active_streams()  # stopped and closed by the failed run
    finally:
        cam.unregister()
    summary = json.loads((tmp_path / "fitted" / "summary.json").read_text())
    fit, live = summary["ground_fit"], summary["live"]
    assert fit["camera_height"] == pytest.approx(2.2, abs=0.02)
    assert fit["pitch_deg"] == pytest.approx(25.0, abs=0.3) and fit["roll_deg"] == pytest.approx(4.0, abs=0.3)
    assert fit["frames"] == ["realsense's first 5 frames"] and live["floor_frames"] == live["structure_frames"] == 5
    assert live["frames"] == 3 and live["processes"] == 2  # the helper's engine has the fitted pose too
    found = {}
    for row in csv.DictReader(open(tmp_path / "fitted" / "detections.csv")):
        found.setdefault(row["frame"], []).append((float(row["x"]), float(row["y"])))
    for record in summary["per_frame"]:  # the camera's clock: frame number / 30 fps, over 3 frames
        objects = truth[round(record["timestamp"] * 30) % 3]["objects"]
        assert found_where_rendered(found.get(record["frame"], []), objects), (record["frame"], found, objects)
    tracks = (tmp_path / "fitted" / "tracks.csv").read_text()
    assert main(["track", str(tmp_path / "fitted"), "--set", "output.rerun=null",
                 "--set", "tracking.method=online"]) == 0
    assert (tmp_path / "fitted" / "tracks.csv").read_text() == tracks


def test_fit_ground_on_a_live_camera_takes_its_next_frames(tilted, tmp_path, capsys):
    """README: `dpom-warp fit-ground realsense` starts the camera, fits the floor on its next
    frames with its accelerometer's up, and lets it go: the tilted scene's pose within 0.3 deg
    and 0.02 m."""
    from dpom_warp.sources.realsense import RealSenseLive

    cam = tilted_camera(tilted)
    try:
        cam.start()
        try:
            assert main(["fit-ground", "realsense", "--output", str(tmp_path / "pose.yaml")]) == 0
        finally:
            cam.stop()
        assert "up from the camera's accelerometer: [" in capsys.readouterr().err
        assert not RealSenseLive("realsense").sensor.get_active_streams()
    finally:
        cam.unregister()
    pose = yaml.safe_load((tmp_path / "pose.yaml").read_text())
    assert pose["camera_height"] == pytest.approx(2.2, abs=0.02) and pose["pitch_deg"] == pytest.approx(25, abs=0.3)
    assert pose["roll_deg"] == pytest.approx(4.0, abs=0.3)


def test_the_api_fits_a_live_cameras_floor_on_the_first_frames_it_is_given(tilted, tmp_path):
    """README: Detector.from_config(live config, first_frames=...) sets up as a live run does: the
    floor fitted on them (the tilted scene's pose within 0.3 deg and 0.02 m), the static planes
    found in them; then every person in view is found in each frame."""
    import numpy as np
    from PIL import Image

    from dpom_warp import Detector

    tmp, _, cfg, _, truth = tilted
    cfg = {**cfg, "input": {**cfg["input"], "background": None}}
    frames = [np.asarray(Image.open(f)) for f in sorted((tmp / "scene" / "frames").glob("*.png"))]
    cam = tilted_camera(tilted)  # the config is read from the camera (its size, intrinsics, accelerometer)
    try:
        det = Detector.from_config(cfg, first_frames=[frames[i % 3] for i in range(5)])
    finally:
        cam.unregister()
    fit = det.ground_fit
    assert fit["frames"] == ["first_frames (the first 5)"] and "structure" in det.setup.inference
    assert fit["camera_height"] == pytest.approx(2.2, abs=0.02)
    assert fit["pitch_deg"] == pytest.approx(25.0, abs=0.3) and fit["roll_deg"] == pytest.approx(4.0, abs=0.3)
    for i in range(3):
        got = [(d.x, d.y) for d in det.detect(frames[i]).detections]
        assert found_where_rendered(got, truth[i]["objects"]), (i, got)

"""The two real recordings of ../shared/data/real: the RealSense D435 .bag and the Azure Kinect
.mkv read with their size, intrinsics and depth values (against an independent decoding of their
messages and blocks), `dpom-warp info` on them, their floor fits with the recording's camera and
gravity (the IMU), and the one-line errors where no floor is in view."""

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from dpom_warp.cli import main

from paths import REAL
RS_BAG = REAL / "realsense_d435" / "single_depth_color_640x480.bag"
AZURE = REAL / "azure_kinect" / "recording.mkv"


@pytest.fixture(autouse=True)
def recording_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DPOM_WARP_CACHE", str(tmp_path / "recordings-cache"))


def run_posed(tmp_path, recording) -> None:
    """`dpom-warp run` on `recording`, its pose given (1.2 m up, pitch 10 degrees), into
    tmp_path/out without pictures; it must succeed."""
    cfg = {"device": "cpu", "input": {"frames": str(recording)},
           "camera": {"extrinsics": {"height": 1.2, "pitch_deg": 10.0}},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    path = tmp_path / "posed.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress"]) == 0


def ros1_image_messages(path: Path, topic: str):
    """Depth images of a ROS 1 bag read without rosbags: the bag format's records walked by
    hand (chunks, connections 0x07, message data 0x02; ROS 1 serialisation of sensor_msgs/Image)."""
    data = path.read_bytes()

    def fields(header):
        out, i = {}, 0
        while i < len(header):
            (n,) = struct.unpack_from("<i", header, i)
            k, _, v = header[i + 4:i + 4 + n].partition(b"=")
            out[k.decode()] = v
            i += 4 + n
        return out

    def records(buf, pos=0):
        """(header fields, body) of each record in `buf`, the records of chunks included."""
        while pos < len(buf):
            (hl,) = struct.unpack_from("<i", buf, pos)
            h = fields(buf[pos + 4:pos + 4 + hl])
            pos += 4 + hl
            (dl,) = struct.unpack_from("<i", buf, pos)
            body = buf[pos + 4:pos + 4 + dl]
            pos += 4 + dl
            if h.get("op", b"\x00")[0] == 0x05:  # a chunk (lz4 frames in RealSense recordings)
                if h["compression"] == b"lz4":
                    import lz4.frame

                    body = lz4.frame.decompress(body)
                elif h["compression"] == b"bz2":
                    import bz2

                    body = bz2.decompress(body)
                yield from records(body)
            else:
                yield h, body

    conns, images = {}, []
    for h, b2 in records(data, data.index(b"\n") + 1):  # after "#ROSBAG V2.0\n"
        op = h.get("op", b"\x00")[0]
        if op == 0x07:
            conns[struct.unpack("<i", h["conn"])[0]] = h["topic"].decode()
        elif op == 0x02 and conns.get(struct.unpack("<i", h["conn"])[0]) == topic:
            j = 12
            (n,) = struct.unpack_from("<i", b2, j)
            j += 4 + n  # frame_id
            height, width = struct.unpack_from("<II", b2, j)
            j += 8
            (n,) = struct.unpack_from("<i", b2, j)
            enc = b2[j + 4:j + 4 + n].decode()
            j += 4 + n + 1
            (n,) = struct.unpack_from("<i", b2, j + 4)  # after the row step
            images.append((enc, np.frombuffer(b2[j + 8:j + 8 + n], "<u2").reshape(height, width)))
    return images


def test_realsense_recording_reads_right_and_runs(tmp_path, capsys):
    from dpom_warp.sources import open_source

    src = open_source(RS_BAG)
    info = src.info()
    assert (info.width, info.height, info.frames, info.encoding) == (640, 480, 2, "mono16")
    assert info.intrinsics["fx"] == pytest.approx(390.43, abs=0.01) and info.intrinsics["cy"] == pytest.approx(242.19, abs=0.01)
    assert info.depth_scale == pytest.approx(0.001, rel=1e-6)
    ours = [fr.depth for fr in src.frames()]
    theirs = ros1_image_messages(RS_BAG, info.topic)
    assert len(ours) == len(theirs) == 2
    for a, (enc, b) in zip(ours, theirs):
        assert enc == "mono16" and np.array_equal(a, b)
        assert a[a > 0].min() == 341 and 3000 < a.max() < 3200
    run_posed(tmp_path, RS_BAG)
    assert sorted(p.name for p in (tmp_path / "out" / "maps").iterdir()) == ["000000.npy", "000001.npy"]
    capsys.readouterr()
    assert main(["info", str(RS_BAG), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["frames"] == 2 and (js["width"], js["height"]) == (640, 480)
    assert set(js["intrinsics"]) == {"fx", "fy", "cx", "cy"} and js["depth_scale"] == pytest.approx(0.001)


def test_info_names_the_sensor_streams_and_counts_the_rest(capsys):
    """`dpom-warp info` in words: the RealSense recording's 70 streams are its two image
    streams and two camera models by name, then the option values and device records counted
    by type (all of them in --json); the Azure Kinect file's one frame is one frame."""
    assert main(["info", str(RS_BAG)]) == 0
    out = capsys.readouterr().out
    (streams,) = [line for line in out.splitlines() if line.startswith("  streams: ")]
    named = streams.split("; and ")[0]
    assert named.count("sensor_msgs/msg/Image") == 2 and named.count("sensor_msgs/msg/CameraInfo") == 2
    assert "std_msgs" not in named and "and 66 more (std_msgs/msg/Float32 28, std_msgs/msg/String 28" in streams
    assert main(["info", str(RS_BAG), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["streams"]) == 70
    assert main(["info", str(AZURE)]) == 0
    out = capsys.readouterr().out
    assert "1 frame of 640x576" in out and "IMU (subtitle)" in out and "distortion: [0.54794, " in out
    # the tilt the accelerometer gives, by hand for a camera upright (up towards the image's top,
    # -y): pitch asin(-up_z) below the horizon, roll atan2(-up_x, -up_y)
    from dpom_warp.sources import open_source

    up = open_source(AZURE).info().gravity_up
    pitch, roll = math.degrees(math.asin(-up[2])), math.degrees(math.atan2(-up[0], -up[1]))
    (imu,) = [line for line in out.splitlines() if line.startswith("  IMU: yes (up in the depth camera's frame: [")]
    assert imu.endswith(f"]: pitch {pitch:.2f} deg, roll {roll:.2f} deg, as camera.extrinsics {{height: H}} "
                        f"takes them)"), imu


def test_azure_kinect_recording_reads_right_and_runs(tmp_path):
    import av

    from dpom_warp.sources import open_source

    src = open_source(AZURE)
    info = src.info()
    assert (info.width, info.height, info.frames, info.imu) == (640, 576, 1, True)
    assert info.depth_scale == 0.001 and len(info.distortion) == 8
    # the Azure Kinect SDK's NFOV unbinned depth camera of this device: fx ~ 504.6, cx ~ 332.8
    assert info.intrinsics["fx"] == pytest.approx(504.61, abs=0.01) and info.intrinsics["cx"] == pytest.approx(332.78, abs=0.01)
    (ours,) = [fr.depth for fr in src.frames()]
    with av.open(str(AZURE)) as c:  # FFmpeg's own decoding of the track
        s = next(s for s in c.streams if s.metadata.get("title") == "DEPTH")
        frame = next(f for f in c.decode(s))
        theirs = frame.to_ndarray()
    assert theirs.shape == ours.shape and np.array_equal(theirs.astype(np.uint16), ours)
    assert ours[ours > 0].min() == 165 and ours.max() == 3690
    run_posed(tmp_path, AZURE)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 1 and len(summary["config"]["camera"]["distortion"]) == 8


def test_azure_kinect_accelerometer_gives_up(tmp_path):
    """The IMU's gravity, turned into the depth camera's frame, is perpendicular to the
    recording's walls (its largest planes, found by Open3D in the depth frame), and becomes
    the floor fit's camera.ground.up when extrinsics are auto, written or left out (the
    default), and the config gives no up; a pose given leaves it alone."""
    import open3d as o3d

    from dpom_warp.loading import load_config
    from dpom_warp.geometry import Camera
    from dpom_warp.sources import open_source

    src = open_source(AZURE)
    info = src.info()
    up = np.array(info.gravity_up)
    assert abs(np.linalg.norm(up) - 1) < 1e-9 and up[1] < -0.9  # the camera stands upright
    depth = next(src.frames()).depth.astype(float) / 1000
    i = info.intrinsics
    cam = Camera(info.width, info.height, i["fx"], i["fy"], i["cx"], i["cy"], distortion=tuple(info.distortion))
    x, y = cam.normalised(*np.meshgrid(np.arange(cam.width), np.arange(cam.height)))
    ok = depth > 0
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
        np.stack([x[ok] * depth[ok], y[ok] * depth[ok], depth[ok]], 1))).voxel_down_sample(0.02)
    o3d.utility.random.seed(0)
    for _ in range(2):
        plane, inliers = cloud.segment_plane(0.02, 3, 1000)
        n = np.asarray(plane[:3]) / np.linalg.norm(plane[:3])
        assert len(inliers) > 2000 and abs(np.degrees(np.arccos(abs(n @ up))) - 90) < 1.0
        cloud = cloud.select_by_index(inliers, invert=True)
    cfg = {"device": "cpu", "input": {"frames": str(AZURE)}, "camera": {"extrinsics": "auto"},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]}}
    path = tmp_path / "az.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert np.allclose(load_config(path).ground.up, up, atol=1e-6)
    del cfg["camera"]["extrinsics"]  # left out: auto, the IMU's up as when written
    path.write_text(yaml.safe_dump(cfg))
    assert np.allclose(load_config(path).ground.up, up, atol=1e-6)
    cfg["camera"]["extrinsics"] = {"height": 1.0, "pitch_deg": 10.0}  # a pose given: no floor fit, no up taken
    path.write_text(yaml.safe_dump(cfg))
    assert load_config(path).ground.up == "auto"
    cfg["camera"] = {"extrinsics": "auto", "ground": {"up": [0, -1, 0]}}  # the config's own up wins
    path.write_text(yaml.safe_dump(cfg))
    assert tuple(load_config(path).ground.up) == (0, -1, 0)


def test_a_height_alone_takes_its_tilt_from_the_accelerometer(tmp_path, capsys):
    """camera.extrinsics {height: H} on the Azure Kinect recording (a desk: no floor to fit):
    the pitch and roll it leaves out are the accelerometer's, so that the pose's world up seen
    from the camera, R^T (0, 0, 1), is the recording's gravity up (to the 3 decimals of a degree
    the angles are kept to); the run says so. An angle given is kept and only the other taken;
    a recording without an accelerometer (the RealSense D435 file) leaves them 0, as before."""
    from dpom_warp.loading import load_config
    from dpom_warp.sources import open_source

    up = np.array(open_source(AZURE).info().gravity_up)
    cfg = {"device": "cpu", "input": {"frames": str(AZURE)}, "camera": {"extrinsics": {"height": 1.0}},
           "grid": {"x": [-1.5, 1.5, 0.1], "y": [0.5, 3.5, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    path = tmp_path / "h.yaml"
    path.write_text(yaml.safe_dump(cfg))
    loaded = load_config(path)
    rotation = loaded.camera.T_world_from_camera[:3, :3]
    np.testing.assert_allclose(rotation.T @ [0, 0, 1], up, atol=1e-4)
    assert loaded.camera.T_world_from_camera[2, 3] == 1.0 and set(loaded.imu_tilt) == {"pitch_deg", "roll_deg"}
    assert main(["run", str(path), "--no-progress"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "accelerometer" in x)
    assert line == (f"camera pitch {loaded.imu_tilt['pitch_deg']:.2f} deg, roll {loaded.imu_tilt['roll_deg']:.2f} deg "
                    f"from the recording's accelerometer (camera.extrinsics leaves pitch_deg and roll_deg out)")
    written = json.loads((tmp_path / "out" / "run.json").read_text())["config"]["camera"]["extrinsics"]
    assert {k: written[k] for k in ("pitch_deg", "roll_deg")} == loaded.imu_tilt
    cfg["camera"]["extrinsics"] = {"height": 1.0, "pitch_deg": 30.0}  # the pitch given wins
    path.write_text(yaml.safe_dump(cfg))
    loaded = load_config(path)
    assert loaded.resolved["camera"]["extrinsics"]["pitch_deg"] == 30.0 and set(loaded.imu_tilt) == {"roll_deg"}
    cfg["input"]["frames"] = str(REAL / "realsense_d435" / "single_depth_color_640x480.bag")  # no IMU
    cfg["camera"]["extrinsics"] = {"height": 1.0}
    path.write_text(yaml.safe_dump(cfg))
    loaded = load_config(path)
    assert loaded.imu_tilt == {}
    np.testing.assert_allclose(loaded.camera.T_world_from_camera[:3, :3].T @ [0, 0, 1], [0, -1, 0], atol=1e-12)
    # a camera looking down and past the vertical: up points behind it (-z) and to the image's
    # bottom (+y), a pitch of 180 - asin(0.95) = 108 deg, which pitch_deg (-90 to 90) cannot say
    from dpom_warp.config import ConfigError
    from dpom_warp.loading import tilt_from_gravity

    with pytest.raises(ConfigError, match=r"^camera.extrinsics: x.mkv's accelerometer has the camera tilted past "
                                          r"straight down \(pitch 108.2 deg"):
        tilt_from_gravity({"height": 3.0}, [0.0, 0.3122, -0.95], "x.mkv")


def run_auto_pose_fails(tmp_path, capsys, recording, camera=None) -> tuple:
    """`dpom-warp run` on `recording` with extrinsics auto (or the `camera` section given), which
    must exit 2: (the config's path, the one error line)."""
    cfg = {"device": "cpu", "input": {"frames": str(recording)},
           "camera": {"extrinsics": "auto"} if camera is None else camera,
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]}, "output": {"dir": str(tmp_path / "out")}}
    path = tmp_path / "auto.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress"]) == 2
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.startswith("dpom-warp: error:")]
    return path, line


def test_a_wall_faced_is_not_taken_for_a_floor_seen_from_above(tmp_path, capsys):
    """The RealSense recording faces an office wall 1.83 m away (no IMU): as a floor it would
    put the camera looking straight down from below the people it is to find, so extrinsics
    auto refuses it with a one-line error naming the recording and saying how to give the
    pose (it used to run, with the wall for a floor and a 'person' on the desk); nothing is
    written. The same plane as the floor of a camera 2.6 m up, and the same low plane with an
    up given or on a voxel grid, are left alone."""
    import dataclasses

    from dpom_warp.loading import load_config
    from dpom_warp.io import InputError
    from dpom_warp.camera_setup import refuse_low_view_from_above

    path, line = run_auto_pose_fails(tmp_path, capsys, RS_BAG)
    assert line.startswith(f"dpom-warp: error: {RS_BAG} (frame 000000) and 1 more frames: ")
    assert "a plane 1.83 m away facing the camera" in line and "more likely a wall" in line
    assert "camera.ground.up" in line and not (tmp_path / "out").exists()
    run = load_config(path)

    @dataclasses.dataclass
    class Fit:
        pitch_deg: float
        camera_height: float

    with pytest.raises(InputError, match="wall"):
        refuse_low_view_from_above(run, Fit(95.0, 1.5), "f")
    refuse_low_view_from_above(run, Fit(90.0, 2.6), "f")  # a ceiling camera
    refuse_low_view_from_above(run, Fit(75.0, 1.5), "f")  # a camera tilted down, not from above
    refuse_low_view_from_above(dataclasses.replace(run, ground=run.ground.model_copy(update={"up": (0.0, 0.0, -1.0)})),
                               Fit(90.0, 1.5), "f")  # up given: the user says it is a floor
    refuse_low_view_from_above(dataclasses.replace(run, grid=run.grid.model_copy(update={"mode": "voxel"})),
                               Fit(90.0, 1.5), "f")  # voxels (drones): no object height to stand below


def test_fit_ground_on_a_recording_takes_its_camera_frames_and_up(tmp_path, capsys):
    """`dpom-warp fit-ground RECORDING`: the recording's camera and first --frames readable
    frames (the pose is fit_ground_frames' on them, in metres), its accelerometer's up where
    it has one (the Azure Kinect desk: no floor near it, a one-line error naming the frame);
    frame files still need --camera."""
    from dpom_warp.geometry import Camera
    from dpom_warp.ground import fit_ground_frames
    from dpom_warp.io import units_to_metres
    from dpom_warp.sources import open_source

    out = tmp_path / "pose.yaml"
    assert main(["fit-ground", str(RS_BAG), "--output", str(out)]) == 0
    assert "fit-ground on 2 frame(s)" in out.read_text()
    pose = yaml.safe_load(out.read_text())
    src = open_source(RS_BAG)
    info, i = src.info(), src.info().intrinsics
    cam = Camera(info.width, info.height, i["fx"], i["fy"], i["cx"], i["cy"])
    want = fit_ground_frames([units_to_metres(fr.depth, info.depth_scale) for fr in src.frames()], cam)
    assert pose == want.report()
    assert main(["fit-ground", str(RS_BAG), "--frames", "1", "--output", str(out)]) == 0
    assert "fit-ground on 1 frame(s)" in out.read_text()
    capsys.readouterr()
    assert main(["fit-ground", str(AZURE)]) == 2
    err = capsys.readouterr().err
    assert "up from the recording's accelerometer: [0.0218, -0.9821, 0.1872]" in err
    assert f"dpom-warp: error: {AZURE} (frame 000000): no floor plane found" in err
    assert main(["fit-ground", str(REAL / "five_people" / "depth_mm.png")]) == 2
    assert "--camera: expected a camera YAML" in capsys.readouterr().err


def test_a_recording_with_no_floor_in_view_is_named_in_the_error(tmp_path, capsys):
    """The Azure Kinect recording looks at a desk: extrinsics auto finds no floor near its
    IMU's up, and the one-line error names the recording and its frame (not the cache's file)
    and the up it looked along; nothing is written. The same with the extrinsics left out
    (auto by default: it used to fit the wall behind the desk, 89 deg from the IMU's up, and
    run)."""
    for camera in (None, {}):
        _, line = run_auto_pose_fails(tmp_path, capsys, AZURE, camera)
        assert line.startswith(f"dpom-warp: error: {AZURE} (frame 000000): no floor plane found")
        assert "of up [0.022, -0.982, 0.187]" in line and ".cache" not in line
        assert not (tmp_path / "out").exists()


def test_the_configs_camera_wins_over_the_recordings_and_the_run_says_so(tmp_path, capsys):
    """README: camera keys the config gives win over the recording's, and the run says where they
    differ (one line each, naming the key, both values and which is used); the run's resolved
    config holds the config's. The RealSense recording's fx and depth scale given otherwise."""
    from dpom_warp.sources import open_source

    info = open_source(RS_BAG).info()
    i = dict(info.intrinsics)
    fx = round(i["fx"] * 1.1, 3)
    cfg = {"device": "cpu", "input": {"frames": str(RS_BAG), "depth_scale": 0.002},
           "camera": {"intrinsics": {**i, "fx": fx}, "extrinsics": {"height": 1.2, "pitch_deg": 0.0}},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(tmp_path / "c.yaml"), "--no-progress"]) == 0
    said = [x for x in capsys.readouterr().out.splitlines() if "differs from the recording's" in x]
    assert any(f"camera.intrinsics.fx: the config's {fx:g} differs from the recording's {i['fx']:g} "
               "(the config's is used)" in x for x in said), said
    assert any(f"input.depth_scale: the config's 0.002 differs from the recording's {info.depth_scale:g}" in x
               for x in said), said
    assert not any("intrinsics.fy" in x or "intrinsics.cx" in x for x in said)  # those agree
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["camera"]["intrinsics"]["fx"] == fx
    assert summary["config"]["input"]["depth_scale"] == 0.002

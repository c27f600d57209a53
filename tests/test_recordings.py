"""Recordings as input: ROS 1, ROS 2 (sqlite) and MCAP bags written here with rosbags from
rendered frames give the PNG run's detections (16UC1 and compressedDepth identical, 32FC1
within 1 mm of depth); the two real recordings read with their size, intrinsics and depth
values (against an independent decoding); `dpom-warp info`; the one-line errors."""

import csv
import json
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp.cli import main

from paths import REAL
RS_BAG = REAL / "realsense_d435" / "single_depth_color_640x480.bag"
AZURE = REAL / "azure_kinect" / "recording.mkv"


@pytest.fixture(autouse=True)
def recording_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DPOM_WARP_CACHE", str(tmp_path / "recordings-cache"))


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A small rendered sequence (4 frames) and its PNG run."""
    from test_cli import small_config

    tmp = tmp_path_factory.mktemp("rec")
    path = small_config(tmp, frames=4)
    cfg = yaml.safe_load(path.read_text())
    cfg["input"]["background"] = None
    cfg["output"]["images"] = False
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "png")]) == 0
    del cfg["synthetic"]
    cfg["evaluation"]["ground_truth"] = None
    return tmp, cfg


def rows(run: Path, rename=None):
    out = [r for r in csv.reader(open(run / "detections.csv"))][1:]
    return [[rename(r[0]) if rename else r[0]] + r[1:] for r in out]


def typestore(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def make(ts, msgtype, **values):
    """A message of the typestore's `msgtype` (its field names matched case-insensitively: ROS 1's
    CameraInfo says K where ROS 2's says k; a ROS 1 header has a seq)."""
    cls = ts.types[msgtype]
    names = {n.lower(): n for n in cls.__dataclass_fields__}
    if "seq" in names and "seq" not in values:
        values["seq"] = 0
    return cls(**{names[k.lower()]: v for k, v in values.items()})


def messages(ts, frames: list[Path], encoding: str, camera: dict | None, compressed=False, truncate=None,
             no_reading=np.nan, distortion=("plumb_bob", np.zeros(5))):
    """(topic, msgtype, message) in order: the camera info, then the depth frames (32FC1: the
    pixels without a reading hold `no_reading`)."""
    out = []
    for i, f in enumerate(frames):
        mm = np.asarray(Image.open(f)).astype(np.uint16)
        stamp = make(ts, "builtin_interfaces/msg/Time", sec=100 + i // 10, nanosec=(i % 10) * 100_000_000)
        head = make(ts, "std_msgs/msg/Header", stamp=stamp, frame_id="depth")
        if camera is not None and i == 0:
            k = np.array([camera["fx"], 0, camera["cx"], 0, camera["fy"], camera["cy"], 0, 0, 1], float)
            roi = make(ts, "sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0,
                       do_rectify=False)
            out.append(("/cam/depth/camera_info", "sensor_msgs/msg/CameraInfo", make(
                ts, "sensor_msgs/msg/CameraInfo", header=head, height=mm.shape[0], width=mm.shape[1],
                distortion_model=distortion[0], d=np.asarray(distortion[1], float), k=k, r=np.eye(3).ravel(),
                p=np.zeros(12),
                binning_x=0, binning_y=0, roi=roi)))
        if compressed:
            import io

            png = io.BytesIO()
            Image.fromarray(mm).save(png, format="PNG")
            data = np.frombuffer(struct.pack("<iff", 0, 0.0, 0.0) + png.getvalue(), np.uint8)
            out.append(("/cam/depth/image_raw/compressedDepth", "sensor_msgs/msg/CompressedImage",
                        make(ts, "sensor_msgs/msg/CompressedImage", header=head,
                             format="16UC1; compressedDepth png", data=data)))
            continue
        if encoding == "32FC1":
            m = mm.astype(np.float32) / 1000.0
            m[mm == 0] = no_reading  # REP 118: NaN (or 0, or inf) is no reading
            data, step = np.frombuffer(m.tobytes(), np.uint8), 4 * mm.shape[1]
        else:
            data, step = np.frombuffer(mm.tobytes(), np.uint8), 2 * mm.shape[1]
        if truncate == i:
            data = data[: len(data) // 2]
        out.append(("/cam/depth/image_raw", "sensor_msgs/msg/Image",
                    make(ts, "sensor_msgs/msg/Image", header=head, height=mm.shape[0], width=mm.shape[1],
                         encoding=encoding, is_bigendian=0, step=step, data=data)))
    return out


def write_bag(path: Path, kind: str, msgs):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    ts = typestore(kind == "ros1")
    if kind == "ros1":
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=8, storage_plugin=plugin)
    conns = {}
    with writer:
        for i, (topic, msgtype, msg) in enumerate(msgs):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            raw = ts.serialize_ros1(msg, msgtype) if kind == "ros1" else ts.serialize_cdr(msg, msgtype)
            writer.write(conns[topic], 1_000_000_000 + i * 1000, raw)
    return path


def recording_config(tmp_path, cfg, frames, name="rec.yaml", **extra):
    c = json.loads(json.dumps(cfg))
    c["input"] = {"frames": str(frames), **extra.pop("input", {})}
    for k in ("width", "height", "intrinsics"):
        c["camera"].pop(k)
    c["output"]["dir"] = str(tmp_path / "out")
    c.update(extra)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(c))
    return path


def camera_of(cfg):
    return dict(cfg["camera"]["intrinsics"])


PNG_NAME = "{:04d}.png"


def same_as_png(tmp_path, scene, out):
    png = rows(scene[0] / "png")
    rec = rows(out, rename=lambda n: PNG_NAME.format(int(n)))
    assert rec == png and png
    assert [r[0] for r in rows(out)][0] == "000000"  # frames named by their index in the stream


@pytest.mark.parametrize("kind", ["ros1", "ros2", "mcap"])
def test_16bit_bags_give_the_png_run(tmp_path, scene, kind):
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))
    name = {"ros1": "seq.bag", "ros2": "seq", "mcap": "seq"}[kind]
    bag = write_bag(tmp_path / name, kind, messages(typestore(kind == "ros1"), frames, "16UC1", camera_of(cfg)))
    if kind == "mcap":
        bag = next(bag.glob("*.mcap"))  # the .mcap file itself
    path = recording_config(tmp_path, cfg, bag)
    assert main(["run", str(path), "--no-progress"]) == 0
    same_as_png(tmp_path, scene, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["camera"]["intrinsics"] == camera_of(cfg)  # the camera from the bag
    assert summary["config"]["camera"]["width"] == cfg["camera"]["width"]
    assert [p["timestamp"] for p in summary["per_frame"]] == pytest.approx([100.0, 100.1, 100.2, 100.3])
    assert summary["tracking"]["fps_from"] == "timestamps" and summary["tracking"]["fps"] == pytest.approx(10.0)
    assert summary["tracking"]["frames_without_map"] == 0


def test_compressed_depth_and_32fc1_bags(tmp_path, scene):
    """compressedDepth PNG gives the same detections; 32FC1 metres (NaN = no reading) too,
    its depth within 1 mm of the PNG's."""
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))
    ts = typestore(False)
    bag = write_bag(tmp_path / "comp", "ros2", messages(ts, frames, "16UC1", camera_of(cfg), compressed=True))
    (tmp_path / "a").mkdir()
    assert main(["run", str(recording_config(tmp_path / "a", cfg, bag)), "--no-progress"]) == 0
    same_as_png(tmp_path, scene, tmp_path / "a" / "out")
    bag = write_bag(tmp_path / "float.bag", "ros1", messages(typestore(True), frames, "32FC1", camera_of(cfg)))
    (tmp_path / "b").mkdir()
    assert main(["run", str(recording_config(tmp_path / "b", cfg, bag)), "--no-progress"]) == 0
    same_as_png(tmp_path, scene, tmp_path / "b" / "out")
    from dpom_warp.sources import open_source

    for fr, f in zip(open_source(bag).frames(), frames):
        mm = np.asarray(Image.open(f)).astype(np.float64)
        metres = np.nan_to_num(fr.depth.astype(np.float64))
        assert np.abs(metres * 1000 - mm).max() <= 1.0


def test_a_truncated_message_is_skipped_with_its_reason(tmp_path, scene, capsys):
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))
    bag = write_bag(tmp_path / "bad.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg),
                                                           truncate=2))
    path = recording_config(tmp_path, cfg, bag)
    assert main(["run", str(path), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["skipped"][0]["frame"] == "000002"
    assert "truncated image" in summary["skipped"][0]["reason"]
    # the tracker knows a camera frame lies between the maps of 000001 and 000003 (their stamps)
    assert summary["tracking"]["frames_without_map"] == 1 and summary["tracking"]["fps"] == pytest.approx(10.0)
    from dpom_warp import Detector
    from dpom_warp.sources import open_source
    from dpom_warp.track_files import tracks_csv

    det = Detector.from_config(path)  # the Python API over the recording's frames: the run's results
    results, times, names = [], [], []
    for fr in open_source(bag).frames():
        if fr.depth is not None:
            results.append(det.detect(fr.depth))
            times.append(fr.timestamp)
            names.append(f"{fr.index:06d}")
    assert [[n, f"{d.x:.4f}", f"{d.y:.4f}"] for n, r in zip(names, results) for d in r.detections] \
        == [r[:3] for r in rows(tmp_path / "out")]
    tracks, report = det.track(results, times=times)
    assert report["frames_without_map"] == 1 and report["fps"] == pytest.approx(10.0)
    assert tracks_csv(tracks, names) == (tmp_path / "out" / "tracks.csv").read_text()
    assert "skipping" in capsys.readouterr().out
    assert main(["run", str(path), "--no-progress", "--overwrite", "--strict"]) == 2


def test_recording_errors_are_one_line(tmp_path, scene, capsys):
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:2]
    ts = typestore(True)
    two = messages(ts, frames, "16UC1", camera_of(cfg))
    two += [(t.replace("image_raw", "other"), m, x) for t, m, x in messages(ts, frames, "16UC1", None)]
    bag = write_bag(tmp_path / "two.bag", "ros1", two)
    cases = [
        (recording_config(tmp_path, cfg, bag), "input.topic: ", "has 2 depth streams; expected one chosen, "
                                                                "found /cam/depth/image_raw, /cam/depth/other"),
        (recording_config(tmp_path, cfg, bag, "nope.yaml", input={"topic": "/nope"}), "input.topic: ",
         "has no depth stream '/nope'"),
    ]
    nocam = write_bag(tmp_path / "nocam.bag", "ros1", messages(ts, frames, "16UC1", None))
    cases.append((recording_config(tmp_path, cfg, nocam, "nocam.yaml"), "camera.intrinsics: required key is missing",
                  "carries no camera information"))
    other = tmp_path / "clip.avi"
    other.write_bytes(b"RIFF")
    c = json.loads(json.dumps(cfg))
    c["input"]["frames"] = str(other)
    p = tmp_path / "avi.yaml"
    p.write_text(yaml.safe_dump(c))
    cases.append((p, "input.frames: ", "unknown format '.avi'"))
    for path, start, part in cases:
        assert main(["run", str(path), "--no-progress", "--overwrite"]) == 2, part
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and err.startswith("dpom-warp: error: ") and start in err and part in err, err
    assert not (tmp_path / "out").exists()  # nothing written


def test_without_the_sensors_extra_the_error_says_how_to_install(monkeypatch):
    from dpom_warp import sources
    from dpom_warp.io import InputError

    with pytest.raises(InputError, match=r'needs the optional package nonexistent_reader; install it with '
                                         r'pip install "dpom-warp\[sensors\]"'):
        sources.need("nonexistent_reader", "input.frames: x.bag (a ROS bag)")


# -- the real recordings ----------------------------------------------------------------------
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
    cfg = {"device": "cpu", "input": {"frames": str(RS_BAG)},
           "camera": {"extrinsics": {"height": 1.2, "pitch_deg": 10.0}},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    path = tmp_path / "rs.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress"]) == 0
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
    cfg = {"device": "cpu", "input": {"frames": str(AZURE)},
           "camera": {"extrinsics": {"height": 1.2, "pitch_deg": 10.0}},
           "grid": {"x": [-2, 2, 0.1], "y": [0.5, 4.0, 0.1]},
           "output": {"dir": str(tmp_path / "out"), "images": False}}
    path = tmp_path / "az.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress"]) == 0
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


def test_realsense_sdk_db3_gives_the_png_run(tmp_path, scene):
    """A RealSense SDK recording (.db3, compressedDepth) made by the SDK's own recorder from a
    SoftwareCamera playing the rendered frames: the PNG run's detections."""
    from dpom_warp.sources.software import SoftwareCamera

    tmp, cfg = scene
    frames = [np.asarray(Image.open(f)).astype(np.uint16) for f in sorted((tmp / "scene" / "frames").glob("*.png"))]
    i = cfg["camera"]["intrinsics"]
    db3 = tmp_path / "sdk.db3"
    assert SoftwareCamera(frames, i["fx"], i["fy"], i["cx"], i["cy"]).record(db3) == len(frames)
    path = recording_config(tmp_path, cfg, db3)
    assert main(["run", str(path), "--no-progress"]) == 0
    same_as_png(tmp_path, scene, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["camera"]["intrinsics"] == pytest.approx(camera_of(cfg))


def test_the_cache_folder_is_dpom_warp_cache_itself_and_the_fit_names_the_recording(tmp_path, scene):
    """$DPOM_WARP_CACHE is the folder recordings are read into, as the README says (it was the
    parent of a `recordings` folder in it); a floor fitted on a recording's frames is reported in
    summary.json by the recording and frame, not by the cache's files."""
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))
    bag = write_bag(tmp_path / "walk.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg)))
    c = json.loads(json.dumps(cfg))
    c["camera"]["extrinsics"] = "auto"
    c["camera"]["ground"] = {"frames": 2}
    path = recording_config(tmp_path, c, bag)
    assert main(["run", str(path), "--no-progress"]) == 0
    cache = tmp_path / "recordings-cache"
    read = [p.parent for p in cache.glob("*/source.json")]
    assert len(read) == 1 and read[0].name.startswith("walk-"), sorted(cache.iterdir())
    fit = json.loads((tmp_path / "out" / "summary.json").read_text())["ground_fit"]
    assert fit["frames"] == [f"{bag} (frame 000000)", f"{bag} (frame 000001)"]


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


def test_a_changed_recording_is_read_again(tmp_path, scene):
    """README: the cache is keyed by the recording's path, size and modification time, so a
    recording written again at the same path (here 4 frames, then its first 2) is read again:
    the second run reads 2 frames, from a new cache folder, and the first's folder is left as it
    was."""
    import os

    from dpom_warp.sources import expand

    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))
    bag = tmp_path / "same.bag"
    write_bag(bag, "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg)))
    first = expand(str(bag), "input.frames")
    assert len(first) == 4
    bag.unlink()
    write_bag(bag, "ros1", messages(typestore(True), frames[:2], "16UC1", camera_of(cfg)))
    os.utime(bag, ns=(bag.stat().st_atime_ns, bag.stat().st_mtime_ns + 1_000_000_000))  # (coarse clocks)
    second = expand(str(bag), "input.frames")
    assert len(second) == 2 and second[0].parent != first[0].parent
    assert all(f.exists() for f in first)
    np.testing.assert_array_equal(np.load(second[1]), np.load(first[1]))  # the same frame, read again


@pytest.mark.parametrize("no_reading", [0.0, np.inf, -np.inf])
def test_32fc1_zeros_and_infinities_are_no_reading(tmp_path, scene, no_reading):
    """README: in a 32FC1 depth image 0 and +-inf are no reading, as NaN is (REP 118): the frames
    read from such a bag are the PNG frames' millimetres, 0 where they have none."""
    from dpom_warp.sources import expand

    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:2]
    bag = write_bag(tmp_path / "f.bag", "ros1", messages(typestore(True), frames, "32FC1", camera_of(cfg),
                                                          no_reading=no_reading))
    got = expand(str(bag), "input.frames")
    for cached, png in zip(got, frames):
        mm = np.asarray(Image.open(png)).astype(np.int64)
        assert (mm == 0).sum() > 100
        read = np.load(cached).astype(np.int64)
        assert np.array_equal(read == 0, mm == 0) and np.abs(read - mm).max() <= 1


def test_a_bags_rational_polynomial_lens_is_read(tmp_path, scene, capsys):
    """README: a CameraInfo's D in plumb_bob (5) or rational_polynomial (8 coefficients) becomes
    camera.distortion; another model is a one-line error naming the bag, the topic, the model and
    what is expected."""
    from dpom_warp.sources import open_source

    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:1]
    d8 = [0.1, -0.05, 0.001, 0.002, 0.01, 0.2, -0.03, 0.005]
    bag = write_bag(tmp_path / "rp.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg),
                                                           distortion=("rational_polynomial", d8)))
    assert list(open_source(bag).info().distortion) == pytest.approx(d8)
    bad = write_bag(tmp_path / "eq.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg),
                                                           distortion=("equidistant", [0.1, 0.0, 0.0, 0.0])))
    assert main(["info", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "distortion model 'equidistant' with 4 coefficients; expected plumb_bob (5) or rational_polynomial (8)" in err
    assert str(bad) in err and "\n" not in err


def imu_messages(ts, n: int, acc, frame_id: str) -> list:
    """`n` sensor_msgs/Imu messages at rest reading `acc` (m/s^2) in `frame_id`."""
    out = []
    for i in range(n):
        stamp = make(ts, "builtin_interfaces/msg/Time", sec=100, nanosec=i * 1_000_000)
        vec = [make(ts, "geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))
               for v in ((0, 0, 0), acc)]
        out.append(("/cam/imu", "sensor_msgs/msg/Imu", make(
            ts, "sensor_msgs/msg/Imu", header=make(ts, "std_msgs/msg/Header", stamp=stamp, frame_id=frame_id),
            orientation=make(ts, "geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=vec[0], angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec[1], linear_acceleration_covariance=np.zeros(9))))
    return out


def test_gravity_from_a_ros_imu_in_the_depth_frame(tmp_path, scene):
    """README: a ROS bag's sensor_msgs/Imu in the depth image's own frame gives the floor fit its
    up (the mean acceleration at rest, normalised: an accelerometer reads +g upwards), which
    extrinsics auto takes as camera.ground.up; an IMU in another frame is not used (its
    transform is not read)."""
    from dpom_warp.loading import load_config
    from dpom_warp.sources import open_source

    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:2]
    acc = (0.3, -9.7, 1.2)
    want = np.array(acc) / np.linalg.norm(acc)
    ts = typestore(True)
    bag = write_bag(tmp_path / "imu.bag", "ros1",
                    messages(ts, frames, "16UC1", camera_of(cfg)) + imu_messages(ts, 5, acc, "depth"))
    assert np.allclose(open_source(bag).info().gravity_up, want, atol=1e-9)
    run = {"device": "cpu", "input": {"frames": str(bag)}, "grid": {"x": [-2, 2, 0.2], "y": [1, 6, 0.2]}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(run))
    assert np.allclose(load_config(tmp_path / "c.yaml").ground.up, want, atol=1e-6)
    other = write_bag(tmp_path / "other.bag", "ros1",
                      messages(ts, frames, "16UC1", camera_of(cfg)) + imu_messages(ts, 5, acc, "imu_link"))
    assert open_source(other).info().gravity_up is None


def test_fit_ground_topic_picks_the_depth_stream(tmp_path, scene, capsys):
    """README: `dpom-warp fit-ground RECORDING --topic TOPIC` fits the floor in that stream. A bag
    with two depth streams of the rendered room (camera 2.2 m up, pitch 20 deg): the first as
    rendered, the second with every depth x 0.8, which puts the floor 0.8 x 2.2 = 1.76 m below
    the camera at the same pitch. Without --topic the choice is a one-line error naming both."""
    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:2]
    nearer = []
    for f in frames:
        mm = np.asarray(Image.open(f)).astype(np.float64)
        nearer.append(tmp_path / f.name)
        Image.fromarray(np.round(mm * 0.8).astype(np.uint16)).save(nearer[-1])
    ts = typestore(True)
    msgs = messages(ts, frames, "16UC1", camera_of(cfg))
    msgs += [(t.replace("image_raw", "nearer"), m, x) for t, m, x in messages(ts, nearer, "16UC1", None)]
    bag = write_bag(tmp_path / "two.bag", "ros1", msgs)
    assert main(["fit-ground", str(bag)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "found /cam/depth/image_raw, /cam/depth/nearer" in err
    for topic, height in (("/cam/depth/image_raw", 2.2), ("/cam/depth/nearer", 1.76)):
        out = tmp_path / f"{topic.rsplit('/', 1)[1]}.yaml"
        assert main(["fit-ground", str(bag), "--topic", topic, "--output", str(out)]) == 0
        pose = yaml.safe_load(out.read_text())
        assert pose["camera_height"] == pytest.approx(height, abs=0.02), topic
        assert pose["pitch_deg"] == pytest.approx(20.0, abs=0.3) and abs(pose["roll_deg"]) < 0.3, topic

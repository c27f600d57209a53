"""Recordings as input: ROS 1, ROS 2 (sqlite) and MCAP bags written here with rosbags from
rendered frames give the PNG run's detections (16UC1 and compressedDepth identical, 32FC1
within 1 mm of depth), and so does a RealSense SDK recording; the recordings' cache; the
one-line errors. The real recordings of ../shared/data/real: test_real_recordings.py."""

import csv
import json
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp.cli import main


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
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # Noetic's store has no tf2_msgs; a ROS 1 bag carries the definition it writes
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return ts


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


def tf_static(ts, transforms) -> tuple:
    """A /tf_static message of (parent, child, quaternion x, y, z, w) transforms."""
    stamp = make(ts, "builtin_interfaces/msg/Time", sec=100, nanosec=0)
    return ("/tf_static", "tf2_msgs/msg/TFMessage", make(ts, "tf2_msgs/msg/TFMessage", transforms=[make(
        ts, "geometry_msgs/msg/TransformStamped", header=make(ts, "std_msgs/msg/Header", stamp=stamp, frame_id=parent),
        child_frame_id=child, transform=make(
            ts, "geometry_msgs/msg/Transform",
            translation=make(ts, "geometry_msgs/msg/Vector3", x=0.01, y=0.02, z=0.03),
            rotation=make(ts, "geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3])))
        for parent, child, q in transforms]))


def test_a_quaternions_rotation_is_scipys():
    """transforms.quaternion_matrix (x, y, z, w, normalised first) against SciPy's, on random
    rotations given at other lengths; a zero quaternion is an error."""
    from scipy.spatial.transform import Rotation

    from dpom_warp.sources.transforms import quaternion_matrix

    rng = np.random.default_rng(3)
    for q in Rotation.random(20, random_state=4).as_quat():
        np.testing.assert_allclose(quaternion_matrix(*(q * rng.uniform(0.2, 5))), Rotation.from_quat(q).as_matrix(),
                                   atol=1e-12)
    with pytest.raises(ValueError):
        quaternion_matrix(0, 0, 0, 0)


@pytest.mark.parametrize("kind", ["ros1", "ros2"])
def test_gravity_from_an_imu_in_another_frame_through_the_static_transforms(tmp_path, scene, kind):
    """README: an IMU in a frame of its own (a robot's imu_link) is turned into the depth image's
    frame by the bag's /tf_static, along a chain of transforms walked either way: here
    depth <- camera_link (written camera_link -> depth, walked backwards) -> imu_link. The
    IMU reads `want` (the up in the depth frame) as R_imu_depth want g, with the rotations
    built by SciPy, not by the reader; without /tf_static the IMU gives no up."""
    from scipy.spatial.transform import Rotation

    from dpom_warp.sources import open_source

    tmp, cfg = scene
    frames = sorted((tmp / "scene" / "frames").glob("*.png"))[:2]
    want = np.array([0.3, -9.7, 1.2]) / np.linalg.norm([0.3, -9.7, 1.2])
    link_from_depth = Rotation.from_euler("xyz", [-90, 0, -90], degrees=True)  # ROS's optical frame under a link
    imu_from_link = Rotation.from_euler("zyx", [30, -12, 5], degrees=True)
    reading = 9.81 * (imu_from_link * link_from_depth).apply(want)  # in imu_link's axes
    ts = typestore(kind == "ros1")
    msgs = messages(ts, frames, "16UC1", camera_of(cfg)) + imu_messages(ts, 5, reading, "imu_link")
    plain = write_bag(tmp_path / f"no_tf.{'bag' if kind == 'ros1' else 'db3'}", kind, msgs)
    assert open_source(plain).info().gravity_up is None
    tf = tf_static(ts, [("camera_link", "depth", link_from_depth.as_quat()),
                        ("camera_link", "/imu_link", imu_from_link.inv().as_quat())])
    bag = write_bag(tmp_path / f"tf.{'bag' if kind == 'ros1' else 'db3'}", kind, [tf] + msgs)
    np.testing.assert_allclose(open_source(bag).info().gravity_up, want, atol=1e-9)


def test_a_realsense_sdk_recordings_accelerometer_gives_up(tmp_path, scene):
    """A RealSense SDK recording of a camera with an accelerometer (a D435i's, made by the SDK's
    own recorder from a SoftwareCamera with a motion module): its readings are in the depth
    sensor's axes (librealsense aligns them; the recording's IMU frame is "Accel", the depth's
    "Depth"), so its up is their direction, and a config that leaves the extrinsics out takes
    it as camera.ground.up."""
    from dpom_warp.loading import load_config
    from dpom_warp.sources import open_source
    from dpom_warp.sources.software import SoftwareCamera

    tmp, cfg = scene
    frames = [np.asarray(Image.open(f)).astype(np.uint16) for f in sorted((tmp / "scene" / "frames").glob("*.png"))[:2]]
    i = cfg["camera"]["intrinsics"]
    acc = (0.4, -9.3, -3.1)
    db3 = tmp_path / "d435i.db3"
    assert SoftwareCamera(frames, i["fx"], i["fy"], i["cx"], i["cy"], accel=acc).record(db3) == 2
    info = open_source(db3).info()
    assert info.imu and any(s["topic"].endswith("/Accel_0/imu/data") for s in info.streams)
    np.testing.assert_allclose(info.gravity_up, np.array(acc) / np.linalg.norm(acc), atol=1e-6)
    run = {"device": "cpu", "input": {"frames": str(db3)}, "grid": {"x": [-2, 2, 0.2], "y": [1, 6, 0.2]}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(run))
    np.testing.assert_allclose(load_config(tmp_path / "c.yaml").ground.up, np.array(acc) / np.linalg.norm(acc),
                               atol=1e-6)


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

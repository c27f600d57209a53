"""A rig of live cameras: the pairing of the cameras' frames as they arrive (sources.rig.RigStream,
on hand-timed frames), and a live rig run end to end: two SoftwareCameras (pyrealsense2's
software_device, serials 101 and 102) play test_rig_run's rendered two-camera scene, and every
map of the live run is the recorded rig run's map of the same rendered frame, bit for bit."""

import copy
import json
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dpom_warp.cli import main
from dpom_warp.sources.base import Frame, Source, SourceInfo
from dpom_warp.sources.rig import RigStream

from test_rig_run import rig_config, write

FPS = 5.0  # the software cameras' rate: a 0.1 s pairing tolerance, far above their threads' offsets


class Handed(Source):
    """A live source whose frames the test hands in (`send`), on the test's thread."""

    def __init__(self, rate=10.0):
        self.rate, self.on_frame, self.stopped = rate, None, False

    def info(self):
        return SourceInfo(kind="handed", path="", frames=0, width=4, height=3, rate_hz=self.rate)

    def start(self, on_frame):
        self.on_frame = on_frame

    def stop(self):
        self.stopped = True

    def send(self, index, arrived):
        self.on_frame(None if index is None else Frame(index, None, np.full((3, 4), index), arrived=arrived))


def stream(n=2, tolerance=None):
    sources = [Handed() for _ in range(n)]
    rig = RigStream(sources, [f"c{i}" for i in range(n)], tolerance)
    got = []
    rig.start(got.append)
    return sources, rig, got


def indices(frame):
    return [p.index if p is not None else None for p in frame.parts]


def test_a_rig_frame_waits_for_a_camera_that_lags_within_the_tolerance():
    """10 frames/s: the tolerance left out is half a frame period, 0.05 s. The first camera's
    frame at t = 1.00 is held (the second camera's last, at 0.93, has its next due at 1.03,
    nearer) until the second camera's at 1.02 comes (nothing nearer can come after it), then
    paired with it, not with the one at 0.93 (a 5 s tolerance here: the test's thread may stall
    for longer than 0.05 s, after which the frame would go with what came)."""
    assert stream()[1].tolerance == pytest.approx(0.05)
    (a, b), rig, got = stream(tolerance=5.0)
    b.send(7, 0.93)
    a.send(0, 1.00)
    assert got == []  # waiting for the second camera
    b.send(8, 1.02)
    assert len(got) == 1 and indices(got[0]) == [0, 8]
    assert np.array_equal(got[0].depth[1], np.full((3, 4), 8)) and got[0].index == 0
    rig.stop()


def test_a_camera_just_ahead_is_not_waited_for():
    """The second camera sent at 0.99 (10 frames/s: its next is due at 1.09, farther from 1.00
    than 0.99 is): the first camera's frame at 1.00 goes at once, paired with it."""
    (a, b), rig, got = stream()
    b.send(4, 0.99)
    a.send(0, 1.00)
    assert [indices(f) for f in got] == [[0, 4]]


def test_the_nearest_frame_within_the_tolerance_is_taken():
    """The second camera sent at 0.97 and 1.04 before the first camera's 1.00 came (it is
    complete at once): 0.97 (0.03 away) is nearer than 1.04 (0.04)."""
    (a, b), rig, got = stream()
    b.send(3, 0.97)
    b.send(4, 1.04)
    a.send(0, 1.00)
    assert [indices(f) for f in got] == [[0, 3]]


def test_a_camera_with_no_frame_near_in_time_is_none_after_the_tolerance():
    """The second camera's only frame is 0.2 s old: the rig frame goes after the tolerance
    (real time, a timer), that camera None, its depth None."""
    (a, b), rig, got = stream(tolerance=0.05)
    b.send(1, time.perf_counter() - 0.2)
    a.send(0, time.perf_counter())
    deadline = time.perf_counter() + 2.0
    while not got and time.perf_counter() < deadline:
        time.sleep(0.005)
    assert [indices(f) for f in got] == [[0, None]] and got[0].depth[1] is None


def test_a_newer_first_frame_sends_the_one_waiting_and_the_end_follows_the_last():
    """The first camera's frame 0 waits for a second camera that sends nothing near: its frame
    1 sends frame 0 with what came (nothing). After the first camera's last frame (2) its end
    waits until that frame is paired (the second camera's frame of the same moment, 1.21,
    comes after the end: a played rig's cameras end together), then the end (None) follows;
    the sources stop with the stream."""
    (a, b), rig, got = stream(tolerance=10.0)
    a.send(0, 1.0)
    a.send(1, 1.1)
    assert [indices(f) for f in got] == [[0, None]]
    b.send(5, 1.12)  # complete: after frame 1 arrived
    assert [indices(f) for f in got] == [[0, None], [1, 5]]
    a.send(2, 1.2)
    a.send(None, None)
    assert len(got) == 2  # frame 2 waits: the second camera's next is due at 1.22, nearer than 1.12
    b.send(6, 1.21)
    assert [indices(f) if f is not None else None for f in got] == [[0, None], [1, 5], [2, 6], None]
    rig.stop()
    assert a.stopped and b.stopped


def test_one_live_camera_twice_in_a_rig_is_one_line(tmp_path, capsys):
    """Two cameras of a live rig naming the same camera: a one-line error naming the second
    camera's key, before any camera is opened (a live camera beside recorded frames: test_rig)."""
    cfg = {"device": "cpu", "grid": {"x": [-1, 1, 0.1], "y": [1, 3, 0.1]},
           "cameras": [{"name": n, "input": {"frames": "realsense:101"}, "camera": {
               "width": 64, "height": 48, "intrinsics": {"fx": 50, "fy": 50, "cx": 31.5, "cy": 23.5},
               "extrinsics": {"height": 1.5, "pitch_deg": 10}}} for n in ("a", "b")],
           "output": {"dir": str(tmp_path / "out")}}
    assert main(["run", write(tmp_path / "rig.yaml", cfg), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("cameras[1].input.frames: expected another camera than cameras[0]'s, found realsense:101 "
                        "again (name each by its serial: realsense:SERIAL)") and "\n" not in err, err
    assert not (tmp_path / "out").exists()


def test_a_live_rig_camera_left_to_fit_its_floor_is_one_line(tmp_path, capsys):
    """One camera's floor fit is no place in the rig's world: a live rig camera with extrinsics
    auto is a one-line error naming its key and calibrate, before any camera is opened (one
    live camera fits its floor on its first frames: test_live)."""
    cfg = {"device": "cpu", "grid": {"x": [-1, 1, 0.1], "y": [1, 3, 0.1]},
           "cameras": [{"name": n, "input": {"frames": f"realsense:{s}", "depth_scale": 0.001}, "camera": {
               "width": 64, "height": 48, "intrinsics": {"fx": 50, "fy": 50, "cx": 31.5, "cy": 23.5},
               "distortion": None, "extrinsics": e, "ground": {"up": [0, -1, 0]}}}
                       for n, s, e in (("a", 101, {"height": 1.5, "pitch_deg": 10, "roll_deg": 0}), ("b", 102, "auto"))],
           "output": {"dir": str(tmp_path / "out")}}
    assert main(["run", write(tmp_path / "rig.yaml", cfg), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("cameras[1].camera.extrinsics: auto: a live rig's cameras are placed in one world by "
                        "`dpom-warp calibrate` on recordings of them; expected each camera's pose "
                        "({T_world_from_camera: ...}, as calibrate writes it)") and "\n" not in err, err
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """test_rig_run's scene run recorded (its maps, by rendered frame), and a live rig config of
    it: each camera a SoftwareCamera (serial 101, 102) with the camera's intrinsics."""
    folder = tmp_path_factory.mktemp("liverig")
    assert main(["run", write(folder / "rig.yaml", rig_config(folder)), "--no-progress"]) == 0
    maps = [np.load(p) for p in sorted((folder / "out" / "maps").glob("*.npy"))]
    assert len(maps) == 6
    live = rig_config(folder, out="live")
    live.pop("synthetic")
    live["evaluation"]["ground_truth"] = None
    for cam, serial in zip(live["cameras"], ("101", "102")):
        cam["input"]["frames"] = f"realsense:{serial}"
        cam["input"].pop("fps")
        for k in ("width", "height", "intrinsics"):
            cam["camera"].pop(k)
    return folder, maps, live


def software_rig(folder) -> list:
    """The scene's two cameras as SoftwareCameras (serials 101, 102) at FPS, registered, not started."""
    from dpom_warp.sources.software import SoftwareCamera

    return [SoftwareCamera([np.asarray(Image.open(f), np.uint16)
                            for f in sorted((folder / "scene" / name / "frames").glob("*.png"))],
                           115.0, 115.0, 79.5, 59.5, fps=FPS, serial=serial).register()
            for name, serial in (("front", "101"), ("side", "102"))]


@pytest.mark.parametrize("workers", [1, 2])
def test_a_live_rig_gives_the_recorded_rigs_maps(recorded, tmp_path, workers, monkeypatch):
    """Both cameras sending at 5 frames/s from one start: each rig frame pairs the two cameras'
    frames of one rendered frame (the software camera's timestamp says which), and its map is the
    recorded rig run's of that frame, bit for bit, inferred here or (--workers 2) by a helper
    process; the records say when each camera's frame arrived, summary.json what each sent;
    `dpom-warp track` gives its online tracks again."""
    from dpom_warp.worker import FrameWorker

    folder, maps, live = recorded
    live = copy.deepcopy(live)  # (the fixture's, shared by the tests)
    live["output"]["dir"] = str(tmp_path / "out")
    path = write(tmp_path / "live.yaml", live)
    if workers == 2:  # this process slower than the frames come: the helper takes some (its own process is not)
        real = FrameWorker.infer
        monkeypatch.setattr(FrameWorker, "infer", lambda self, small: time.sleep(0.3) or real(self, small))
    cams = software_rig(folder)
    try:
        for cam in cams:
            cam.start()
        assert main(["run", path, "--no-progress", "--max-frames", "5", "--workers", str(workers)]) == 0
    finally:
        for cam in cams:
            cam.stop()
            cam.unregister()
    out = tmp_path / "out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["live"]["frames"] == 5 and summary["live"]["processes"] == workers
    assert set(summary["live"]["cameras"]) == {"front", "side"}
    assert {n: c["frames"] for n, c in summary["cameras"].items()} == {"front": 5, "side": 5}
    for rec in summary["per_frame"]:
        name = rec["frame"]
        record = json.loads((out / "frames" / f"{name}.json").read_text())
        assert abs(record["stats"]["arrived_ms"]["side"]) <= 100 and record["stats"]["arrived_ms"]["front"] == 0
        rendered = round(record["timestamp"] * FPS) % 6  # the software camera's clock: frame number / fps
        np.testing.assert_array_equal(np.load(out / "maps" / f"{name}.npy"), maps[rendered], err_msg=name)
    if workers == 2:
        assert any(r["worker"].startswith("process ") for r in summary["per_frame"])
    else:  # `dpom-warp track` on it: the online tracks again from its maps, at the cameras' rate
        tracks = (out / "tracks.csv").read_text()
        assert main(["track", str(out), "--set", "output.images=false", "--set", "tracking.method=online"]) == 0
        assert (out / "tracks.csv").read_text() == tracks


def test_a_floor_only_live_rig_finds_each_cameras_planes_in_its_first_frames(recorded, tmp_path):
    """Floor-only (no background frames): the first input.structure.frames rig frames are each
    camera's for its static planes (not inferred), as a recorded floor-only rig's first files;
    the helper process then infers with them (--workers 2)."""
    folder, _, live = recorded
    live = copy.deepcopy(live)
    live["output"]["dir"] = str(tmp_path / "out")
    for cam in live["cameras"]:
        cam["input"]["background"] = None
    path = write(tmp_path / "live.yaml", live)
    cams = software_rig(folder)
    try:
        for cam in cams:
            cam.start()
        assert main(["run", path, "--no-progress", "--max-frames", "2", "--workers", "2"]) == 0
    finally:
        for cam in cams:
            cam.stop()
            cam.unregister()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["live"]["structure_frames"] == 5 and summary["live"]["frames"] == 2
    structure = summary["inference"]["structure"]
    assert set(structure) == {"front", "side"} and all("planes" in r for r in structure.values())
    assert summary["cameras"]["front"]["frames"] == summary["cameras"]["side"]["frames"] == 2


def test_a_played_rig_gives_the_recorded_rigs_maps(recorded, tmp_path):
    """--play on a rig config (input.play set on every camera): each camera's frames are sent at
    their rig frame's time (input.fps 5) from one start and paired again as they arrive; every
    map written is the recorded rig run's map of the same frame, bit for bit, and every frame
    sent is written or counted as dropped."""
    folder, maps, _ = recorded
    out = tmp_path / "out"
    assert main(["run", str(folder / "rig.yaml"), "--play", "--no-progress", "--output", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    live = summary["live"]
    assert live["received"] == 6 and live["frames"] + live["dropped"] == 6 and live["frames"] >= 1
    assert summary["config"]["cameras"][1]["input"]["play"] is True
    for rec in summary["per_frame"]:
        name = rec["frame"]
        record = json.loads((out / "frames" / f"{Path(name).stem}.json").read_text())
        assert record["cameras"] == {"front": name, "side": name}  # the same rendered frame, both cameras
        np.testing.assert_array_equal(np.load(out / "maps" / f"{Path(name).stem}.npy"), maps[int(Path(name).stem)],
                                      err_msg=name)


def test_the_api_on_a_live_rig_config_detects_as_the_recorded_rig(recorded, tmp_path):
    """Detector.from_config of a live rig's config (its cameras found, not started: their
    intrinsics and depth scale read from them, nothing else) detects a rig frame given as a list,
    one frame a camera, as the recorded rig run detected the same frame."""
    import csv

    from dpom_warp import Detector

    folder, _, live = recorded
    live = copy.deepcopy(live)
    live["output"]["dir"] = str(tmp_path / "out")
    cams = software_rig(folder)
    try:
        det = Detector.from_config(write(tmp_path / "live.yaml", live))
        frames = [np.asarray(Image.open(folder / "scene" / n / "frames" / "0002.png")) for n in ("front", "side")]
        got = [(round(d.x, 4), round(d.y, 4)) for d in det.detect(frames).detections]
    finally:
        for cam in cams:
            cam.unregister()
    want = [(float(r["x"]), float(r["y"])) for r in csv.DictReader(open(folder / "out" / "detections.csv"))
            if r["frame"] == "0002.png"]
    assert got and sorted(got) == sorted(want)


def test_the_api_finds_a_live_rigs_planes_in_rig_frames_it_is_given(recorded, tmp_path):
    """Detector.find_static_planes on a floor-only live rig's config (the scene with two
    free-standing cabinets in the grid): given the first five rig frames (a list a frame, one
    depth a camera), each camera's planes are the ones a recorded floor-only rig run found in its
    first five files, and a frame is then detected as that run detected it; a rig whose every
    camera has background frames is a one-line error."""
    import csv

    from dpom_warp import Detector
    from dpom_warp.config import ConfigError

    floor = rig_config(tmp_path, out="floor")
    floor["synthetic"].update(obstacles=2, people=4)
    for cam in floor["cameras"]:
        cam["input"]["background"] = None
    assert main(["run", write(tmp_path / "floor.yaml", floor), "--no-progress"]) == 0
    want = json.loads((tmp_path / "floor" / "summary.json").read_text())["inference"]["structure"]
    assert set(want) == {"front", "side"} and any(r["pixels"] > 0 for r in want.values())  # the cabinets
    live = copy.deepcopy(recorded[2])
    live["output"]["dir"] = str(tmp_path / "live")
    for cam in live["cameras"]:
        cam["input"]["background"] = None
    with_bg = {k: v for k, v in rig_config(tmp_path, out="bg").items() if k != "synthetic"}  # (the scene as is)
    with pytest.raises(ConfigError, match="^cameras: expected a camera with input.background null"):
        Detector.from_config(write(tmp_path / "bg.yaml", with_bg)).find_static_planes([])
    cams = software_rig(tmp_path)
    try:
        det = Detector.from_config(write(tmp_path / "live.yaml", live))

        def rig_frame(i):
            return [np.asarray(Image.open(tmp_path / "scene" / n / "frames" / f"{i:04d}.png")) for n in ("front", "side")]

        report = det.find_static_planes([rig_frame(i) for i in range(5)])
        got = [(round(d.x, 4), round(d.y, 4)) for d in det.detect(rig_frame(2)).detections]
    finally:
        for cam in cams:
            cam.unregister()
    assert {n: r["pixels"] for n, r in report.items()} == {n: r["pixels"] for n, r in want.items()}
    rows = [(float(r["x"]), float(r["y"])) for r in csv.DictReader(open(tmp_path / "floor" / "detections.csv"))
            if r["frame"] == "0002.png"]
    assert got and sorted(got) == sorted(rows)

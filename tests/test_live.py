"""A run on a live camera: a SoftwareCamera (pyrealsense2's software_device) stands in for a
RealSense camera, fed rendered frames at 30 fps on a thread; the run infers the newest frame, drops the rest
(counted), tracks online and writes the usual outputs; no camera is a one-line error."""

import json

import pytest
import yaml

from dpom_warp.cli import main


@pytest.fixture
def camera_config(tmp_path):
    from test_cli import small_config

    from dpom_warp.config import load_config
    from dpom_warp.sources.realsense import SoftwareCamera

    path = small_config(tmp_path, frames=6)
    cam = SoftwareCamera.of_config(load_config(path)).register()  # the rendered frames at 30 fps
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]
    cfg["input"]["frames"] = "realsense"
    cfg["input"].pop("depth_scale", None)
    for k in ("width", "height", "intrinsics"):
        cfg["camera"].pop(k)
    cfg["evaluation"]["ground_truth"] = None
    cfg["output"].update(images_every=5, rerun=str(tmp_path / "live.rrd"))
    path.write_text(yaml.safe_dump(cfg))
    yield path, cam, tmp_path
    cam.unregister()


def test_live_run_keeps_the_newest_frame_and_writes_the_outputs(camera_config, capsys):
    path, cam, tmp = camera_config
    cam.start()  # 30 frames a second on its own thread
    try:
        assert main(["run", str(path), "--no-progress", "--max-frames", "12"]) == 0
    finally:
        cam.stop()
    out = tmp / "out"
    summary = json.loads((out / "summary.json").read_text())
    live = summary["live"]
    assert live["frames"] == summary["frames"] == 12 and live["stopped_by"] == "max_frames"
    assert live["received"] >= 12 and live["dropped"] >= live["received"] - 13  # at most one pending
    assert live["latency_ms_median"] > 0 and live["frames_per_s"] > 0
    assert summary["config"]["camera"]["width"] == 128 and summary["config"]["input"]["depth_scale"] == 0.001
    names = sorted(p.stem for p in (out / "maps").glob("*.npy"))
    assert len(names) == 12 and all(len(n) == 6 and n.isdigit() for n in names)
    assert names != [f"{i:06d}" for i in range(12)] or live["dropped"] == 0  # frames named by stream index
    assert len(list((out / "images").glob("*.png"))) == 3  # every 5th of 12
    assert summary["tracking"]["method"] == "online"
    assert (out / "tracks.csv").read_text().startswith("frame,track,x,y,z,rho")
    assert "live: 12 frames inferred of" in capsys.readouterr().out
    from rerun.chunk import RrdReader  # the live view's recording: every inferred frame

    rows = {}
    for chunk in RrdReader(str(tmp / "live.rrd")).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/world/camera/depth"] == rows["/world/camera/depth/detections"] == 12


def test_no_camera_is_one_line(camera_config, capsys):
    path, cam, _ = camera_config
    cam.unregister()
    assert main(["run", str(path), "--no-progress", "--max-frames", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "input.frames: realsense: no RealSense camera connected" in err


def test_camera_unplugged_mid_run_is_one_line_and_loses_nothing(camera_config, capsys, monkeypatch):
    """The camera goes after a few frames, as an unplugged one does: its frames stop and its SDK
    fails to stop the sensor. Every output of the frames inferred is written (maps, records,
    detections, tracks, the summary saying why it stopped), then one line and exit code 1."""
    import threading
    import time

    from dpom_warp import live
    from dpom_warp.sources.realsense import RealSenseLive

    path, cam, tmp = camera_config
    out = tmp / "out"
    monkeypatch.setattr(live, "STALL_S", 1.0)
    real_stop = RealSenseLive.stop

    def unplugged_stop(self):
        real_stop(self)
        raise RuntimeError("failed to set power state\n(usb)")

    monkeypatch.setattr(RealSenseLive, "stop", unplugged_stop)

    def unplug():
        deadline = time.time() + 120
        while len(list((out / "frames").glob("*.json"))) < 3 and time.time() < deadline:
            time.sleep(0.01)
        cam.stop()

    cam.start()
    unplugger = threading.Thread(target=unplug)
    unplugger.start()
    try:
        code = main(["run", str(path), "--no-progress"])
    finally:
        unplugger.join()
        cam.stop()
    captured = capsys.readouterr()
    err = captured.err.strip()
    summary = json.loads((out / "summary.json").read_text())
    n = summary["live"]["frames"]
    assert code == 1 and "\n" not in err and n >= 3
    assert (f"input.frames: realsense: the camera stopped sending (no frame for 1 s after {n} frames: "
            f"unplugged?)") in err and f"the {n} frames inferred are written to {out}" in err
    assert summary["live"]["stopped_by"] == "camera stopped sending"
    assert summary["live"]["stop_error"] == "failed to set power state"
    assert "the camera did not stop cleanly (failed to set power state)" in captured.out
    names = sorted(p.stem for p in (out / "maps").glob("*.npy"))
    assert len(names) == n == len(list((out / "frames").glob("*.json"))) == summary["frames"]
    rows = (out / "tracks.csv").read_text().splitlines()
    assert rows[0].startswith("frame,track") and {r.split(",")[0] for r in rows[1:]} <= set(names)
    assert (out / "detections.csv").exists() and not [p for p in out.rglob(".*") if p.is_file()]

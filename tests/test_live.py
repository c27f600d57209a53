"""A run on a live camera: a SoftwareCamera (pyrealsense2's software_device) stands in for a
RealSense camera, fed rendered frames at 30 fps on a thread; the run infers the newest frame, drops the rest
(counted), tracks online and writes the usual outputs; no camera is a one-line error."""

import dataclasses
import json
import os

import pytest
import yaml

from dpom_warp.cli import main


def on_the_live_camera(cfg: dict) -> dict:
    """small_config's mapping run on the live camera (`realsense`): its size, intrinsics and
    depth units left to the camera, nothing rendered, no ground truth."""
    del cfg["synthetic"]
    cfg["input"]["frames"] = "realsense"
    cfg["input"].pop("depth_scale", None)
    for k in ("width", "height", "intrinsics"):
        cfg["camera"].pop(k)
    cfg["evaluation"]["ground_truth"] = None
    return cfg


@pytest.fixture
def camera_config(tmp_path):
    from test_cli import small_config

    from dpom_warp.loading import load_config
    from dpom_warp.frames import render_synthetic
    from dpom_warp.sources import expand
    from dpom_warp.sources.software import SoftwareCamera

    path = small_config(tmp_path, frames=6)
    cfg = load_config(path)
    render_synthetic(cfg, lambda *_: None)
    cam = SoftwareCamera.of_files(expand(cfg.inputs.frames, "input.frames"), cfg.camera).register()  # at 30 fps
    (tmp_path / "plain.yaml").write_text(path.read_text())  # the same frames as files (plain_maps)
    cfg = on_the_live_camera(yaml.safe_load(path.read_text()))
    cfg["output"].update(images_every=5, rerun=str(tmp_path / "live.rrd"))
    path.write_text(yaml.safe_dump(cfg))
    yield path, cam, tmp_path
    cam.unregister()


def test_live_run_keeps_the_newest_frame_and_writes_the_outputs(camera_config, capsys):
    path, cam, tmp = camera_config
    cam.start()  # 30 frames a second on its own thread
    try:  # one process: at most one frame pending
        assert main(["run", str(path), "--no-progress", "--max-frames", "12", "--workers", "1"]) == 0
    finally:
        cam.stop()
    out = tmp / "out"
    summary = json.loads((out / "summary.json").read_text())
    live = summary["live"]
    assert live["frames"] == summary["frames"] == 12 and live["stopped_by"] == "max_frames"
    printed = capsys.readouterr().out
    assert live["processes"] == 1 and "device cpu, 1 process;" in printed
    assert live["received"] >= 12 and live["dropped"] >= live["received"] - 13  # at most one pending
    assert live["latency_ms_median"] > 0 and live["frames_per_s"] > 0
    # once running, the output cannot outpace a 30 frames/s stream for long (11 intervals)
    assert 0 < live["frames_per_s_steady"] <= 1.5 * live["camera_fps"] == 45
    assert summary["config"]["camera"]["width"] == 128 and summary["config"]["input"]["depth_scale"] == 0.001
    names = sorted(p.stem for p in (out / "maps").glob("*.npy"))
    assert len(names) == 12 and all(len(n) == 6 and n.isdigit() for n in names)
    # frames are named by stream index: the indices skipped between the first map and the last
    # were dropped (frames arriving after the last one taken, during the shutdown, are dropped too)
    skipped = int(names[-1]) - int(names[0]) + 1 - 12
    assert 0 <= skipped <= live["dropped"] and live["received"] >= 12 + skipped
    assert len(list((out / "images").glob("*.png"))) == 3  # every 5th of 12
    assert summary["tracking"]["method"] == "online"
    # the camera frames dropped between the first map and the last, by the frames' timestamps
    assert summary["tracking"]["frames_without_map"] == int(names[-1]) - int(names[0]) + 1 - 12
    assert (out / "tracks.csv").read_text().startswith("frame,track,x,y,z,rho")
    assert "live: 12 frames inferred of" in printed
    from rerun.chunk import RrdReader  # the live view's recording: every inferred frame

    rows = {}
    for chunk in RrdReader(str(tmp / "live.rrd")).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    # each frame's boxes are logged with it, then again with their identities once the online
    # tracker commits it (tracking.delay frames later, or at the end), with its tracks
    assert rows["/world/camera/depth"] == rows["/world/tracks"] == 12 and rows["/world/camera/depth/detections"] == 24
    # the pictures are drawn once their frame is committed, with the tracks of tracks.csv
    import numpy as np

    from dpom_warp.config import parse_config
    from dpom_warp.detect import detect_map
    from dpom_warp.geometry import build_geometry
    from dpom_warp.io import units_to_metres
    from dpom_warp.outputs import ShownTracks
    from dpom_warp.writers import tracked_picture
    from dpom_warp.track_files import per_frame, tracks_csv
    from dpom_warp.tracking import Cells, run_tracker

    cfg = parse_config(summary["config"])
    geometry = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    stamps = [p["timestamp"] for p in summary["per_frame"]]
    assert [p["frame"] for p in summary["per_frame"]] == names
    maps = np.stack([np.load(out / "maps" / f"{n}.npy").ravel() for n in names])
    # the live tracker's tracks again from its maps and their times, at the heads its frames'
    # records found: tracks.csv, exactly
    from dpom_warp.heads import MATCH, found_in, place_tracks

    tracks, _ = run_tracker(maps, Cells.for_run(geometry, cfg), cfg.grid.shape, cfg.tracking,
                            summary["tracking"]["fps"], cfg.detection.threshold, "online", stamps)
    place_tracks(tracks, [found_in(json.loads((out / "frames" / f"{n}.json").read_text())) for n in names],
                 MATCH * cfg.detection.nms_radius)
    assert tracks and tracks_csv(tracks, names) == (out / "tracks.csv").read_text()
    trails, drawn = ShownTracks(geometry, cfg.tracking.trail), 0
    for i, (n, rows) in enumerate(zip(names, per_frame(tracks, len(names)))):
        shown = trails.at(i, rows)
        if i % 5 == 0:
            rho_map = maps[i].reshape(cfg.grid.shape)
            sent = round(stamps[i] * 30)  # the camera's frame number
            depth = units_to_metres(cam.frames[sent % len(cam.frames)], 0.001)
            # as a finished run draws a frame with its tracks (frames_out)
            png = tracked_picture(cfg, geometry, depth, rho_map, detect_map(rho_map, geometry, cfg.detection), n,
                                  None, shown)
            drawn += png == (out / "images" / f"{n}.png").read_bytes()
    assert drawn == 3
    # `dpom-warp track` on a live run: no frames were kept to draw pictures from (one line);
    # without pictures it gives the live run's tracks again from its maps and timestamps
    live_tracks = (out / "tracks.csv").read_text()
    capsys.readouterr()
    assert main(["track", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "a live run keeps no frames (input.frames: realsense)" in err and "\n" not in err
    assert main(["track", str(out), "--set", "output.images=false", "--set", "output.rerun=null",
                 "--set", "tracking.method=online"]) == 0
    assert (out / "tracks.csv").read_text() == live_tracks


def plain_maps(tmp, rendered: int = 6):
    """The maps the plain run gives the live test's `rendered` frames."""
    import numpy as np

    plain_path = tmp / "plain.yaml"  # camera_config's: small_config before the live changes
    plain = yaml.safe_load(plain_path.read_text())
    plain["output"]["dir"] = str(tmp / "plain")
    plain_path.write_text(yaml.safe_dump(plain))
    assert main(["run", str(plain_path), "--no-progress"]) == 0
    return [np.load(tmp / "plain" / "maps" / f"{i:04d}.npy") for i in range(rendered)]


def assert_plain_maps_in_stream_order(out, want, frames):
    """Every map of the live run is the plain run's of the same rendered frame (bit for bit; the
    camera plays `want`'s frames over and over), written in stream order; returns the per-frame
    records."""
    import numpy as np

    summary = json.loads((out / "summary.json").read_text())
    assert summary["live"]["frames"] == frames
    names = [p["frame"] for p in summary["per_frame"]]  # in the order written and tracked
    assert len(names) == frames and names == sorted(names)
    first = [j for j in range(len(want)) if np.array_equal(np.load(out / "maps" / f"{names[0]}.npy"), want[j])]
    assert len(first) == 1  # the stream's first frame is one of the rendered ones, then in order
    for name in names:
        np.testing.assert_array_equal(np.load(out / "maps" / f"{name}.npy"),
                                      want[(first[0] + int(name) - int(names[0])) % len(want)], err_msg=name)
    return summary


def test_live_run_on_two_processes_gives_the_plain_runs_maps_in_stream_order(camera_config):
    """--workers 2: a helper process infers beside the main one; every frame's map is the one
    the plain run gives the same rendered frame, records come in stream order, and both
    processes inferred some."""
    path, cam, tmp = camera_config
    want = plain_maps(tmp)
    # frames sent faster than one process infers them (~10 ms a frame here), so that some
    # arrive while the helper is busy and the main process takes them: at 30 fps the helper
    # alone keeps up with this small scene
    cam.fps = 250.0
    cam.start()
    try:
        assert main(["run", str(path), "--no-progress", "--max-frames", "12", "--workers", "2"]) == 0
    finally:
        cam.stop()
    summary = assert_plain_maps_in_stream_order(tmp / "out", want, 12)
    assert summary["live"]["processes"] == 2
    from test_long_runs import own_start_files

    assert not own_start_files()  # the helpers' start file removed with them
    workers = {p["worker"] for p in summary["per_frame"]}
    assert "main" in workers and any(w.startswith("process ") for w in workers), workers


def helper_pids() -> list[int]:
    """This process's spawned multiprocessing children (a live run's helpers)."""
    import os
    from pathlib import Path

    pids = []
    for proc in Path("/proc").iterdir():
        try:
            stat = (proc / "stat").read_text().rsplit(")", 1)[1].split()
            cmd = (proc / "cmdline").read_bytes()
        except (OSError, IndexError):
            continue
        if int(stat[1]) == os.getpid() and b"multiprocessing" in cmd and b"spawn_main" in cmd:
            pids.append(int(proc.name))
    return pids


def test_a_helper_process_that_dies_loses_no_frame(camera_config, capsys):
    """The helper is killed mid-run: its frame is inferred by the main process, the run goes
    on in one process to --max-frames, every map still the plain run's; one line says so."""
    import os
    import signal
    import threading
    import time

    path, cam, tmp = camera_config
    want = plain_maps(tmp)
    out, killed = tmp / "out", []

    def kill_the_helper():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            records = list((out / "frames").glob("*.json")) if (out / "frames").exists() else []
            if len(records) >= 4:
                for pid in helper_pids():
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
            time.sleep(0.01)

    killer = threading.Thread(target=kill_the_helper, daemon=True)
    cam.start()
    killer.start()
    try:
        assert main(["run", str(path), "--no-progress", "--max-frames", "20", "--workers", "2"]) == 0
    finally:
        cam.stop()
        killer.join(5)
    assert killed, "the helper process was not found"
    assert "live: a helper process died" in capsys.readouterr().out
    summary = assert_plain_maps_in_stream_order(out, want, 20)
    assert summary["per_frame"][-1]["worker"] == "main"


def test_a_helper_process_that_dies_starting_leaves_the_run_in_one_process(camera_config, capsys, monkeypatch):
    """The helper dies as it is spawned (a program that exits at once in place of Python):
    one line says so and the run goes on in one process, every map the plain run's."""
    import multiprocessing.resource_tracker
    import multiprocessing.spawn
    import os
    import shutil

    path, cam, tmp = camera_config
    want = plain_maps(tmp)
    multiprocessing.resource_tracker.ensure_running()  # the tracker is spawned with Python
    monkeypatch.setattr(multiprocessing.spawn, "_python_exe", os.fsencode(shutil.which("true")))
    cam.start()
    try:
        assert main(["run", str(path), "--no-progress", "--max-frames", "6", "--workers", "2"]) == 0
    finally:
        cam.stop()
    assert "live: a helper process died starting" in capsys.readouterr().out
    summary = assert_plain_maps_in_stream_order(tmp / "out", want, 6)
    assert {p["worker"] for p in summary["per_frame"]} == {"main"}


@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_writes_and_tracks_every_frame_taken(camera_config, workers):
    """Ctrl-C (SIGINT to the run's process) mid-run: the frames taken so far, the one being
    inferred and those the helper or the finisher thread held included, are all written and
    tracked, in stream order, each the plain run's map; the summary says why it stopped."""
    import os
    import signal
    import threading
    import time

    path, cam, tmp = camera_config
    want = plain_maps(tmp)
    out, sent = tmp / "out", []

    def interrupt():
        # the run may first compile its kernels (a fresh cache: a minute or more on CI); if the
        # frames never come, the camera stops, so that the run ends and the test fails, not hangs
        deadline = time.time() + 400
        while time.time() < deadline:
            if (out / "frames").exists() and len(list((out / "frames").glob("[!.]*.json"))) >= 5:
                os.kill(os.getpid(), signal.SIGINT)
                sent.append(True)
                return
            time.sleep(0.01)
        cam.stop()

    cam.fps = 100.0  # frames arriving while the finisher and the helper are busy
    cam.start()
    ctrl_c = threading.Thread(target=interrupt, daemon=True)
    ctrl_c.start()
    try:
        # (--max-frames: a run that missed the Ctrl-C ends, and fails below, rather than hangs)
        assert main(["run", str(path), "--no-progress", "--workers", str(workers), "--max-frames", "2000"]) == 0
    finally:
        cam.stop()
        ctrl_c.join(5)
    assert sent
    summary = json.loads((out / "summary.json").read_text())
    assert summary["live"]["stopped_by"] == "Ctrl-C"
    frames = summary["live"]["frames"]
    assert frames >= 5 and len(list((out / "maps").glob("*.npy"))) == frames
    assert_plain_maps_in_stream_order(out, want, frames)
    t = summary["tracking"]  # every frame pushed to the online tracker: a solve each past the delay
    assert t["method"] == "online" and t["solves"] == max(0, frames - t["delay_frames"]) + 1
    # every 5th frame's picture, those the tracker had not committed at Ctrl-C drawn at the end
    assert len(list((out / "images").glob("*.png"))) == (frames + 4) // 5


def test_an_error_writing_a_frame_ends_the_live_run_with_one_line(camera_config, capsys, monkeypatch):
    """The finisher thread writes the frames; an error there (a full disk) ends the run with
    a non-zero exit and a line naming it, the frames before it written, nothing after."""
    from dpom_warp.writers import Maps

    path, cam, tmp = camera_config
    real, calls = Maps.frame, []

    def failing(self, done):
        calls.append(done.stem)
        if len(calls) == 4:
            raise OSError(28, "No space left on device")
        return real(self, done)

    monkeypatch.setattr(Maps, "frame", failing)
    cam.start()
    try:
        assert main(["run", str(path), "--no-progress", "--max-frames", "12"]) != 0
    finally:
        cam.stop()
    err = capsys.readouterr().err
    assert "No space left on device" in err and len(err.strip().splitlines()) == 1
    assert len(list((tmp / "out" / "frames").glob("*.json"))) == 3


def test_a_frame_handed_to_a_pool_already_broken_is_a_future_of_that_error(camera_config):
    """The main process may learn of a helper's death when it hands over the next frame (the
    pool is marked broken before its futures fail): that frame must come back as a failed
    future, as every other frame of a dead helper does, not as an error out of the run."""
    import os
    import signal
    from concurrent.futures.process import BrokenProcessPool

    import numpy as np

    from dpom_warp.loading import load_config
    from dpom_warp.worker import Helpers
    from dpom_warp.session import set_up

    _, _, tmp = camera_config
    setup = set_up(load_config(tmp / "plain.yaml"), [], "cpu", log=lambda *a: None)
    helpers = Helpers(setup.spec, setup.engine, 1)
    frame = np.zeros((setup.engine.views[0].height, setup.engine.views[0].width), np.float32)
    try:
        pids = helper_pids()
        assert len(pids) == 1
        os.kill(pids[0], signal.SIGKILL)
        with pytest.raises(BrokenProcessPool):
            helpers.submit(frame).result(timeout=60)  # the death seen: the pool is broken now
        late = helpers.submit(frame)  # raised out of submit before the fix (CI, stop 28)
        with pytest.raises(BrokenProcessPool):
            late.result(timeout=0)
    finally:
        helpers.close()


def test_live_workers_with_warm_start_is_one_line(camera_config, capsys):
    path, _, _ = camera_config
    assert main(["run", str(path), "--no-progress", "--workers", "2", "--set", "model.warm_start=true"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "model.warm_start: each frame starts from the previous one" in err
    assert "expected no --workers with it" in err


def test_a_floor_only_live_run_finds_the_walls_in_its_first_frames(tmp_path):
    """Floor-only, a live camera's first input.structure.frames (5) frames give the static planes
    a recorded run finds in its first files (test_structure's wall across the grid, a person
    against it, one behind a desk): the wall is found and made background, every detection is
    one of the two people, and both are found in every frame; with the planes off the wall is
    taken for people. The frames taken for the planes are not inferred (live.structure_frames)."""
    import csv

    import numpy as np

    from dpom_warp.sources.software import SoftwareCamera
    from test_structure import CAM, PEOPLE, rendered

    mm = [np.clip(np.round(rendered(seed=s) * 1000), 0, 65535).astype(np.uint16) for s in range(3)]
    i = CAM["intrinsics"]
    cam = SoftwareCamera(mm, i["fx"], i["fy"], i["cx"], i["cy"]).register()
    found = {}
    try:
        for planes in (True, False):
            out = tmp_path / f"planes_{planes}"
            cfg = {"device": "cpu", "input": {"frames": "realsense", "background": None,
                                              "structure": {"planes": planes}},
                   "camera": {"extrinsics": {"height": 2.2, "pitch_deg": 20.0}},
                   "grid": {"x": [-2.5, 2.5, 0.1], "y": [1.5, 5.0, 0.1]},
                   "output": {"dir": str(out), "images": False}, "tracking": {"method": "off"}}
            (tmp_path / "live.yaml").write_text(yaml.safe_dump(cfg))
            cam.start()
            try:
                assert main(["run", str(tmp_path / "live.yaml"), "--no-progress", "--max-frames", "4",
                             "--workers", "2" if planes else "1"]) == 0  # the helper's engine has the planes
            finally:
                cam.stop()
            summary = json.loads((out / "summary.json").read_text())
            rows = list(csv.reader(open(out / "detections.csv")))[1:]
            found[planes] = (summary, np.array([[float(r[1]), float(r[2])] for r in rows]).reshape(-1, 2))
    finally:
        cam.unregister()
    summary, dets = found[True]
    assert summary["live"]["structure_frames"] == 5 and summary["frames"] == 4
    assert summary["live"]["processes"] == 2  # a frame a helper inferred without the planes would hold the wall
    walls = [p for p in summary["inference"]["structure"]["planes"] if abs(p["normal"][1]) > 0.99]
    assert walls and summary["inference"]["structure"]["pixels"] > 0
    near = [np.hypot(*(dets - p).T) < 0.5 for p in PEOPLE]
    assert np.all(near[0] | near[1]) and len(dets) == 4 * len(PEOPLE), dets
    plain_summary, plain = found[False]
    assert plain_summary["live"]["structure_frames"] == 0 and "structure" not in plain_summary["inference"]
    assert any(min(np.hypot(*(d - p)) for p in PEOPLE) > 0.5 for d in plain), plain  # the wall


def test_the_api_on_a_live_cameras_config_reads_no_frames_before(camera_config):
    """Detector.from_config of a live camera's config, floor-only with its pose given: nothing is
    read before (the frames are the ones given to detect; a folder's config reads its first
    frames for the static planes), and a frame given is detected as the same frame's file is by
    the folder's config."""
    import numpy as np
    from PIL import Image

    from dpom_warp import Detector

    path, _, tmp = camera_config
    plain = yaml.safe_load((tmp / "plain.yaml").read_text())
    live = Detector.from_config(path, {"input.background": None, "input.structure.planes": False})
    files = Detector.from_config({**{k: v for k, v in plain.items() if k != "synthetic"}},
                                 {"input.background": None, "input.structure.planes": False})
    frame = np.asarray(Image.open(sorted((tmp / "scene" / "frames").glob("*.png"))[0]))
    got = [(d.x, d.y) for d in live.detect(frame).detections]
    assert got and got == [(d.x, d.y) for d in files.detect(frame).detections]
    assert "structure" not in Detector.from_config(path, {"input.background": None}).setup.inference
    # its pose left out: a live run fits the floor on the camera's first frames; the API has none
    from dpom_warp.config import ConfigError

    with pytest.raises(ConfigError, match=r"^camera.extrinsics: auto needs frames to fit the floor on, and a live "
                                          r"camera \(realsense\) has none before detect; expected the camera's pose"
                                          r".* or its first frames as Detector.from_config's first_frames$"):
        Detector.from_config(path, {"input.background": None, "camera.extrinsics": "auto"})
    from dpom_warp.io import InputError

    with pytest.raises(ConfigError, match=r"^first_frames: expected a live camera's config .*, found input.frames: "):
        Detector.from_config({k: v for k, v in plain.items() if k != "synthetic"}, first_frames=[frame])
    with pytest.raises(InputError, match=r"^first_frames: expected at least one frame, found none$"):
        Detector.from_config(path, {"input.background": None}, first_frames=[])
    with pytest.raises(InputError, match=r"^depth \(first_frames, frame 1\): expected an array of shape \(106, 128\)"):
        Detector.from_config(path, {"input.background": None}, first_frames=[frame, frame[:-1]])


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
    from dpom_warp.live import usable_cpus
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
    assert summary["live"]["processes"] == (3 if usable_cpus() >= 2 else 1)  # no --workers: 3 on 2 CPUs
    assert summary["live"]["stop_error"] == "failed to set power state"
    assert "the camera did not stop cleanly (failed to set power state)" in captured.out
    names = sorted(p.stem for p in (out / "maps").glob("*.npy"))
    assert len(names) == n == len(list((out / "frames").glob("*.json"))) == summary["frames"]
    rows = (out / "tracks.csv").read_text().splitlines()
    assert rows[0].startswith("frame,track") and {r.split(",")[0] for r in rows[1:]} <= set(names)
    assert (out / "detections.csv").exists() and not [p for p in out.rglob(".*") if p.is_file()]


def test_a_live_run_without_workers_uses_both_cores_on_the_cpu(tmp_path, monkeypatch):
    """No --workers: three processes on the CPU where it has two CPUs or more (one infers half
    to three quarters of a 30 fps stream; the third smooths the machine's slow frames), one
    where it has one, on a GPU and with warm starts (frames in order, one process). The
    unplugged-camera test runs the default end to end."""
    from dpom_warp import live
    from dpom_warp.loading import load_config
    from test_cli import small_config

    cfg = load_config(small_config(tmp_path, frames=2))
    warm = dataclasses.replace(cfg, model=cfg.model.replace(warm_start=True))
    assert 1 <= live.usable_cpus() <= (os.cpu_count() or 1)
    for cpus, device, c, want in ((2, "cpu", cfg, 3), (16, "cpu", cfg, 3), (1, "cpu", cfg, 1),
                                  (16, "cuda:0", cfg, 1), (16, "cpu", warm, 1)):
        monkeypatch.setattr(live, "usable_cpus", lambda: cpus)
        assert live.default_workers(c, device) == want, (cpus, device, c.model.warm_start)

"""Bad input, faults and long runs: each case gives one line naming the key or file, exit
code 2, and no output; bad frames in a sequence are skipped and reported; interrupted runs
resume to the same files; identical runs give identical bytes."""

import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp.config import ConfigError
from dpom_warp.cli import main
from dpom_warp.io import TEMP_MARK, write_depth_png
from dpom_warp.worker import CACHE_PREFIX

from test_cli import small_config
import paths

REAL = paths.REAL / "five_people"


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A rendered small sequence (6 frames) and its config, shared by the tests here."""
    tmp = tmp_path_factory.mktemp("scene")
    path = small_config(tmp, frames=6)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "first")]) == 0
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]  # the frames now exist; tests copy and damage them
    return tmp, cfg


def write_config(tmp_path, cfg, **sets):
    cfg = json.loads(json.dumps(cfg))
    for key, value in sets.items():
        node = cfg
        *parents, last = key.split("__")
        for p in parents:
            node = node.setdefault(p, {})
        if value is DELETE:
            node.pop(last, None)
        else:
            node[last] = value
    cfg["output"]["dir"] = str(tmp_path / "out")
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


DELETE = object()


def frames_with(tmp_path, scene_dir, bad_name, make):
    """A copy of the frames folder with frame `bad_name` replaced by what `make` writes."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for f in sorted((scene_dir / "scene" / "frames").glob("*.png")):
        (folder / f.name).write_bytes(f.read_bytes())
    target = folder / bad_name
    target.unlink(missing_ok=True)
    make(target)
    return folder


def png8(p):
    Image.fromarray(np.zeros((106, 128), np.uint8)).save(p)


def png_rgb(p):
    Image.fromarray(np.zeros((106, 128, 3), np.uint8)).save(p)


def truncated(p):
    src = sorted(p.parent.glob("*.png"))[0].read_bytes()
    p.write_bytes(src[: len(src) // 3])


def npy(values):
    def make(p):
        np.save(p.with_suffix(".npy"), values)
    return make


CONFIG_CASES = [
    ({"grid__x": [1.0, -1.0, 0.2]}, "grid.x: expected min < max in [min, max, step], found 1.0 >= -1.0"),
    ({"grid__y": [1.0, 6.0, -0.2]}, "grid.y: expected a step > 0 in [min, max, step], found -0.2"),
    ({"grid__y": [1.0, 6.0, 0]}, "grid.y: expected a step > 0 in [min, max, step], found 0"),
    ({"object__width": 8.0}, "object.width: expected at most the grid's x extent 5 m, found 8"),
    ({"detection__threshold": 1.2}, "detection.threshold: expected a value < 1, found 1.2"),
    ({"detection__threshold": 0}, "detection.threshold: expected a value > 0, found 0"),
    ({"model__damping": "fast"}, "model.damping: expected a number, found 'fast'"),
    ({"model__iterations": 10}, "model.iterations: unknown key"),
    ({"camera__lens": "wide"}, "camera.lens: unknown key"),
    # several unknown keys: every one named in the one line, with its closest known key
    ({"model__prio": 0.1, "model__dampng": 0.2},
     "model: unknown keys dampng (did you mean damping?), prio (did you mean prior?); expected keys among prior, "),
    ({"model__prio": 0.1, "grid__stepp": 1}, "grid.stepp: unknown key (expected one of mode, x, y, z); "
                                             "model.prio: unknown key (did you mean prior? expected one of prior,"),
    ({"model__sensor_noise": [0.01]}, "model.sensor_noise: expected a list of 2 numbers"),
    ({"model__sensor_noise": [-0.01, 0.001]}, "model.sensor_noise: expected [a, b] >= 0"),
    ({"model__damping": 0.5, "model__damping_max": 0.3}, "model.damping_max: expected at least model.damping"),
    ({"model__top_heights": [1.9]}, "model.top_heights: expected heights below object.height (1.85 m), found [1.9]"),
    ({"model__top_heights": [1.85]}, "model.top_heights: expected heights below object.height (1.85 m), found [1.85]"),
    ({"grid__mode": "voxel", "grid__z": [0.0, 2.4, 0.1], "model__top_heights": [1.6]},
     "model.top_heights: expected [] in voxel mode (no top-band test there), found [1.6]"),
    ({"model__top_heights": 1.6}, "model.top_heights: expected a list of heights > 0 (metres), found 1.6"),
    ({"camera__intrinsics__fx": DELETE}, "camera.intrinsics.fx: required key is missing"),
    ({"camera__intrinsics__cx": 400}, "camera.intrinsics.cx: expected a value <= 128, found 400"),
    ({"camera__width": 160}, "expected 160x106 pixels (camera.width x camera.height), found 128x106"),
    ({"camera__extrinsics": "guess"}, "camera.extrinsics: expected auto, {T_world_from_camera: 4x4}"),
    ({"camera__extrinsics": {"T_world_from_camera": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}},
     "camera.extrinsics.T_world_from_camera: expected a rigid transform"),
    ({"camera__ground__up": [0, 0, 0]}, "camera.ground.up: expected a non-zero direction"),
    ({"camera__ground__up": "down"}, "camera.ground.up: expected auto or a list of 3 numbers, found 'down'"),
    ({"device": "gpu"}, "device: expected auto, cpu, cuda or cuda:N, found 'gpu'"),
    ({"engine__memory_gb": 0.001}, "engine.memory_gb: the engine needs at least"),
    ({"input__frames": "/nonexistent/*.png"}, "input.frames: no files match '/nonexistent/*.png'"),
    ({"evaluation__ground_truth": "/nonexistent/gt.json"}, "/nonexistent/gt.json: no such ground-truth file"),
    ({"grid__x": [40.0, 42.0, 0.1]}, "grid: none of its 560 locations is in the camera's view (the camera at "
                                     "x 0.00 m, y 0.00 m, 2.20 m up); expected grid.x"),
]


@pytest.mark.parametrize("sets, message", CONFIG_CASES, ids=[m[:40] for _, m in CONFIG_CASES])
def test_bad_config(tmp_path, capsys, scene, sets, message):
    path = write_config(tmp_path, scene[1], **sets)
    assert main(["run", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert err.startswith("dpom-warp: error: ") and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_an_output_folder_that_cannot_be_one(tmp_path, capsys, scene):
    """--output naming a file, or a path under one: one line, exit 2, the file untouched (it
    said 'Not a directory; finished frames are kept, continue with --resume' of a run that
    had not started)."""
    path = write_config(tmp_path, scene[1])
    taken = tmp_path / "taken"
    taken.write_text("mine")
    for out, message in ((taken, f"output.dir: {taken} is a file; expected an empty or new folder"),
                         (taken / "sub", f"output.dir: {taken / 'sub'}: cannot make the folder (Not a directory)")):
        assert main(["run", str(path), "--no-progress", "--output", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"dpom-warp: error: {message}") and len(err.splitlines()) == 1, err
    assert taken.read_text() == "mine"


def test_yaml_syntax_and_top_level(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("device: cpu\ngrid: [unclosed\n")
    assert main(["run", str(bad)]) == 2
    assert "bad.yaml: not valid YAML at line" in capsys.readouterr().err
    bad.write_text("- just\n- a list\n")
    assert main(["run", str(bad)]) == 2
    assert "expected a YAML mapping at the top, found list" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "missing.yaml")]) == 2
    assert "missing.yaml: no such config file" in capsys.readouterr().err


FRAME_CASES = [
    ("0002.png", lambda p: p.write_bytes(b""), "0002.png: not a readable image"),
    ("0002.png", truncated, "0002.png: not a readable image"),
    ("0002.png", png8, "0002.png: expected a single-channel 16-bit depth PNG, found mode L"),
    ("0002.png", png_rgb, "0002.png: expected a single-channel 16-bit depth PNG, found mode RGB"),
    ("0002.png", lambda p: write_depth_png(p, np.ones((50, 60))), "0002.png: expected 128x106 pixels"),
    ("0002.png", lambda p: write_depth_png(p, np.zeros((106, 128))), "0002.png: no depth readings"),
    ("0002.npy", npy(np.full((106, 128), np.nan)), "0002.npy: depth has NaN or infinite values: expected finite depth units (0 = no "
     "reading), found 13568 of 13568 pixels not finite"),
    ("0002.npy", npy(np.full((106, 128), np.inf)), "0002.npy: depth has NaN or infinite values"),
    ("0002.npy", npy(-np.ones((106, 128))), "0002.npy: depth has negative values: expected depth units >= 0 "
     "(0 = no reading), found a minimum of -1"),
]


@pytest.mark.parametrize("name, make, message", FRAME_CASES, ids=[m for *_, m in FRAME_CASES])
def test_bad_frame_is_skipped_or_fatal_with_strict(tmp_path, capsys, scene, name, make, message):
    folder = frames_with(tmp_path, scene[0], "0002.png", lambda p: None)
    make(folder / name)
    path = write_config(tmp_path, scene[1], input__frames=f"{folder}/*", evaluation__ground_truth=None)
    assert main(["run", str(path), "--no-progress", "--strict"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()

    assert main(["run", str(path), "--no-progress"]) == 0
    assert "1 frame(s) skipped" in capsys.readouterr().out
    summary = json.load(open(tmp_path / "out" / "summary.json"))
    assert summary["frames"] == 5 and len(summary["skipped"]) == 1
    assert summary["skipped"][0]["frame"] == name and message in summary["skipped"][0]["reason"]
    assert not (tmp_path / "out" / "maps" / "0002.npy").exists()


def test_every_frame_bad_is_an_error(tmp_path, capsys, scene):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        png8(folder / f"{i}.png")
    path = write_config(tmp_path, scene[1], input__frames=f"{folder}/*.png", evaluation__ground_truth=None)
    assert main(["run", str(path), "--no-progress"]) == 2
    assert "(none of the 3 frames is usable)" in capsys.readouterr().err


def test_no_floor_with_auto_pose_names_the_frame(tmp_path, capsys, scene):
    folder = tmp_path / "frames"
    folder.mkdir()
    # a flat wall ahead of a level camera (with up: auto it would be a floor seen from straight above)
    write_depth_png(folder / "wall.png", np.full((106, 128), 2.0))
    path = write_config(tmp_path, scene[1], input__frames=f"{folder}/*.png", input__background=None,
                        camera__extrinsics="auto", camera__ground__up=[0, -1, 0],
                        evaluation__ground_truth=None)
    assert main(["run", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "wall.png: no floor plane found" in err
    assert not (tmp_path / "out").exists()


def test_non_empty_output_needs_overwrite_or_resume(tmp_path, capsys, scene):
    path = write_config(tmp_path, scene[1])
    assert main(["run", str(path), "--no-progress"]) == 0
    assert main(["run", str(path), "--no-progress"]) == 2
    assert "is not empty; expected an empty or new folder (use --overwrite" in capsys.readouterr().err
    (tmp_path / "out" / "maps" / "0000.npy").write_bytes(b"garbage")
    assert main(["run", str(path), "--no-progress", "--overwrite"]) == 0
    assert np.load(tmp_path / "out" / "maps" / "0000.npy").shape == (28, 25)
    assert main(["run", str(path), "--no-progress", "--overwrite", "--resume"]) == 2
    other = write_config(tmp_path, scene[1], detection__threshold=0.7)
    assert main(["run", str(other), "--no-progress", "--resume"]) == 2
    assert "holds a run of another config (detection.threshold: 0.5 then, 0.7 now)" in capsys.readouterr().err


@pytest.mark.parametrize("pose", ["given", "auto"])
def test_identical_runs_give_identical_bytes(tmp_path, scene, pose):
    """Two runs of one config through the CLI write the same bytes in every file (the summary
    but its timings), the pose given or fitted on the background frames (extrinsics: auto)."""
    sets = {"camera__extrinsics": "auto"} if pose == "auto" else {}
    path = write_config(tmp_path, scene[1], **sets)
    a, b = tmp_path / "first", tmp_path / "out"  # the same folder, run twice (its name is in files)
    assert main(["run", str(path), "--no-progress"]) == 0
    b.rename(a)
    assert main(["run", str(path), "--no-progress"]) == 0
    files = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
    assert files == sorted(str(p.relative_to(b)) for p in b.rglob("*") if p.is_file())
    assert len([f for f in files if f.startswith("maps/")]) == 6 and "tracks.csv" in files
    for name in files:
        if name != "summary.json" and not name.startswith("frames/"):
            assert (a / name).read_bytes() == (b / name).read_bytes(), name

    def untimed(record):
        if isinstance(record, dict):
            return {k: untimed(v) for k, v in record.items() if not k.endswith("_s") and k not in (
                "timings", "runner", "stats", "started", "created", "frames_per_s", "ms_per_frame", "time_ms")}
        return [untimed(v) for v in record] if isinstance(record, list) else record

    for name in ["summary.json"] + [f for f in files if f.startswith("frames/")]:
        assert untimed(json.loads((a / name).read_text())) == untimed(json.loads((b / name).read_text())), name
    if pose == "auto":
        fit = json.loads((a / "summary.json").read_text())["ground_fit"]
        assert fit["camera_height"] == pytest.approx(2.2, abs=0.02)  # the rendered camera's


def test_interrupted_run_resumes_to_the_same_files(tmp_path, scene, monkeypatch, capsys):
    from dpom_warp.worker import FrameWorker

    path = write_config(tmp_path, scene[1])
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "whole")]) == 0
    real = FrameWorker.process
    calls = []

    out = tmp_path / "out"

    def interrupted(self, items, *read):  # Ctrl-C while the fourth frame is inferred
        if len(calls) == 3:
            # and as if it had landed inside a write's mkstemp (the write's cleanup never ran)
            (out / "frames" / f".0002.json{TEMP_MARK}x1y2z3.json").write_text("")
            raise KeyboardInterrupt
        calls.append(1)
        return real(self, items, *read)

    monkeypatch.setattr(FrameWorker, "process", interrupted)
    assert main(["run", str(path), "--no-progress"]) == 130
    assert "continue with --resume" in capsys.readouterr().err
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary file left
    assert len(list((out / "frames").glob("*.json"))) == 3 and not (out / "detections.csv").exists()
    monkeypatch.setattr(FrameWorker, "process", real)
    assert main(["run", str(path), "--no-progress", "--resume"]) == 0
    assert "resuming: 3 frames already done, 3 to go" in capsys.readouterr().out
    whole = tmp_path / "whole"
    for name in ("detections.csv", "tracks.csv", "track_table.csv"):  # tracks from the saved maps
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    for folder in ("maps", "images"):
        for m in (whole / folder).iterdir():
            assert (out / folder / m.name).read_bytes() == m.read_bytes()
    a, b = (json.load(open(d / "summary.json")) for d in (out, whole))
    assert a["scores"] == b["scores"] and a["frames"] == b["frames"] == 6


def test_killed_run_leaves_whole_files_and_resumes(tmp_path, scene):
    """SIGTERM while frames are inferred (each frame slowed by a second, so the signal always
    comes before the end): exit 130, whole files; --resume gives a whole run's files byte for
    byte."""
    from slow import slow_env

    path = write_config(tmp_path, scene[1])
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "whole")]) == 0
    cmd = [sys.executable, "-m", "dpom_warp.cli", "run", str(path), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=slow_env(tmp_path, 1.0))
    deadline = time.time() + 120
    # a finished record (glob("*.json") also matches a record being written: .NAME.json.tmp-*.json)
    while not list((out / "frames").glob("[!.]*.json")) and time.time() < deadline and proc.poll() is None:
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err  # the run cannot have ended: 5 frames of 1 s were left
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary files left
    done = len(list((out / "frames").glob("*.json")))
    assert 1 <= done < 6 and not (out / "detections.csv").exists()
    for m in (out / "maps").glob("*.npy"):
        assert np.load(m).shape == (28, 25)  # every written map is whole
    assert main(["run", str(path), "--no-progress", "--resume"]) == 0
    whole = tmp_path / "whole"
    for name in ("detections.csv", "tracks.csv", "track_table.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    for folder in ("maps", "images", "frames"):
        names = sorted(p.name for p in (whole / folder).iterdir())
        assert names == sorted(p.name for p in (out / folder).iterdir())
        for n in names:
            a, b = (out / folder / n).read_bytes(), (whole / folder / n).read_bytes()
            if folder == "frames":  # records: the same but for their timings
                a, b = (json.loads(x) for x in (a, b))
                for r in (a, b):
                    r.pop("stats")
            assert a == b, f"{folder}/{n}"


def test_workers_give_the_same_files(tmp_path, scene, monkeypatch):
    """--workers 2: this process and a helper infer the frames (the helper once it has
    started: here this process is slowed down so that it has), the files are the one-process
    run's."""
    import time

    from test_live import helper_pids

    from dpom_warp.worker import FrameWorker

    path = write_config(tmp_path, scene[1])
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "one")]) == 0
    real = FrameWorker.process

    def slow(self, items, *read):  # this process only: the helpers run their own module
        if not slow.calls:  # the helper's process spawned, then ample time for it to start
            deadline = time.time() + 30
            while not helper_pids() and time.time() < deadline:
                time.sleep(0.05)
            time.sleep(8.0)
        slow.calls += 1
        time.sleep(0.5)
        return real(self, items, *read)

    slow.calls = 0

    monkeypatch.setattr(FrameWorker, "process", slow)
    assert main(["run", str(path), "--no-progress", "--workers", "2", "--output", str(tmp_path / "two")]) == 0
    assert not own_start_files()  # the helpers' start file removed with them
    one, two = tmp_path / "one", tmp_path / "two"
    for name in ("detections.csv", "tracks.csv", "track_table.csv"):
        assert (one / name).read_bytes() == (two / name).read_bytes(), name
    for folder in ("maps", "images"):
        for m in (one / folder).iterdir():
            assert (two / folder / m.name).read_bytes() == m.read_bytes()
    summary = json.load(open(two / "summary.json"))
    assert summary["scores"] == json.load(open(one / "summary.json"))["scores"]
    workers = summary["runner"]["frames_per_worker"]
    assert "main" in workers and any(w.startswith("process ") for w in workers), workers
    assert sum(workers.values()) == summary["frames"]


def own_start_files() -> list:
    """This process's files for its helpers to start from (worker.helper_start_file)."""
    import os

    return list(Path(tempfile.gettempdir()).glob(f"{CACHE_PREFIX}{os.getpid()}-*/helper.pickle"))


def test_a_worker_process_that_dies_before_reading_its_start_is_one_line(tmp_path, scene):
    """--workers 2, the helper dying as it is spawned, before it reads what it starts from
    (here: a program that exits at once in place of Python): the run ends with the one line
    (exit 1). It hung when the engine's spec and kernels (~1 MB) were the spawn's arguments:
    CPython writes them into a pipe whose reading end it holds open itself, so the write never
    ended and the pool's lock was never released. (A process of its own: a hang is a timeout.)"""
    path = write_config(tmp_path, scene[1])
    script = ("import multiprocessing.resource_tracker, multiprocessing.spawn, shutil, sys\n"
              "from dpom_warp.cli import main\n"
              "multiprocessing.resource_tracker.ensure_running()  # spawned with Python\n"
              "multiprocessing.spawn.set_executable(shutil.which('true'))\n"
              f"sys.exit(main(['run', {str(path)!r}, '--no-progress', '--workers', '2']))\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        err = proc.communicate(timeout=180)[1].strip()
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail("the run hung on a helper that died before reading its start")
    assert proc.returncode == 1, err
    assert "--workers: a worker process died" in err and "continue with --resume" in err and "\n" not in err
    assert not list(Path(tempfile.gettempdir()).glob(f"{CACHE_PREFIX}{proc.pid}-*")), \
        "the helpers' start file left behind"


def test_a_worker_process_that_dies_is_one_line_and_resume_finishes(tmp_path, scene, monkeypatch, capsys):
    """--workers 2: the helper killed mid-run ends the run with one line (exit 1), the frames
    written before kept; --resume finishes it to the one-process run's files."""
    import os
    import signal
    import threading
    import time

    from test_live import helper_pids

    from dpom_warp.worker import FrameWorker

    path = write_config(tmp_path, scene[1])
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "whole")]) == 0
    real, killed = FrameWorker.process, []

    def slow(self, items, *read):  # this process: slow enough that the helper takes chunks
        time.sleep(1.0)
        return real(self, items, *read)

    def kill_the_helper():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            pids = helper_pids()
            if pids and (tmp_path / "out" / "maps").exists():
                for pid in pids:
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
            time.sleep(0.05)

    monkeypatch.setattr(FrameWorker, "process", slow)
    killer = threading.Thread(target=kill_the_helper, daemon=True)
    killer.start()
    assert main(["run", str(path), "--no-progress", "--workers", "2"]) == 1
    killer.join(5)
    assert killed
    err = capsys.readouterr().err.strip()
    assert "--workers: a worker process died" in err and "continue with --resume" in err and "\n" not in err
    monkeypatch.setattr(FrameWorker, "process", real)
    assert main(["run", str(path), "--no-progress", "--resume"]) == 0
    out, whole = tmp_path / "out", tmp_path / "whole"
    for name in ("detections.csv", "tracks.csv", "track_table.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    for m in (whole / "maps").iterdir():
        assert (out / "maps" / m.name).read_bytes() == m.read_bytes()


@pytest.mark.parametrize("graph", ["off", "on"])
def test_batches_give_the_same_files_and_skip_bad_frames(tmp_path, scene, graph):
    """engine.batch: frames go through the engine several at a time (with the loop replayed as
    a graph or not); a bad frame in a batch is skipped alone and the others are unchanged."""
    folder = frames_with(tmp_path, scene[0], "0002.png", truncated)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    one = write_config(tmp_path / "a", scene[1], input__frames=f"{folder}/*")
    many = write_config(tmp_path / "b", scene[1], input__frames=f"{folder}/*", engine__batch=4,
                        engine__graph=graph)
    assert main(["run", str(one), "--no-progress"]) == 0
    assert main(["run", str(many), "--no-progress"]) == 0
    a, b = tmp_path / "a" / "out", tmp_path / "b" / "out"
    assert (a / "detections.csv").read_bytes() == (b / "detections.csv").read_bytes()
    maps = sorted(m.name for m in (a / "maps").iterdir())
    assert len(maps) == 5 and maps == sorted(m.name for m in (b / "maps").iterdir())
    for m in maps:
        assert (b / "maps" / m).read_bytes() == (a / "maps" / m).read_bytes()
    summary = json.load(open(b / "summary.json"))
    assert [s["frame"] for s in summary["skipped"]] == ["0002.png"]
    assert summary["scores"] == json.load(open(a / "summary.json"))["scores"]
    assert summary["inference"]["batch"] == 4  # as given; auto on the CPU: one frame a call
    assert json.load(open(a / "summary.json"))["inference"]["batch"] == 1


def test_auto_batch_is_a_gpus_and_shrinks_to_the_memory_budget(tmp_path, scene, monkeypatch):
    """engine.batch auto: 16 frames a call for a recorded run on a GPU, one otherwise; where
    engine.memory_gb holds fewer, halved until it holds them (given, the batch is refused
    with the budget's error)."""
    from dpom_warp import session
    from dpom_warp.api import Detector

    assert session.auto_batch("cuda:0", recorded=True) == 16
    assert session.auto_batch("cuda:0", recorded=False) == session.auto_batch("cpu", recorded=True) == 1
    path = write_config(tmp_path, scene[1])
    held = {n: Detector.from_config(path, overrides={"engine.batch": n}).engine.memory_bytes() for n in (2, 8)}
    budget = (held[2] + held[8]) / 2 / 2**30  # two frames' buffers fit, eight do not
    with pytest.raises(ConfigError, match="engine.memory_gb: the engine needs at least"):
        Detector.from_config(path, overrides={"engine.memory_gb": budget, "engine.batch": 8})
    monkeypatch.setattr(session, "auto_batch", lambda device, recorded: 8)  # (a GPU's choice, on the CPU)
    det = Detector.from_config(path, overrides={"engine.memory_gb": budget})
    assert 2 <= det.engine.batch < 8 and det.engine.memory_bytes() <= budget * 2**30


def test_every_frame_over_max_entries_fails_and_leaves_nothing(tmp_path, scene, capsys):
    """A run whose every frame is refused while inferring (lists over engine.max_entries) is a
    failure, not "0 frames": one line, exit 2, no output folder; the same with --strict."""
    path = write_config(tmp_path, scene[1], engine__max_entries=50)
    for extra in ([], ["--strict"]):
        assert main(["run", str(path), "--no-progress", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("dpom-warp: error: ") and "\n" not in err and "engine.max_entries" in err
        assert not (tmp_path / "out").exists(), extra


def test_unreachable_ray_address_is_one_line_at_once(tmp_path, scene):
    """--ray at an address nothing listens on: one line and exit 2 within seconds (Ray alone
    retries for minutes), nothing written."""
    import socket

    with socket.socket() as s:  # a port nothing listens on once this closes
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = write_config(tmp_path, scene[1])
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "dpom_warp.cli", "run", str(path), "--no-progress", "--ray",
                           f"127.0.0.1:{port}"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and time.perf_counter() - t < 60
    err = proc.stderr.strip()
    assert "\n" not in err and f"--ray: cannot join a Ray cluster at 127.0.0.1:{port}: nothing answers" in err
    assert not (tmp_path / "out").exists()


def test_a_record_is_written_only_after_its_map_and_picture(tmp_path, scene, monkeypatch, capsys):
    """The picture of the third frame cannot be written: the run stops with one line (exit 1),
    that frame has its map but no record (so it is not done), the frames before are whole, and
    --resume finishes the run to a whole run's files."""
    import dpom_warp.writers as writers  # a frame's files: writers.Pictures

    path = write_config(tmp_path, scene[1], tracking__method="off")  # pictures drawn per frame
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "whole")]) == 0
    real = writers.write_bytes_atomic

    def failing(target, data):
        if Path(target).name == "0002.png":
            raise OSError(28, "No space left on device", str(target))
        return real(target, data)

    monkeypatch.setattr(writers, "write_bytes_atomic", failing)
    capsys.readouterr()
    assert main(["run", str(path), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "0002.png: No space left on device" in err and "--resume" in err
    out = tmp_path / "out"
    assert (out / "maps" / "0002.npy").exists() and not (out / "frames" / "0002.json").exists()
    assert sorted(p.name for p in (out / "frames").glob("*.json")) == ["0000.json", "0001.json"]
    monkeypatch.setattr(writers, "write_bytes_atomic", real)
    assert main(["run", str(path), "--no-progress", "--resume"]) == 0
    for name in ("detections.csv",):
        assert (out / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
    for p in (tmp_path / "whole" / "images").iterdir():
        assert (out / "images" / p.name).read_bytes() == p.read_bytes()


def csv_rows(path: Path) -> list:
    import csv

    return [r for r in csv.reader(open(path))][1:]


def entries_of(run: Path) -> dict:
    return {p["frame"]: p["entries"] for p in json.loads((run / "summary.json").read_text())["per_frame"]}


def test_frames_over_max_entries_inside_a_run_are_skipped_with_their_reason(tmp_path, scene, capsys):
    """A cap between the frames' list sizes: the frames above it are skipped, listed with
    their reason, the others inferred as without the cap; --strict stops at the first."""
    first = tmp_path / "first"
    path = write_config(tmp_path, scene[1], tracking__method="off", output__images=False)
    assert main(["run", str(path), "--no-progress", "--output", str(first)]) == 0
    entries = entries_of(first)
    cap = sorted(entries.values())[len(entries) // 2]  # the larger half cannot fit
    over = sorted(f for f, n in entries.items() if n > cap)
    assert 0 < len(over) < len(entries)
    path = write_config(tmp_path, scene[1], tracking__method="off", output__images=False,
                        engine__max_entries=cap)
    capsys.readouterr()
    assert main(["run", str(path), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(s["frame"] for s in summary["skipped"]) == over
    assert all("engine.max_entries" in s["reason"] for s in summary["skipped"])
    kept = [r for r in csv_rows(first / "detections.csv") if r[0] not in over]
    assert csv_rows(tmp_path / "out" / "detections.csv") == kept
    assert main(["run", str(path), "--no-progress", "--overwrite", "--strict"]) == 2
    assert "engine.max_entries" in capsys.readouterr().err


def test_a_batch_over_max_entries_is_retried_frame_by_frame(tmp_path, scene):
    """Batches of 3 whose lists together outgrow the cap while each frame fits: every frame is
    inferred alone instead, to the files of a run without batches."""
    first = tmp_path / "first"
    path = write_config(tmp_path, scene[1], tracking__method="off", output__images=False)
    assert main(["run", str(path), "--no-progress", "--output", str(first)]) == 0
    cap = max(entries_of(first).values()) + 1  # every frame fits, no batch of 3 does
    path = write_config(tmp_path, scene[1], tracking__method="off", output__images=False,
                        engine__max_entries=cap, engine__batch=3)
    assert main(["run", str(path), "--no-progress"]) == 0
    assert (tmp_path / "out" / "detections.csv").read_bytes() == (first / "detections.csv").read_bytes()
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["skipped"] == []


def test_a_frame_unreadable_inside_a_batch_is_skipped_alone(tmp_path, scene):
    """A frame that cannot be read when its batch comes (its file replaced after the run's
    checks): its outcome is the reason, the batch's other frames are inferred."""
    from dpom_warp.loading import load_config
    from dpom_warp.pipeline import plan_run
    from dpom_warp.worker import FrameItem, FrameWorker

    path = write_config(tmp_path, scene[1], tracking__method="off", output__images=False, engine__batch=3)
    cfg = load_config(path)
    plan = plan_run(cfg, str(tmp_path / "out"), "cpu", log=lambda *_: None)
    worker = FrameWorker(plan.spec, engine=plan.engine)
    items = [FrameItem(str(f)) for f in plan.frames[:3]]
    items[1] = FrameItem(items[1].path, b"not a png")  # what a worker would get for a damaged file
    outcomes = worker.process(items)
    assert [o[0] for o in outcomes][0] == Path(items[1].path).name and outcomes[0][2] is not None
    assert "not a readable image" in outcomes[0][2]
    assert sorted(o[0] for o in outcomes[1:]) == sorted(Path(items[i].path).name for i in (0, 2))
    assert all(o[1] is not None and o[2] is None for o in outcomes[1:])


def _limits(model, prefix=""):
    """(key, kind, limit) of every bound the config's models state (pydantic's gt, ge, lt, le)."""
    import typing

    import annotated_types as at
    from pydantic import BaseModel

    for name, f in model.model_fields.items():
        ann = f.annotation
        subs = [ann] if isinstance(ann, type) and issubclass(ann, BaseModel) else [
            a for a in typing.get_args(ann) if isinstance(a, type) and issubclass(a, BaseModel)]
        for sub in subs:
            yield from _limits(sub, f"{prefix}{name}.")
        for m in f.metadata:
            for kind, cls in (("gt", at.Gt), ("ge", at.Ge), ("lt", at.Lt), ("le", at.Le)):
                if isinstance(m, cls):
                    yield f"{prefix}{name}", kind, getattr(m, kind)


def test_every_config_value_at_each_limit_it_states():
    """Issue 63, boundaries: every bound a config key states (the schema and docs/config.md say
    it) holds at the limit itself: an exclusive one (> or <) refuses the limit with the one-line
    error naming the key, an inclusive one (>= or <=) takes it and refuses one step beyond (1 for
    a count, 1e-6 for a value), naming the key. Three inclusive limits meet another key's check
    first (a camera 1 pixel wide cannot hold cx 31.5), which that key's error names."""
    from dpom_warp.config import ConfigError, parse_config
    from dpom_warp.config.read import apply_overrides
    from dpom_warp.config.schema import ConfigFile

    base = {"device": "cpu", "input": {"frames": "f/*.png"}, "synthetic": {"cache": "c"},
            "camera": {"width": 64, "height": 48, "intrinsics": {"fx": 50.0, "fy": 50.0, "cx": 31.5, "cy": 23.5},
                       "extrinsics": {"height": 2.0, "pitch_deg": 20.0}},
            "grid": {"x": [-1, 1, 0.1], "y": [1, 3, 0.1]}}
    parse_config(base)
    other_first = {"input.background_auto.max_frames": "input.background_auto.min_frames",
                   "camera.width": "camera.intrinsics.cx", "camera.height": "camera.intrinsics.cy"}

    def error(key, value):
        try:
            parse_config(apply_overrides(base, [f"{key}={value}"]))
        except ConfigError as e:
            assert "\n" not in str(e)
            return str(e)
        return None

    limits = list(_limits(ConfigFile))
    assert len(limits) > 100
    for key, kind, v in limits:
        sign = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}[kind]
        if kind in ("gt", "lt"):
            assert error(key, v) == f"{key}: expected a value {sign} {v:g}, found {v:g}", key
            continue
        step = 1 if isinstance(v, int) else 1e-6
        beyond = v - step if kind == "ge" else v + step
        got = error(key, v)
        assert got is None or got.startswith(other_first[key] + ": "), (key, got)
        assert error(key, beyond).startswith(f"{key}: expected a value {sign} {v:g}"), (key, beyond)

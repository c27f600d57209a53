"""Long runs and faults: identical runs give identical bytes, interrupted and killed runs
resume to the same files, worker processes and batches give the one-process run's files (a
helper that dies is one line), and a frame's record is written only after its map and picture."""

import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from dpom_warp.cli import main
from dpom_warp.config import ConfigError
from dpom_warp.io import TEMP_MARK
from dpom_warp.worker import CACHE_PREFIX

from run_scene import frames_with, scene_fixture, truncated, write_config  # noqa: F401 (the fixture `scene`)


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

"""`dpom-warp run CONFIG --play` (input.play): the frames of a folder or a recording sent at
their own rate through the live path (newest frame inferred, the rest dropped, tracks online),
live mode tried without a camera; the maps are the plain run's, frame by frame."""

import json
import time

import numpy as np
import pytest
import yaml

from dpom_warp.cli import main
from test_cli import small_config


def test_played_frames_go_through_the_live_path_and_give_the_plain_maps(tmp_path, capsys):
    path = small_config(tmp_path, frames=6)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "plain"),
                 "--set", "output.images=false"]) == 0
    capsys.readouterr()
    t = time.perf_counter()
    assert main(["run", str(path), "--no-progress", "--play", "--output", str(tmp_path / "live"),
                 "--set", "input.fps=10", "--set", "output.images=false"]) == 0
    wall = time.perf_counter() - t
    printed = capsys.readouterr().out
    assert "until the frames end, Ctrl-C" in printed and "(stopped by end of the frames)" in printed
    summary = json.loads((tmp_path / "live" / "summary.json").read_text())
    live = summary["live"]
    assert live["received"] == 6 and live["frames"] + live["dropped"] == 6 and live["frames"] >= 1
    assert live["stopped_by"] == "end of the frames" and live["camera_fps"] == 10
    assert wall > 0.5  # the last frame is sent 5 intervals of 0.1 s after the first
    names = [p["frame"] for p in summary["per_frame"]]  # the files' names, in order
    assert names == sorted(names) and set(names) <= {f"{i:04d}" for i in range(6)}
    for p in summary["per_frame"]:
        assert p["timestamp"] == pytest.approx(int(p["frame"]) / 10)  # at input.fps
        np.testing.assert_array_equal(np.load(tmp_path / "live" / "maps" / f"{p['frame']}.npy"),
                                      np.load(tmp_path / "plain" / "maps" / f"{p['frame']}.npy"))
    assert json.loads((tmp_path / "live" / "run.json").read_text())["config"]["input"]["play"] is True
    assert summary["tracking"]["method"] == "online"


def test_a_played_recording_keeps_its_own_clock(tmp_path):
    """A bag's frames are sent at its timestamps (10 frames/s here, whatever input.fps says)
    and the records carry them."""
    from test_recordings import camera_of, messages, recording_config, typestore, write_bag

    path = small_config(tmp_path, frames=3)
    assert main(["run", str(path), "--no-progress", "--set", "output.images=false"]) == 0  # renders the frames
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]
    cfg["evaluation"]["ground_truth"] = None
    frames = sorted((tmp_path / "scene" / "frames").glob("*.png"))
    write_bag(tmp_path / "recording.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg)))
    rec = recording_config(tmp_path, cfg, "recording.bag", name="rec.yaml")
    assert main(["run", str(rec), "--no-progress", "--play", "--output", str(tmp_path / "live"),
                 "--set", "input.fps=2", "--set", "output.images=false"]) == 0
    summary = json.loads((tmp_path / "live" / "summary.json").read_text())
    assert summary["live"]["camera_fps"] == pytest.approx(10.0) and summary["live"]["received"] == 3
    stamps = {round(p["timestamp"], 6) for p in summary["per_frame"]}
    assert stamps <= {100.0, 100.1, 100.2} and summary["live"]["frames"] == len(stamps)


@pytest.mark.parametrize("flag", ["--resume", "--ray"])
def test_play_with_resume_or_ray_is_one_line(tmp_path, capsys, flag):
    path = small_config(tmp_path, frames=2)
    assert main(["run", str(path), "--no-progress", "--play", flag]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dpom-warp: error: --play: ") and err.rstrip().endswith(f"expected no {flag}")
    assert not (tmp_path / "out").exists()


def test_the_newest_frame_slot_ends_with_its_stream():
    """put(None): the last frame still there is taken, then take returns None at once."""
    from dpom_warp.sources import NewestFrame

    slot = NewestFrame()
    slot.put("a")
    slot.put("b")
    slot.put(None)
    t = time.perf_counter()
    assert slot.take(10.0) == "b" and slot.take(10.0) is None
    assert time.perf_counter() - t < 1.0 and slot.ended and (slot.received, slot.dropped) == (2, 1)

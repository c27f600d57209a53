"""`dpom-warp run` end to end on a small rendered scene, and its errors."""

import csv
import json

import numpy as np
import pytest
import yaml

from dpom_warp.cli import main
from paths import CONFIGS
from pictures import assert_picture


def small_config(tmp_path, frames=3, **changes):
    """The demo config shrunk to a 128x106 camera and a coarse grid, rendering `frames` frames
    (3 people, 4 background frames) into tmp_path/scene, no evaluation figures; `changes` replace
    top-level sections."""
    cfg = yaml.safe_load(open(CONFIGS / "demo_people.yaml"))
    cache = tmp_path / "scene"
    cfg["device"] = "cpu"
    cfg["input"]["frames"] = f"{cache}/frames/*.png"
    cfg["input"]["background"] = f"{cache}/background/*.png"
    cfg["camera"].update(width=128, height=106,
                         intrinsics={"fx": 91.25, "fy": 91.25, "cx": 63.5, "cy": 52.5})
    cfg["grid"].update(x=[-2.5, 2.5, 0.2], y=[1.0, 6.5, 0.2])
    cfg["evaluation"]["ground_truth"] = f"{cache}/ground_truth.json"
    cfg["evaluation"]["plots"] = False  # 1.7 s of matplotlib a run; the tests of the figures turn them on
    cfg["output"]["dir"] = str(tmp_path / "out")
    cfg["synthetic"].update(cache=str(cache), frames=frames, background_frames=4, people=3, seed=3)
    for k, v in changes.items():
        cfg[k] = v
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_run_writes_all_outputs(tmp_path, capsys):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    out = tmp_path / "out"
    printed = capsys.readouterr().out
    assert "MODA" in printed
    rows = list(csv.reader(open(out / "detections.csv")))
    assert rows[0] == ["frame", "x", "y", "z", "rho", "u0", "v0", "u1", "v1"]
    assert len(rows) > 1
    for r in rows[1:]:
        assert r[0].endswith(".png") and 0.5 <= float(r[4]) <= 1.0
        u0, v0, u1, v1 = map(int, r[5:])
        assert 0 <= u0 <= u1 < 128 and 0 <= v0 <= v1 < 106
    frames = sorted(p.name for p in (tmp_path / "scene" / "frames").glob("*.png"))
    assert len(frames) == 3
    for name in frames:
        stem = name[:-4]
        m = np.load(out / "maps" / f"{stem}.npy")
        assert m.shape == (28, 25) and m.dtype == np.float32
        assert np.all((m >= 0) & (m <= 1))
        assert_picture(out / "images" / f"{stem}.png", (128 + 100, 106))  # the frame and the map beside it
    summary = json.load(open(out / "summary.json"))
    assert summary["config"]["grid"]["x"] == [-2.5, 2.5, 0.2]
    assert summary["scores"]["n_gt"] == 9
    assert summary["scores"]["moda"] > 0.5
    assert summary["timings"]["median_infer_s"] > 0
    assert not list(out.rglob(".*.tmp")) and not list(out.rglob(".*png"))  # no temporary files


def test_floor_only_background_and_set_override(tmp_path):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress", "--set", "input.background=null",
                 "--set", "detection.threshold=0.6", "--output", str(tmp_path / "floor")]) == 0
    summary = json.load(open(tmp_path / "floor" / "summary.json"))
    assert summary["background"] == "floor plane only"
    assert summary["config"]["detection"]["threshold"] == 0.6
    assert summary["scores"]["tp"] > 0


def test_max_frames_takes_the_first_frames_of_any_source(tmp_path, capsys):
    """--max-frames N runs the first N frames of a glob (a quick look at a long recording),
    said on the console; the outputs hold those frames alone."""
    path = small_config(tmp_path, frames=4)
    assert main(["run", str(path), "--no-progress", "--max-frames", "2"]) == 0
    assert "--max-frames: the first 2 of 4 frames" in capsys.readouterr().out
    summary = json.load(open(tmp_path / "out" / "summary.json"))
    assert summary["frames"] == 2 and summary["scores"]["n_gt"] == 6  # 3 people in each of 2 frames
    with open(tmp_path / "out" / "detections.csv") as f:
        assert {r["frame"] for r in csv.DictReader(f)} == {"0000.png", "0001.png"}
    assert sorted(p.name for p in (tmp_path / "out" / "maps").iterdir()) == ["0000.npy", "0001.npy"]


def test_a_folder_of_frames_is_its_png_and_npy_files(tmp_path, capsys):
    """input.frames may name a folder (a user points at where the frames are): its .png and
    .npy files in sorted order, the glob's run; a folder with none is a one-line error."""
    from dpom_warp.sources.files import FileFrames

    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    (tmp_path / "scene" / "frames" / "notes.txt").write_text("not a frame")
    assert main(["run", str(path), "--no-progress", "--set", f"input.frames={tmp_path / 'scene' / 'frames'}",
                 "--output", str(tmp_path / "folder")]) == 0
    assert (tmp_path / "folder" / "detections.csv").read_text() == (tmp_path / "out" / "detections.csv").read_text()
    assert [f.name for f in FileFrames(str(tmp_path / "scene" / "frames")).files] == ["0000.png", "0001.png", "0002.png"]
    (tmp_path / "empty").mkdir()
    capsys.readouterr()
    assert main(["run", str(path), "--no-progress", "--set", f"input.frames={tmp_path / 'empty'}",
                 "--output", str(tmp_path / "none")]) == 2
    assert "a folder with no frames in it (expected 16-bit PNG or .npy" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


def test_fit_ground_takes_a_folder_or_a_quoted_glob(tmp_path, capsys):
    """`dpom-warp fit-ground FOLDER` (and a glob the shell did not expand) fits on the frame
    files in it, as input.frames takes them: the rendered scene's pose (2.2 m, pitch 20)."""
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress", "--max-frames", "1"]) == 0  # renders the scene
    camera = tmp_path / "camera.yaml"
    camera.write_text(yaml.safe_dump({"width": 128, "height": 106, "depth_scale": 0.001,
                                      "intrinsics": {"fx": 91.25, "fy": 91.25, "cx": 63.5, "cy": 52.5}}))
    background = tmp_path / "scene" / "background"
    for source, count in ((str(background), 4), (f"{background}/000[01].png", 2)):
        out = tmp_path / "pose.yaml"
        assert main(["fit-ground", source, "--camera", str(camera), "--output", str(out)]) == 0
        text = out.read_text()
        pose = yaml.safe_load(text)
        assert f"fit-ground on {count} frame(s)" in text
        assert pose["camera_height"] == pytest.approx(2.2, abs=0.02) and pose["pitch_deg"] == pytest.approx(20, abs=0.5)


@pytest.mark.parametrize("override, message", [
    ("grid.x=[1, 0, 0.1]", "grid.x: expected min < max"),
    ("grid.y=[0, 5, 0]", "grid.y: expected a step > 0"),
    ("model.damping=0", "model.damping: expected a value > 0"),
    ("detection.threshold=1.5", "detection.threshold: expected a value < 1"),
    ("model.dampng=0.2", "model.dampng: unknown key"),
    ("camera.width=abc", "camera.width: expected an integer, found 'abc'"),
    ("device=tpu", "device: expected auto, cpu, cuda or cuda:N, found 'tpu'"),
    ("camera.width=640", "expected 640x106 pixels (camera.width x camera.height), found 128x106"),
    ("object.width=9", "object.width: expected at most the grid's x extent 5 m, found 9"),
    ("camera.extrinsics.T_world_from_camera=[[1,0],[0,1]]", "expected a 4x4 list of numbers"),
    ("input.background_auto={min_frames: 200}", "input.background_auto.min_frames: expected at "
     "most max_frames (100), found 200"),
    ("model.top_band=1", "model.top_band: expected a value < 1"),
])
def test_bad_config_is_one_line_exit_2(tmp_path, capsys, override, message):
    path = small_config(tmp_path)
    if override.startswith("camera.extrinsics"):
        cfg = yaml.safe_load(path.read_text())
        cfg["camera"]["extrinsics"] = {"T_world_from_camera": [[1, 0], [0, 1]]}
        path.write_text(yaml.safe_dump(cfg))
        override = "device=cpu"
    if override.startswith("camera.width=640"):
        assert main(["run", str(path), "--no-progress"]) == 0  # render the frames first
        override = "camera.width=640"
        capsys.readouterr()
        args = ["run", str(path), "--no-progress", "--set", override, "--set", "synthetic=null",
                "--set", "camera.intrinsics.cx=319.5", "--output", str(tmp_path / "other")]  # (the output
        # folder is checked first: the render's run filled out/)
    else:
        args = ["run", str(path), "--no-progress", "--set", override]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert len(err.splitlines()) == 1 and err.startswith("dpom-warp: error: ")
    assert "Traceback" not in err


def test_unavailable_device_is_a_config_error(tmp_path, capsys):
    path = small_config(tmp_path)
    import warp as wp

    assert main(["run", str(path), "--no-progress", "--device", "cuda:7"]) == 2
    err = capsys.readouterr().err
    assert "device: expected one of auto, cpu" in err and "found 'cuda:7'" in err
    assert err.rstrip().endswith("(Warp finds no CUDA device here)") == (not wp.get_cuda_devices())


def test_missing_frames_names_the_key(tmp_path, capsys):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress", "--set", "synthetic=null",
                 "--set", f"input.frames={tmp_path}/nothing/*.png"]) == 2
    assert "input.frames: no files match" in capsys.readouterr().err


def test_images_every_draws_every_nth_frame_with_or_without_tracks(tmp_path):
    """output.images_every on a recorded run: pictures of the 1st, N+1th, ... frames done,
    the same pictures as every frame's (with tracks or without); a retrack at another N
    leaves no stale picture."""
    path = small_config(tmp_path, frames=5)
    stems = [f"{i:04d}" for i in range(5)]
    pictures = {}
    for method in ("ksp", "off"):
        for every in (1, 2):
            out = tmp_path / f"out_{method}_{every}"
            assert main(["run", str(path), "--no-progress", "--output", str(out), "--set",
                         f"tracking.method={method}", "--set", f"output.images_every={every}"]) == 0
            pictures[method, every] = {p.stem: p.read_bytes() for p in (out / "images").iterdir()}
        assert sorted(pictures[method, 1]) == stems and sorted(pictures[method, 2]) == stems[::2]
        assert all(pictures[method, 2][s] == pictures[method, 1][s] for s in stems[::2])
    assert pictures["ksp", 1] != pictures["off", 1]  # with tracks: their identities drawn
    run = tmp_path / "out_ksp_1"
    assert main(["track", str(run), "--set", "output.images_every=3"]) == 0
    assert sorted(p.stem for p in (run / "images").iterdir()) == stems[::3]
    assert main(["track", str(run), "--set", "tracking.method=off", "--set", "output.images_every=2"]) == 0
    assert {p.stem: p.read_bytes() for p in (run / "images").iterdir()} == {
        s: pictures["off", 1][s] for s in stems[::2]}


def test_view_is_a_config_key_not_a_process_flag(tmp_path, monkeypatch):
    """`--view` is `output.view: true` for that run alone: the run's resolved config says so,
    its Rerun log is spawned, and a later run in the same process without it spawns nothing
    (it was a module-level flag that stayed set for every later run)."""
    from dpom_warp import view

    spawned = []

    class Recorder:
        def __init__(self, path, spawn=False, name="dpom-warp"):
            spawned.append(spawn)

        def __getattr__(self, name):
            return lambda *a, **k: None

    monkeypatch.setattr(view, "RerunLog", Recorder)
    path = small_config(tmp_path, frames=2)
    assert main(["run", str(path), "--no-progress", "--view", "--set", "output.images=false"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["output"]["view"] is True and spawned == [True]
    assert main(["run", str(path), "--no-progress", "--overwrite", "--set", "output.images=false"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["output"]["view"] is False and spawned == [True]


def test_info_into_a_pipe_closed_early_ends_quietly(tmp_path):
    """`dpom-warp info SOURCE --json | head -1`: the reader stops early; info ends with exit 0
    and nothing on stderr (it printed a run's "Broken pipe ... --resume" line). The reader here
    (`true`) reads nothing and is gone before info prints: the closed pipe every time."""
    import subprocess
    import sys

    from paths import REAL

    bag = next(REAL.glob("**/*.bag"))
    cmd = f'"{sys.executable}" -m dpom_warp.cli info "{bag}" --json | true'
    done = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=120)
    assert done.stderr == "" and done.returncode == 0, (done.returncode, done.stderr)


def test_a_full_output_folder_is_refused_before_any_setup(tmp_path, capsys):
    """The "not empty" error comes first: nothing is rendered, fitted or set up, nothing
    printed on stdout before it (it came after the scene check and the engine's setup)."""
    path = small_config(tmp_path, frames=2)
    assert main(["run", str(path), "--no-progress", "--set", "output.images=false"]) == 0
    capsys.readouterr()
    assert main(["run", str(path), "--no-progress"]) == 2
    got = capsys.readouterr()
    assert got.out == ""
    assert got.err.startswith("dpom-warp: error: output.dir: ") and "is not empty" in got.err
    assert main(["run", str(path), "--no-progress", "--resume", "--set", "model.prior=0.02"]) == 2
    got = capsys.readouterr()
    assert got.out == "" and "holds a run of another config (model.prior: 0.01 then, 0.02 now)" in got.err


def test_resume_redoes_a_frame_whose_map_was_removed(tmp_path, capsys):
    """--resume on a finished run whose maps/0001.npy was deleted infers that frame again and
    ends with the plain run's files (it stopped with "maps/0001.npy: No such file ... continue
    with --resume"); an unreadable record is done again the same way."""
    path = small_config(tmp_path, frames=3)
    plain, again = tmp_path / "plain", tmp_path / "again"
    for out in (plain, again):
        assert main(["run", str(path), "--no-progress", "--output", str(out), "--set", "output.images=false"]) == 0
    (again / "maps" / "0001.npy").unlink()
    (again / "frames" / "0002.json").write_text("{truncated")
    capsys.readouterr()
    assert main(["run", str(path), "--no-progress", "--output", str(again), "--resume",
                 "--set", "output.images=false"]) == 0
    assert "1 frames already done, 2 to go (2 of them again" in capsys.readouterr().out
    for name in ("detections.csv", "tracks.csv", "maps/0000.npy", "maps/0001.npy", "maps/0002.npy"):
        assert (again / name).read_bytes() == (plain / name).read_bytes(), name
    for n in ("0001", "0002"):
        assert json.loads((again / "frames" / f"{n}.json").read_text())["rows"] == \
            json.loads((plain / "frames" / f"{n}.json").read_text())["rows"]


def test_frames_of_an_unknown_format_without_camera_keys_name_the_file(tmp_path, capsys):
    """`input.frames: frames.xyz` and no camera keys: the file and the formats known, not
    "camera.width: required key is missing" (what the missing keys made of it)."""
    (tmp_path / "frames.xyz").write_bytes(b"\0" * 16)
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump({"input": {"frames": "frames.xyz"}, "grid": {"x": [-2, 2, 0.1], "y": [1, 6, 0.1]},
                                    "output": {"dir": str(tmp_path / "out")}}))
    assert main(["run", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"dpom-warp: error: {path}: input.frames: {tmp_path / 'frames.xyz'}: unknown format '.xyz'; "
                   f"expected a folder or glob of 16-bit PNG or .npy frames, a recording (.bag, .db3, .mcap, .mkv, "
                   f"a ROS 2 bag's folder) or a live camera (realsense[:SERIAL])")
    assert not (tmp_path / "out").exists()


def test_config_errors_say_where_the_value_came_from(tmp_path, capsys):
    """A `--set` error is blamed on the --set, not the config file; a frames path that matches
    nothing, or an empty folder, names the config file (or the --set) as well as the key."""
    path = small_config(tmp_path, frames=2)

    def error(*args):
        assert main(["run", str(path), "--no-progress", *args]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err
        return err.removeprefix("dpom-warp: error: ")

    assert error("--set", "model.prio=1").startswith("--set model.prio=1: model.prio: unknown key (did you mean prior?")
    assert error("--set", "grid.y=[1, 6, 0]").startswith("--set grid.y=[1, 6, 0]: grid.y: expected a step > 0 in [min")
    assert error("--set", "model.prior=2").startswith("--set model.prior=2: model.prior: expected a value < 1")
    raw = yaml.safe_load(path.read_text())
    raw["model"]["prio"] = 1
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(raw))
    assert main(["run", str(bad), "--no-progress", "--set", "model.prior=0.02"]) == 2
    assert capsys.readouterr().err.startswith(f"dpom-warp: error: {bad}: model.prio: unknown key")
    empty = tmp_path / "empty"
    empty.mkdir()
    raw = yaml.safe_load(path.read_text())
    del raw["synthetic"]
    raw["input"]["frames"] = str(empty)
    path.write_text(yaml.safe_dump(raw))
    assert error().startswith(f"{path}: input.frames: {empty}: a folder with no frames in it")
    assert error("--set", f"input.frames={tmp_path}/none/*.png").startswith(
        f"--set input.frames={tmp_path}/none/*.png: input.frames: no files match")
    assert not (tmp_path / "out").exists()


def test_info_on_a_folder_counts_the_frames_a_run_reads(tmp_path, capsys):
    """`info` on a folder of three good frames, a truncated PNG and an 8-bit PNG says 3 frames
    (it said 5, the files) and names the two others with their reasons: the same two a run
    of that folder skips."""
    from PIL import Image

    folder = tmp_path / "frames"
    folder.mkdir()
    depth = np.full((6, 8), 2000, np.uint16)
    for i in range(3):
        Image.fromarray(depth + i).save(folder / f"{i:04d}.png")
    (folder / "0003.png").write_bytes((folder / "0000.png").read_bytes()[:40])  # truncated
    Image.fromarray(np.full((6, 8), 200, np.uint8)).save(folder / "0004.png")  # 8-bit
    assert main(["info", str(folder), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["frames"], info["width"], info["height"]) == (3, 8, 6)
    assert [b["file"] for b in info["unreadable"]] == ["0003.png", "0004.png"]
    assert "not a readable image" in info["unreadable"][0]["reason"]
    assert "found mode L" in info["unreadable"][1]["reason"]
    assert main(["info", str(folder)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "3 frames of 8x6" in lines[1]
    assert "  not readable: 2 of 5 files (a run skips them):" in lines
    assert lines[-1].strip() == info["unreadable"][1]["reason"]
    from dpom_warp.frames import check_frames

    good, skipped = check_frames(sorted(folder.iterdir()), 0.001, (6, 8), strict=False)
    assert [f.name for f in good] == ["0000.png", "0001.png", "0002.png"]
    assert [s["frame"] for s in skipped] == ["0003.png", "0004.png"]

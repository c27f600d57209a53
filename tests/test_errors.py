"""Bad input: each case gives one line naming the key or file, exit code 2, and no output;
bad frames in a sequence are skipped and reported (fatal with --strict); every bound a config
key states holds at its limit. Long runs and faults: test_long_runs."""

import json
import subprocess
import sys
import time

import numpy as np
import pytest

from dpom_warp.cli import main
from dpom_warp.io import write_depth_png

from run_scene import (DELETE, frames_with, npy, png8, png_rgb, scene_fixture,  # noqa: F401 (the fixture `scene`)
                       truncated, write_config)


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

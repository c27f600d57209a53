"""A rig run end to end (issue 61): a rendered scene seen by two cameras 1.4 m up (people hide
each other whole from either), run as a `cameras:` config, each camera alone, a camera whose
frames run out, a rig of one against the single-camera config, --workers, `track` and the
Python API. The engine's fusion against the NumPy reference is in test_warp_vs_reference and
test_rig."""

import copy
import csv
import json
import math
import re
import shutil
import statistics

import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp.cli import main
from pictures import assert_picture

CAMERA = {"width": 160, "height": 120, "intrinsics": {"fx": 115.0, "fy": 115.0, "cx": 79.5, "cy": 59.5}}
POSES = {"front": {"height": 1.4, "pitch_deg": 8.0},  # at the grid's near end, looking along +y
         "side": {"height": 1.4, "pitch_deg": 8.0, "yaw_deg": 90.0, "x": 3.5, "y": 3.5}}  # at its right, across


def rig_config(folder, names=("front", "side"), out="out", **changes) -> dict:
    """The rig's config (cameras `names`), its frames rendered into folder/scene (8 people,
    6 frames); `changes` replace top-level sections."""
    scene = folder / "scene"
    cfg = {"device": "cpu",
           "cameras": [{"name": n, "input": {"frames": f"{scene}/{n}/frames/*.png",
                                             "background": f"{scene}/{n}/background/*.png", "fps": 5},
                        "camera": {**CAMERA, "extrinsics": POSES[n]}} for n in names],
           "grid": {"x": [-2.0, 2.0, 0.1], "y": [1.5, 5.5, 0.1]},
           "object": {"width": 0.4, "height": 1.85, "shape": "solid"},
           "evaluation": {"ground_truth": f"{scene}/ground_truth.json"},
           "output": {"dir": str(folder / out)},
           "synthetic": {"cache": str(scene), "seed": 2, "frames": 6, "background_frames": 4, "people": 8,
                         "area": [-1.8, 1.8, 1.8, 5.2]}}
    cfg.update(changes)
    return copy.deepcopy(cfg)  # (callers change it: never the module's POSES and CAMERA)


def write(path, cfg):
    path.write_text(yaml.safe_dump(cfg))
    return str(path)


def detections(folder) -> dict:
    out = {}
    for row in csv.DictReader(open(folder / "detections.csv")):
        out.setdefault(row["frame"], []).append((float(row["x"]), float(row["y"])))
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The rig run, and each camera alone (a rig of one) on the same frames."""
    folder = tmp_path_factory.mktemp("rig")
    for name, names in (("out", ("front", "side")), ("front", ("front",)), ("side", ("side",))):
        rig = rig_config(folder, names, out=name)
        if name != "out":
            rig.pop("synthetic")  # the rig's scene: rendered by its run
        assert main(["run", write(folder / f"{name}.yaml", rig), "--no-progress"]) == 0
    return folder


def test_people_hidden_from_one_camera_are_found_by_the_rig(runs):
    """Every person under 5 % visible from one camera and at least half visible from the other
    (the rendered truth says which) is detected by the rig within 0.3 m, and the camera they
    are hidden from, alone, has no detection within 0.3 m of them: the other camera's pixels
    found them in the one map. The rig scores at least each camera alone."""
    truth = json.loads((runs / "scene" / "ground_truth.json").read_text())
    rig, alone = detections(runs / "out"), {n: detections(runs / n) for n in ("front", "side")}

    def nearest(dets, frame, o):
        return min([math.hypot(x - o["x"], y - o["y"]) for x, y in dets.get(frame, [])] + [math.inf])

    hidden = 0
    for f in truth:
        for o in f["objects"]:
            seen = o["visible_in"]
            for hid, other in (("front", "side"), ("side", "front")):
                if seen.get(hid, 0.0) < 0.05 and seen.get(other, 0.0) >= 0.5:
                    hidden += 1
                    assert nearest(rig, f["frame"], o) < 0.3, (f["frame"], o)
                    assert nearest(alone[hid], f["frame"], o) > 0.3, (f["frame"], o, hid)
    assert hidden >= 2
    moda = {n: json.loads((runs / n / "summary.json").read_text())["scores"]["moda"] for n in ("out", "front", "side")}
    assert moda["out"] >= max(moda["front"], moda["side"]) and moda["out"] > 0.95


def test_a_rig_runs_outputs(runs):
    """summary.json has each camera's frames and the frames it missed (none here), each record
    names each camera's file, the config written is the rig's; every frame's picture shows the
    second camera's depth below the first camera's and the map."""
    summary = json.loads((runs / "out" / "summary.json").read_text())
    assert {n: {k: c[k] for k in ("frames", "missing")} for n, c in summary["cameras"].items()} == {
        "front": {"frames": 6, "missing": []}, "side": {"frames": 6, "missing": []}}
    assert all(0 < c["median_read_s"] < 1 for c in summary["cameras"].values())
    # each camera's engine time: its lists and its pixels' launches in the loop, within the engine's
    # whole stage of each frame; summary.json's medians are those of the frames' records
    stats = summary["per_frame"]
    for p in stats:
        for key, whole in (("lists_s_cameras", "engine_lists_s"), ("iterations_s_cameras", "engine_iterations_s")):
            assert sorted(p[key]) == ["front", "side"] and all(t > 0 for t in p[key].values())
            assert sum(p[key].values()) <= p[whole]
    for n, c in summary["cameras"].items():
        assert c["median_lists_s"] == statistics.median(p["lists_s_cameras"][n] for p in stats)
        assert c["median_iterations_s"] == statistics.median(p["iterations_s_cameras"][n] for p in stats)
    assert [c["name"] for c in summary["config"]["cameras"]] == ["front", "side"]
    assert "input" not in summary["config"] and "camera" not in summary["config"]
    record = json.loads((runs / "out" / "frames" / "0002.json").read_text())
    assert record["cameras"] == {"front": "0002.png", "side": "0002.png"}
    one = np.asarray(Image.open(runs / "front" / "images" / "0002.png"))
    rgb = assert_picture(runs / "out" / "images" / "0002.png")
    assert rgb.shape[0] > one.shape[0] + 400  # the side camera's panel (424 px high) below
    below = rgb[one.shape[0] + 40:one.shape[0] + 440, 40:600]
    assert len(np.unique(below.reshape(-1, 3), axis=0)) > 50  # a depth image there, not a blank
    from dpom_warp.render import VIEW_INKS  # each camera's field of view outlined on the map in its colour

    alone = np.asarray(Image.open(runs / "front" / "images" / "0002.png").convert("RGB"))
    for ink in VIEW_INKS[:2]:  # (a rig of one draws none: its grey is its view)
        assert (rgb[:one.shape[0]] == ink).all(axis=2).sum() > 100 and not (alone == ink).all(axis=2).any()
    assert main(["track", str(runs / "out"), "--set", "tracking.max_gap=2", "--set",
                 f"output.rerun={runs / 'rig.rrd'}"]) == 0  # tracks made again, and a Rerun log of the rig
    from rerun.chunk import RrdReader

    rows = {}
    for chunk in RrdReader(str(runs / "rig.rrd")).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/world/cameras/front/depth"] == rows["/world/cameras/side/depth"] == 6
    # each camera's boxes, as it sees the detections (those in its view): with the frame and with its tracks
    assert rows["/world/cameras/front/depth/detections"] == rows["/world/cameras/side/depth/detections"] == 6
    from dpom_warp.config import parse_config
    from dpom_warp.geometry import build_geometry

    cfg = parse_config(summary["config"])
    dets = detections(runs / "out")
    for c, (name, m) in enumerate(cfg.cameras):
        g = build_geometry(m.camera, cfg.grid, cfg.obj)
        chunk = next(x for x in RrdReader(str(runs / "rig.rrd")).stream()
                     if x.entity_path == f"/world/cameras/{name}/depth/detections").to_record_batch().to_pydict()
        for frame, centres in zip(chunk["frame"], chunk["Boxes2D:centers"]):
            ks = [int(np.argmin(np.hypot(*(g.locations[:, :2] - xy).T))) for xy in dets[f"{frame:04d}.png"]]
            want = sorted(((g.rect[k][0] + g.rect[k][2]) / 2, (g.rect[k][1] + g.rect[k][3]) / 2)
                          for k in ks if g.rect_area[k] > 0)
            assert sorted(tuple(x) for x in centres) == want, (name, frame)
    assert (runs / "out" / "tracks.csv").read_text().count("\n") > 6


def test_a_camera_whose_frames_run_out_early(runs, tmp_path, capsys):
    """The side camera's last two frames missing: a warning naming the camera, those frames'
    records say it had none, and they are inferred from the front camera alone: their maps
    are the front camera's own run's, bit for bit."""
    scene = tmp_path / "scene"
    shutil.copytree(runs / "scene", scene)
    for name in ("0004.png", "0005.png"):
        (scene / "side" / "frames" / name).unlink()
    rig = rig_config(tmp_path)
    rig.pop("synthetic")
    assert main(["run", write(tmp_path / "rig.yaml", rig), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "warning: cameras[1] (side): no frame for 2 of the rig's 6 frames (first 0004.png)" in printed
    assert re.search(r"^cameras, median ms a frame \(reading \+ lists \+ its pixels in the mean field\): "
                     r"front \d+ \+ \d+ \+ \d+ \(6 frames\); side \d+ \+ \d+ \+ \d+ \(4 frames, 2 missing\)$",
                     printed, re.M)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert {k: summary["cameras"]["side"][k] for k in ("frames", "missing")} == {"frames": 4,
                                                                                "missing": ["0004.png", "0005.png"]}
    for stem in ("0004", "0005"):
        record = json.loads((tmp_path / "out" / "frames" / f"{stem}.json").read_text())
        assert record["cameras"]["side"] is None
        assert list(record["stats"]["lists_s_cameras"]) == ["front"]  # the engine time of the camera that ran
        np.testing.assert_array_equal(np.load(tmp_path / "out" / "maps" / f"{stem}.npy"),
                                      np.load(runs / "front" / "maps" / f"{stem}.npy"))
    np.testing.assert_array_equal(np.load(tmp_path / "out" / "maps" / "0003.npy"),
                                  np.load(runs / "out" / "maps" / "0003.npy"))


def test_a_rig_of_one_is_the_single_camera_config(runs, tmp_path):
    """`cameras:` with one camera gives the detections and maps of the same camera given as a
    single input and camera."""
    rig = rig_config(runs, ("front",))
    single = {k: v for k, v in rig.items() if k not in ("cameras", "synthetic")}
    single.update(input=rig["cameras"][0]["input"], camera=rig["cameras"][0]["camera"],
                  output={"dir": str(tmp_path / "single")})
    assert main(["run", write(tmp_path / "single.yaml", single), "--no-progress"]) == 0
    assert (tmp_path / "single" / "detections.csv").read_bytes() == (runs / "front" / "detections.csv").read_bytes()
    for stem in ("0000", "0005"):
        assert (tmp_path / "single" / "maps" / f"{stem}.npy").read_bytes() == (
            runs / "front" / "maps" / f"{stem}.npy").read_bytes()


def test_workers_take_rig_frames_as_units(runs, tmp_path):
    """--workers 2: the rig's frames inferred by two processes give the one-process run's bytes."""
    rig = rig_config(runs, output={"dir": str(tmp_path / "two")})
    rig.pop("synthetic")
    assert main(["run", write(tmp_path / "rig.yaml", rig), "--no-progress", "--workers", "2"]) == 0
    for name in ("detections.csv", "tracks.csv", "maps/0003.npy", "images/0003.png"):
        assert (tmp_path / "two" / name).read_bytes() == (runs / "out" / name).read_bytes(), name


def test_the_api_takes_one_frame_a_camera(runs):
    """Detector.from_config(rig).detect: a list in the config's order or a dict by name gives
    detections.csv's rows; a camera given None is inferred from the others (the front camera's
    own map); a list of the wrong length or an unknown name is a one-line error."""
    from dpom_warp import Detector
    from dpom_warp.io import InputError, read_depth

    rig = rig_config(runs)
    rig.pop("synthetic")
    det = Detector.from_config(rig)
    frames = [read_depth(runs / "scene" / n / "frames" / "0003.png", 0.001, (120, 160)) for n in ("front", "side")]
    got = det.detect(frames)
    want = [row for row in csv.reader(open(runs / "out" / "detections.csv")) if row[0] == "0003.png"]
    assert [f"{d.x:.4f},{d.y:.4f},{d.rho:.6f}" for d in got.detections] == [f"{r[1]},{r[2]},{r[4]}" for r in want]
    by_name = det.detect({"side": frames[1], "front": frames[0]})
    np.testing.assert_array_equal(by_name.rho_star, got.rho_star)
    front_only = det.detect_batch([[frames[0], None]])[0]
    np.testing.assert_array_equal(front_only.rho_star.astype(np.float32), np.load(runs / "front" / "maps" / "0003.npy")
                                  .reshape(front_only.rho_star.shape))
    with pytest.raises(InputError, match=r"expected a list of 2 frames, one a camera of the rig \(front, side\)"):
        det.detect([frames[0]])
    with pytest.raises(InputError, match=r"expected the rig's cameras \['front', 'side'\], found 'back'"):
        det.detect({"back": frames[0]})


def test_calibrate_places_the_cameras_from_their_frames(runs, tmp_path):
    """No pose given: `dpom-warp calibrate` recovers each camera's pose from its floor fit and the
    people both cameras see walking (heights within 0.03 m, positions within 0.05 m, rotations
    within 1 degree of the rendered truth), writes a config that runs as it is (its paths made
    relative to where it is written) and scores within 0.01 of the given-pose run."""
    import dataclasses

    from dpom_warp.calibrate import pose_angles
    from dpom_warp.geometry import pose_from_angles
    from dpom_warp.loading import load_config

    rig = rig_config(runs)
    rig.pop("synthetic")
    for item in rig["cameras"]:
        item["camera"].pop("extrinsics")  # auto: nothing measured
    rig["output"] = {"dir": str(tmp_path / "calibrated_run")}
    (tmp_path / "sub").mkdir()
    assert main(["calibrate", write(tmp_path / "auto.yaml", rig), "--output", str(tmp_path / "sub" / "cal.yaml")]) == 0
    cfg = load_config(tmp_path / "sub" / "cal.yaml")
    for (name, m) in cfg.cameras:
        p = POSES[name]
        truth = pose_from_angles(p["height"], p["pitch_deg"], 0.0, p.get("yaw_deg", 0.0), p.get("x", 0.0), p.get("y", 0.0))
        got = m.camera.T_world_from_camera
        assert abs(got[2, 3] - truth[2, 3]) < 0.03, name
        assert np.linalg.norm(got[:2, 3] - truth[:2, 3]) < 0.05, (name, got[:3, 3])
        turn = np.rad2deg(np.arccos(np.clip((np.trace(got[:3, :3].T @ truth[:3, :3]) - 1) / 2, -1, 1)))
        assert turn < 1.0, (name, turn, pose_angles(got))
        assert not m.pose_auto and dataclasses.is_dataclass(m.camera)
    assert main(["run", str(tmp_path / "sub" / "cal.yaml"), "--no-progress"]) == 0
    moda = [json.loads((d / "summary.json").read_text())["scores"]["moda"] for d in (tmp_path / "calibrated_run", runs / "out")]
    assert abs(moda[0] - moda[1]) <= 0.01


def test_calibrate_refuses_a_camera_that_shares_too_little(runs, tmp_path, capsys):
    """The side camera given only its empty-room frames: no person to match and too little of its
    scene in common with the front camera's: a one-line error naming it, nothing written."""
    rig = rig_config(runs)
    rig.pop("synthetic")
    for item in rig["cameras"]:
        item["camera"].pop("extrinsics")
    rig["cameras"][1]["input"]["frames"] = rig["cameras"][1]["input"]["background"]
    out = tmp_path / "cal.yaml"
    assert main(["calibrate", write(tmp_path / "auto.yaml", rig), "--output", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dpom-warp: error: cameras[1] (side): calibrate: shares too little with the cameras before "
                          "it: 0 people matched across cameras (expected at least 8), and its static scene alone")
    assert err.count("\n") == 1 and not out.exists()


def test_cameras_of_other_sizes_make_one_rig_and_a_wrong_size_is_named(tmp_path, capsys):
    """A rig's cameras need not share a resolution: the side camera at 128 x 96 beside the front
    one's 160 x 120 runs (the run, and the API given one frame of each size, a camera missing in
    a batch); the same frames given to a config that says the side camera is 160 x 120 are a
    one-line error naming the camera, the file and the keys, and nothing is written."""
    from dpom_warp import Detector

    rig = rig_config(tmp_path)
    rig["cameras"][1]["camera"].update({"width": 128, "height": 96,
                                        "intrinsics": {"fx": 92.0, "fy": 92.0, "cx": 63.5, "cy": 47.5}})
    assert main(["run", write(tmp_path / "rig.yaml", rig), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["scores"]["moda"] > 0.9 and summary["cameras"]["side"]["frames"] == 6
    det = Detector.from_config({k: v for k, v in rig.items() if k != "synthetic"})
    d0, d1 = (np.asarray(Image.open(tmp_path / "scene" / n / "frames" / "0000.png")) for n in ("front", "side"))
    assert d0.shape == (120, 160) and d1.shape == (96, 128)
    both, alone = det.detect_batch([[d0, d1], [d0, None]])
    assert sorted((round(d.x, 4), round(d.y, 4)) for d in both.detections) == sorted(
        (float(r["x"]), float(r["y"])) for r in csv.DictReader(open(tmp_path / "out" / "detections.csv"))
        if r["frame"] == "0000.png")
    assert alone.detections
    wrong = rig_config(tmp_path, out="wrong")
    wrong.pop("synthetic")
    capsys.readouterr()
    assert main(["run", write(tmp_path / "wrong.yaml", wrong), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dpom-warp: error: cameras[1] (side): {tmp_path}/scene/side/frames/0000.png: expected 160x120 "
                   f"pixels (camera.width x camera.height), found 128x96 (none of the 6 frames is usable)"]
    assert not (tmp_path / "wrong").exists()


def test_a_bad_frame_of_the_first_camera_skips_the_rig_frame(runs, tmp_path):
    """The front camera's frame 0002 unreadable: the rig frame it names is skipped with the
    file's reason (summary.json's skipped); the side camera's bad frame 0003 leaves the side
    camera out of that rig frame only, inferred from the front camera (its own run's map)."""
    scene = tmp_path / "scene"
    shutil.copytree(runs / "scene", scene)
    (scene / "front" / "frames" / "0002.png").write_bytes(b"not a png")
    (scene / "side" / "frames" / "0003.png").write_bytes(b"not a png")
    rig = rig_config(tmp_path)
    rig.pop("synthetic")
    assert main(["run", write(tmp_path / "rig.yaml", rig), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [s["frame"] for s in summary["skipped"]] == ["0002.png"]
    assert summary["skipped"][0]["reason"].startswith("cameras[0] (front): ") and "0002.png" in summary["skipped"][0]["reason"]
    assert summary["cameras"]["side"]["missing"] == ["0003.png"] and summary["frames"] == 5
    np.testing.assert_array_equal(np.load(tmp_path / "out" / "maps" / "0003.npy"), np.load(runs / "front" / "maps" / "0003.npy"))


def test_the_api_warns_of_each_cameras_units_on_its_own(runs):
    """A rig frame whose side camera comes in millimetres as floats: one warning naming that
    camera and the frame; the next such frame does not warn again, though the front camera's
    right frames come between (each camera's units are judged on their own)."""
    import warnings

    from dpom_warp import Detector
    from dpom_warp.io import read_depth

    rig = rig_config(runs)
    rig.pop("synthetic")
    det = Detector.from_config(rig)
    front, side = (read_depth(runs / "scene" / n / "frames" / "0001.png", 0.001, (120, 160)) for n in ("front", "side"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        det.detect_batch([[front, side * 1000], [front, side * 1000]])
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith("depth (camera side, frame 0): a float array is read as metres")

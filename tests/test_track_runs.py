"""A run's track files: tracks.csv and track_table.csv as written and read back, a rendered
run's tracks, pictures and scores, `dpom-warp track` tracking a finished run again without
inferring (other methods, input.fps, a Rerun recording), a voxel run's 3D tracks, and a
rendered run's tracks at their heads nearer the truth than at the cells."""

import csv
import json

import numpy as np
import pytest

from dpom_warp.track_files import TABLE_HEADER, TRACKS_HEADER, read_tracks_csv, tracks_csv
from paths import CONFIGS

from test_tracking import maps_of, solve, walk


def test_track_files(tmp_path):
    a = walk(0.5, 0.5, 0.1, 0.0, 4)
    tracks = solve(maps_of([a], 4))
    names = [f"{i:04d}.png" for i in range(4)]
    text = tracks_csv(tracks, names)
    assert text.splitlines()[0] == TRACKS_HEADER and text.startswith("frame,track,x,y,z,rho")
    assert text.splitlines()[1] == "0000.png,1,0.5000,0.5000,0.0000,0.980000,0"
    (tmp_path / "tracks.csv").write_text(text)
    rows = read_tracks_csv(tmp_path / "tracks.csv")
    assert list(rows) == names and rows["0003.png"][0][:3] == (1, 0.8, 0.5)
    from dpom_warp.track_files import track_table

    table = track_table(tracks, names, 10.0).splitlines()
    assert table[0] == TABLE_HEADER
    assert table[1] == "1,0000.png,0003.png,4,0,0.300,1.000"  # 0.3 m in 0.3 s


@pytest.fixture(scope="module")
def tracked_run(tmp_path_factory):
    """A small rendered sequence (8 frames, 3 people) run once with tracks and pictures."""
    from dpom_warp.cli import main
    from test_cli import small_config

    tmp = tmp_path_factory.mktemp("tracked")
    path = small_config(tmp, frames=8)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "run")]) == 0
    return tmp / "run", path


def test_a_run_writes_tracks_pictures_and_scores(tracked_run):
    run, _ = tracked_run
    lines = (run / "tracks.csv").read_text().splitlines()
    assert lines[0] == TRACKS_HEADER
    names = {line.split(",")[0] for line in (run / "detections.csv").read_text().splitlines()[1:]}
    rows = [line.split(",") for line in lines[1:]]
    assert rows and {r[0] for r in rows} <= {f"{i:04d}.png" for i in range(8)} and names
    assert (run / "track_table.csv").read_text().startswith(TABLE_HEADER)
    summary = json.loads((run / "summary.json").read_text())
    t = summary["tracking"]
    assert t["method"] == "ksp" and t["tracks"] == len({r[1] for r in rows}) and t["time_s"] > 0
    assert len(list((run / "images").glob("*.png"))) == 8
    ev = json.loads((run / "eval.json").read_text())[0]["tracking"]
    s = ev["tracks"]["ignore_hidden"]["0.5"]
    # the scores against their definitions, from the counts beside them (CLEAR MOT, IDF1)
    assert s["num_objects"] > 0 and s["num_misses"] + s["num_false_positives"] + s["num_switches"] >= 0
    assert s["mota"] == pytest.approx(
        1 - (s["num_misses"] + s["num_false_positives"] + s["num_switches"]) / s["num_objects"], abs=1e-9)
    assert s["recall"] == pytest.approx(1 - s["num_misses"] / s["num_objects"], abs=1e-9)
    assert s["idf1"] == pytest.approx(2 * s["idp"] * s["idr"] / (s["idp"] + s["idr"]), abs=1e-9)
    assert 0.5 < s["mota"] <= 1 and 0.5 < s["idf1"] <= 1 and 0 < s["hota"] <= 1
    assert "naive" in ev and set(ev["tracks"]["penalise_hidden"]) == {"0.5", "1"}


def test_track_command_retracks_without_inferring(tracked_run, tmp_path, capsys):
    import shutil

    from dpom_warp.cli import main

    run = tmp_path / "run"
    shutil.copytree(tracked_run[0], run)
    maps_before = {p.name: p.read_bytes() for p in (run / "maps").iterdir()}
    made = (run / "run.json").read_bytes()
    config_made = json.loads((run / "summary.json").read_text())["config"]
    assert main(["track", str(run), "--set", "tracking.method=online", "--set", "tracking.delay=3"]) == 0
    summary = json.loads((run / "summary.json").read_text())
    assert summary["tracking"]["method"] == "online" and summary["tracking"]["delay_frames"] == 3
    settings = summary["tracking"]["settings"]  # what this track used; the run's config as made
    assert settings["set"] == ["tracking.method=online", "tracking.delay=3"]
    assert settings["tracking"]["method"] == "online" and settings["tracking"]["delay"] == 3
    assert summary["config"] == config_made and (run / "run.json").read_bytes() == made
    assert {p.name: p.read_bytes() for p in (run / "maps").iterdir()} == maps_before
    assert main(["track", str(run)]) == 0  # a plain track: as the run did (ksp), not the last override
    assert json.loads((run / "summary.json").read_text())["tracking"]["method"] == "ksp"
    assert (run / "tracks.csv").read_bytes() == (tracked_run[0] / "tracks.csv").read_bytes()
    assert main(["track", str(run), "--set", "tracking.method=ksp"]) == 0
    assert (run / "tracks.csv").read_bytes() == (tracked_run[0] / "tracks.csv").read_bytes()
    for p in (tracked_run[0] / "images").iterdir():  # the pictures are drawn again, the same
        assert (run / "images" / p.name).read_bytes() == p.read_bytes()
    capsys.readouterr()
    assert main(["track", str(run), "--set", "tracking.method=off"]) == 0
    assert not (run / "tracks.csv").exists() and not (run / "track_table.csv").exists()
    assert capsys.readouterr().out.strip().endswith(  # says why, and how to track anyway
        "no tracks in " + str(run) + ": tracking.method: off (--set tracking.method=ksp|online tracks any run)")
    off = json.loads((run / "summary.json").read_text())["tracking"]
    assert (off["method"], off["why"], off["settings"]["set"]) == ("off", "tracking.method: off", ["tracking.method=off"])
    assert (run / "run.json").read_bytes() == made
    # input.fps (README: `track --set input.fps=...`): at 100 frames/s a track may move max_speed / 100 +
    # jitter = 0.22 m between consecutive frames, where at the run's 5 (0.6 m) the tracks step
    # farther (the rendered people walk 0.3 m a frame); the reach is the cells' (the heads it
    # places them at move a track by up to a cell's width more)

    def longest_step(folder):
        rows = [r.split(",") for r in (folder / "tracks.csv").read_text().splitlines()[1:]]
        by = {}
        for r in rows:
            by.setdefault(r[1], []).append((int(r[0][:4]), float(r[2]), float(r[3])))
        return max((np.hypot(b[1] - a[1], b[2] - a[2]) for t in by.values() for a, b in zip(t, t[1:])
                    if b[0] == a[0] + 1), default=0.0)

    assert longest_step(tracked_run[0]) > 0.22 + 1e-9
    assert main(["track", str(run), "--set", "input.fps=100", "--set", "tracking.positions=cell"]) == 0
    assert json.loads((run / "summary.json").read_text())["tracking"]["fps"] == 100
    assert longest_step(run) <= 2.0 / 100 + 0.2 + 1e-9
    assert main(["track", str(run), "--set", "model.alpha=1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("dpom-warp: error: --set model.alpha: expected a tracking.* key") and "\n" not in err
    assert main(["track", str(tmp_path / "nothing")]) == 2
    assert "not a finished dpom-warp run" in capsys.readouterr().err


def test_voxel_run_gives_3d_tracks(tmp_path):
    """Drones: the same files, with z."""
    import yaml

    from dpom_warp.cli import main

    cfg = yaml.safe_load(open(CONFIGS / "demo_drones.yaml"))
    cache = tmp_path / "scene"
    cfg.update(device="cpu")
    cfg["input"].update(frames=f"{cache}/frames/*.png", background=f"{cache}/background/*.png")
    cfg["camera"].update(width=128, height=106, intrinsics={"fx": 91.25, "fy": 91.25, "cx": 63.5, "cy": 52.5})
    cfg["grid"].update(x=[-2.0, 2.0, 0.2], y=[1.5, 5.5, 0.2], z=[0.4, 2.4, 0.2])
    cfg["evaluation"].update(ground_truth=f"{cache}/ground_truth.json", plots=False)
    cfg["output"].update(dir=str(tmp_path / "out"), images=False)
    cfg["synthetic"].update(cache=str(cache), frames=6, background_frames=3, people=2, seed=4)
    path = tmp_path / "drones.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--no-progress"]) == 0
    rows = read_tracks_csv(tmp_path / "out" / "tracks.csv")
    zs = [r[3] for rs in rows.values() for r in rs]
    assert zs and all(0.4 <= z <= 2.4 for z in zs) and len(set(zs)) > 1


def test_rerun_recording_holds_every_frame(tracked_run, tmp_path):
    """output.rerun: a .rrd with the depth, boxes, map and tracks of every frame (read back)."""
    import shutil

    from rerun.chunk import RrdReader

    from dpom_warp.cli import main

    run = tmp_path / "run"
    shutil.copytree(tracked_run[0], run)
    rrd = tmp_path / "view" / "run.rrd"
    assert main(["track", str(run), "--set", f"output.rerun={rrd}"]) == 0
    rows = {}
    for chunk in RrdReader(str(rrd)).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    for entity in ("/world/camera/depth", "/world/camera/depth/detections", "/world/occupancy",
                   "/world/tracks", "/world/trails"):
        assert rows.get(entity) == 8, (entity, rows)
    assert "/world/camera" in rows


def _errors(run, truth_file) -> np.ndarray:
    truth = {f["frame"]: np.array([[o["x"], o["y"]] for o in f["objects"]]) for f in json.load(open(truth_file))}
    return np.array([np.min(np.hypot(*(truth[r["frame"]] - [float(r["x"]), float(r["y"])]).T))
                     for r in csv.DictReader(open(run / "tracks.csv")) if r["bridged"] == "0"])


def test_a_rendered_run_s_tracks_stand_nearer_the_truth_at_the_heads(tracked_run):
    """The small rendered run (0.2 m cells: a cell's centre up to 0.14 m from anyone in it): its
    tracks, at their heads, against the rendered people, then the same maps tracked again at the
    cells' centres (`dpom-warp track --set tracking.positions=cell`): the heads' mean error under
    two thirds of the cells', and summary.json counts the track-frames at a head."""
    from dpom_warp.cli import main

    run, config = tracked_run
    truth = config.parent / "scene" / "ground_truth.json"
    heads = _errors(run, truth)
    positions = json.loads((run / "summary.json").read_text())["tracking"]["positions"]
    assert positions["head"] > positions["cell"] and positions["head"] + positions["cell"] == len(heads)
    try:
        assert main(["track", str(run), "--set", "tracking.positions=cell", "--set", "output.images=false"]) == 0
        cells = _errors(run, truth)
        assert "positions" not in json.loads((run / "summary.json").read_text())["tracking"]
    finally:  # the module's run as it was for the other tests
        assert main(["track", str(run)]) == 0
    assert len(cells) == len(heads)
    assert heads.mean() < 2 / 3 * cells.mean()

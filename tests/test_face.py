"""The face of the package: the Python API against the CLI, the config schema, the config
errors users hit first, --version, help, unconverged frames, pictures and eval --compare."""

import csv
import json
import re

import jsonschema
import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp import Detector, __version__
from dpom_warp.cli import main
from dpom_warp.config import ConfigError, json_schema, parse_config
from dpom_warp.loading import load_config
from dpom_warp.io import InputError, read_depth

from test_cli import small_config

from paths import ROOT
from pictures import assert_picture
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))
SCHEMA = ROOT / "configs" / "dpom-warp.schema.json"


def csv_rows(path):
    return [r for r in csv.reader(open(path))][1:]


def api_rows(name, result):
    return [[name, f"{d.x:.4f}", f"{d.y:.4f}", f"{d.z:.4f}", f"{d.rho:.6f}", *map(str, d.box)]
            for d in result.detections]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """The people demo through `dpom-warp run` (its scene rendered into .cache/demo_people,
    shared with the quick start)."""
    out = tmp_path_factory.mktemp("demo") / "run"
    assert main(["run", str(ROOT / "configs" / "demo_people.yaml"), "--no-progress", "--output", str(out),
                 "--set", "output.images=false"]) == 0
    return out


def test_api_gives_the_cli_detections_on_the_demo(demo_run):
    det = Detector.from_config(ROOT / "configs" / "demo_people.yaml")
    cfg = det.config
    summary = json.loads((demo_run / "summary.json").read_text())
    assert summary["inference"]["stride"] == det.engine.resolution.stride > 1  # the fast path
    assert cfg.model.sparse_epsilon > 0
    frames = sorted((ROOT / ".cache" / "demo_people" / "frames").glob("*.png"))
    assert len(frames) == summary["frames"] == 20
    rows, iterations, results = [], [], []
    for f in frames:
        depth = np.asarray(Image.open(f))  # uint16 in the config's depth units
        result = det.detect(depth)
        rows += api_rows(f.name, result)
        iterations.append(result.iterations)
        results.append(result)
        assert result.rho_star.shape == cfg.grid.shape and result.timings["total_s"] > 0
    assert rows == csv_rows(demo_run / "detections.csv")
    assert iterations == [p["iterations"] for p in summary["per_frame"]]  # the same work per frame
    from dpom_warp.track_files import tracks_csv

    tracks, report = det.track(results)  # the same tracks as tracks.csv
    assert report["method"] == "ksp" and len(tracks) >= 5
    assert tracks_csv(tracks, [f.name for f in frames]) == (demo_run / "tracks.csv").read_text()
    fps = cfg.inputs.fps  # a recording's timestamps one frame apart: the same tracks, at their rate
    stamped, report = det.track(results, times=[7.0 + k / fps for k in range(len(results))])
    assert tracks_csv(stamped, [f.name for f in frames]) == (demo_run / "tracks.csv").read_text()
    assert report["fps"] == pytest.approx(fps) and report["frames_without_map"] == 0
    with pytest.raises(ValueError, match="one timestamp per result"):
        det.track(results, times=[0.0])
    # as frames come: each push commits the frame tracking.delay behind, with its final identity
    from dpom_warp.track_files import per_frame

    times, delay = [7.0 + k / fps for k in range(len(results))], cfg.tracking.delay
    online, shown = det.online_tracker(fps), []
    for k, r in enumerate(results):
        got = online.push(r, times[k])
        assert [f for f, _ in got] == ([k - delay] if k >= delay else [])
        shown += got
    shown += online.finish()
    want, _ = det.track(results, method="online", times=times)
    assert online.tracks and tracks_csv(online.tracks, [f.name for f in frames]) == \
        tracks_csv(want, [f.name for f in frames])
    assert [f for f, _ in shown] == list(range(len(results)))
    assert [[(i, p.tolist(), b) for i, p, b in rows] for _, rows in shown] == \
        [[(i, p.tolist(), b) for i, p, b in rows] for rows in per_frame(want, len(results))]
    with pytest.raises(RuntimeError, match="after finish"):
        online.push(results[0])


def test_api_float_metres_and_batches_match_single_frames(tmp_path):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    frames = sorted((tmp_path / "scene" / "frames").glob("*.png"))
    metres = [read_depth(f, 0.001) for f in frames]
    single = Detector.from_config(path)
    batched = Detector.from_config(path, overrides={"engine.batch": 2})
    one = [single.detect(np.asarray(Image.open(f))) for f in frames]
    floats = [single.detect(m) for m in metres]
    many = batched.detect_batch(np.stack(metres))
    expected = csv_rows(tmp_path / "out" / "detections.csv")
    for results in (one, floats, many):
        assert [r for f, res in zip(frames, results) for r in api_rows(f.name, res)] == expected
    np.testing.assert_array_equal(many[1].rho_star, one[1].rho_star)


def test_api_warns_once_of_frames_in_the_wrong_units(tmp_path):
    """A frame in millimetres passed as floats (or integers at a wrong input.depth_scale) puts
    every reading out of reach: the Detector says so once, as a run does, and not otherwise."""
    import warnings

    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    raw = np.asarray(Image.open(sorted((tmp_path / "scene" / "frames").glob("*.png"))[0]))
    det = Detector.from_config(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the right units: no word
        det.detect(raw)
        det.detect(raw * np.float32(0.001))
    det = Detector.from_config(path)
    with pytest.warns(UserWarning, match=r"^depth \(frame 0\): a float array is read as metres, and its "
                      r"readings' median is \d+(\.\d+)? m: expected 0.15 to 30 m"):
        assert det.detect(raw.astype(np.float32)).detections == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once
        det.detect(raw.astype(np.float32))
    det = Detector.from_config(path, overrides={"input.depth_scale": 1.0})
    with pytest.warns(UserWarning, match=r"median is \d+(\.\d+)? m, at input.depth_scale 1 m per unit"):
        det.detect(raw)


def test_api_checks_every_frame_s_units_and_names_the_frame(tmp_path):
    """Not only the first frame: a frame in the wrong units after right ones is named by its
    place among the frames the Detector was given (across detect and detect_batch calls);
    a run of wrong frames warns at its first, and again after right frames came between."""
    import warnings

    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    raw = np.asarray(Image.open(sorted((tmp_path / "scene" / "frames").glob("*.png"))[0]))
    wrong, right = raw.astype(np.float32), raw * np.float32(0.001)  # millimetres as floats; metres
    det = Detector.from_config(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        det.detect(right)
        det.detect_batch([raw, right])  # frames 0, 1, 2: right
    with pytest.warns(UserWarning, match=r"^depth \(frame 4\): a float array is read as metres") as got:
        det.detect_batch([right, wrong, wrong])  # frames 3, 4, 5: the warning at 4, once
    assert len(got) == 1
    with pytest.warns(UserWarning, match=r"^depth \(frame 7\): ") as got:
        det.detect(right)  # 6
        det.detect(wrong)  # 7: wrong again after a right frame
    assert len(got) == 1 and det.frames_given == 8
    with pytest.raises(InputError, match=r"^depth \(frame 8\): expected an array of shape"):
        det.detect(raw[:, 1:])


def test_api_errors(tmp_path):
    path = small_config(tmp_path)
    det = Detector.from_config(path)
    with pytest.raises(InputError, match=r"expected an array of shape \(106, 128\).*found \(106, 127\)"):
        det.detect(np.zeros((106, 127), np.uint16))
    with pytest.raises(InputError, match="expected metres >= 0"):
        det.detect(np.full((106, 128), -1.0))
    raw = yaml.safe_load(path.read_text())
    raw["modle"] = {}
    with pytest.raises(ConfigError, match=r"^config: modle: unknown key \(did you mean model\?"):
        Detector.from_config(raw)


def test_schema_file_is_current_and_every_config_validates():
    schema = json.loads(SCHEMA.read_text())
    assert schema == json_schema(), "configs/dpom-warp.schema.json is stale: run dpom-warp schema --output it"
    assert len(CONFIGS) >= 3
    for path in CONFIGS:
        jsonschema.validate(yaml.safe_load(path.read_text()), schema)
        assert path.read_text().startswith("# yaml-language-server: $schema=dpom-warp.schema.json")


@pytest.mark.parametrize("damage", [
    lambda c: c.update(gird=c.pop("grid")),
    lambda c: c["model"].update(prior=1.5),
    lambda c: c["model"].update(damping="fast"),
    lambda c: c["camera"].update(extrinsics="guess"),
    lambda c: c["grid"].update(x=[0, 1]),
    lambda c: c["output"].update(images="yes"),
])
def test_schema_rejects_a_broken_config(damage):
    cfg = yaml.safe_load((ROOT / "configs" / "demo_people.yaml").read_text())
    damage(cfg)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(cfg, json.loads(SCHEMA.read_text()))


def test_schema_command(tmp_path, capsys):
    assert main(["schema"]) == 0
    assert json.loads(capsys.readouterr().out) == json_schema()
    assert main(["schema", "--output", str(tmp_path / "s.json")]) == 0
    assert json.loads((tmp_path / "s.json").read_text()) == json_schema()


def test_misspelt_section_is_reported_as_unknown(tmp_path, capsys):
    cfg = yaml.safe_load(small_config(tmp_path).read_text())
    cfg["gird"] = cfg.pop("grid")
    (tmp_path / "typo.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", str(tmp_path / "typo.yaml"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "typo.yaml: gird: unknown key (did you mean grid? expected one of device, input" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "out").exists()


def test_relative_paths_are_relative_to_the_config_folder(tmp_path, capsys, monkeypatch):
    small_config(tmp_path)  # renders nothing yet; the config below renders into its folder
    cfg = yaml.safe_load((tmp_path / "config.yaml").read_text())
    folder = tmp_path / "configs"
    folder.mkdir()
    cfg["synthetic"]["cache"] = "../scene"
    cfg["input"].update(frames="../scene/frames/*.png", background="../scene/background/*.png")
    cfg["evaluation"]["ground_truth"] = "../scene/ground_truth.json"
    cfg["output"]["dir"] = "../out"
    (folder / "run.yaml").write_text(yaml.safe_dump(cfg))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    loaded = load_config(folder / "run.yaml", ["output.images=false"])
    assert loaded.inputs.frames == str(tmp_path / "scene" / "frames" / "*.png")
    assert loaded.output.dir == str(tmp_path / "out")
    assert main(["run", str(folder / "run.yaml"), "--no-progress"]) == 0
    assert (tmp_path / "out" / "detections.csv").read_text().startswith("frame,x,y,z,rho")
    assert (tmp_path / "scene" / "frames").is_dir()
    capsys.readouterr()
    # a --set path is relative to the current folder, and a failed glob says where it looked
    assert main(["run", str(folder / "run.yaml"), "--no-progress", "--overwrite",
                 "--set", "input.frames=frames/*.png"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"input.frames: no files match 'frames/*.png' (looked for {elsewhere}/frames/*.png;" in err
    assert "relative to its folder" in err and len(err.splitlines()) == 1


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"dpom-warp {__version__}"
    with pytest.raises(SystemExit):
        main(["--help"])
    top = capsys.readouterr().out
    assert "\n  dpom-warp run CONFIG..." in top and "\n  dpom-warp eval RUN_DIR" in top  # one per line
    with pytest.raises(SystemExit):
        main(["eval", "--help"])
    assert "(default: 0.05)" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["fit-ground", "--help"])
    assert "(default: 45.0)" in capsys.readouterr().out


def test_unconverged_frames_are_counted_and_named(tmp_path, capsys, demo_run):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress", "--set", "model.max_iterations=3",
                 "--set", "model.check_every=1"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["unconverged"] == [p["frame"] for p in summary["per_frame"]] and summary["unconverged"]
    out = capsys.readouterr().out
    assert f"{len(summary['unconverged'])} frame(s) stopped at model.max_iterations (3) without converging" in out
    # the demo: 19 of its 20 frames converge in 55 to 85 iterations; its first frame keeps
    # moving (two cells trading a person) and is named, not hidden
    demo = json.loads((demo_run / "summary.json").read_text())
    assert demo["unconverged"] == [p["frame"] for p in demo["per_frame"] if not p["converged"]]
    assert len(demo["unconverged"]) < len(demo["per_frame"]) / 4


def test_setup_steps_are_announced(tmp_path, capsys):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("rendering the synthetic scene (3 frames)")
    assert any(line.startswith("setting up the engine") for line in out)


def test_picture_legend_and_labels():
    from dpom_warp.detect import Detected
    from dpom_warp.geometry import Grid
    from dpom_warp.render import frame_picture, place_label
    from PIL import ImageDraw

    grid = Grid(x=(-1, 1, 0.1), y=(1, 3, 0.1))
    rho = np.zeros(grid.shape)
    dets = [Detected(0, 0.0, 2.0, 0.0, 0.9, (10, 10, 40, 80)), Detected(1, 0.1, 2.0, 0.0, 0.8, (12, 11, 42, 80))]
    depth = np.full((106, 128), 2.0, np.float32)

    def green_legend(png):
        im = np.asarray(Image.open(__import__("io").BytesIO(png)).convert("RGB"))
        band = im[-20:, :200].reshape(-1, 3)
        return bool(np.any((band[:, 1] > 120) & (band[:, 0] < 60) & (band[:, 2] < 60)))

    assert not green_legend(frame_picture(depth, rho, grid, dets, (0, 0)))
    assert green_legend(frame_picture(depth, rho, grid, dets, (0, 0), truth=[]))
    draw = ImageDraw.Draw(Image.new("RGB", (300, 300)))
    taken = []
    rects = [place_label(draw, "0.99", (50, 60 + i), taken, (0, 0, 300, 300)) for i in range(4)]
    for i, a in enumerate(rects):
        assert 0 <= a[1] and a[3] <= 300
        for b in rects[:i]:
            assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1]


def test_pictures_png_encoder_round_trips_and_gives_the_same_bytes_on_any_thread():
    """render.encode_png: Pillow reads back exactly the image given (odd sizes, every value);
    the same image gives the same bytes encoded alone or on threads encoding at once (runs
    that resume or share frames promise a one-process run's files byte for byte); anything
    but RGB is a clear error."""
    import io
    from concurrent.futures import ThreadPoolExecutor

    from dpom_warp.render import encode_png

    rng = np.random.default_rng(3)
    images = []
    for h, w in ((1, 1), (7, 13), (106, 129), (504, 1017)):
        rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        rgb[: h // 2] = 200  # flat rows, as the pictures have
        back = Image.open(io.BytesIO(encode_png(rgb)))
        assert back.mode == "RGB" and back.size == (w, h)
        assert np.array_equal(np.asarray(back), rgb)
        images.append(rgb)
    alone = [encode_png(rgb) for rgb in images]
    with ThreadPoolExecutor(2) as pool:
        for _ in range(10):
            assert list(pool.map(encode_png, images + images[::-1])) == alone + alone[::-1]
    with pytest.raises(ValueError, match="expected an \\(H, W, 3\\) image, found \\(4, 4, 4\\)"):
        encode_png(np.zeros((4, 4, 4), np.uint8))


def test_pictures_drawn_on_a_shared_template_are_those_drawn_from_scratch():
    """render.frame_picture copies its unchanging parts from a template drawn once per layout:
    a picture drawn after others (other depths, maps, detections, tracks, a voxel grid) is the
    one drawn on a fresh template, and the template itself is never drawn on."""
    import io

    from dpom_warp.detect import Detected
    from dpom_warp.geometry import Grid
    from dpom_warp.render import frame_picture, picture_template

    rng = np.random.default_rng(5)
    ground = Grid(x=(-2, 2, 0.1), y=(0.5, 5, 0.1))
    voxel = Grid(x=(-2, 2, 0.2), y=(0.5, 5, 0.2), mode="voxel", z=(0, 2.4, 0.2))

    def picture(k, grid):
        rho = rng.random(grid.shape) ** 8
        depth = (rng.random((106, 128)) * 5).astype(np.float32)
        dets = [Detected(i, -1 + 0.7 * i, 2 + 0.3 * i, 1.0, 0.5 + 0.1 * i, (5 + 30 * i, 10, 25 + 30 * i, 80))
                for i in range(k % 3 + 1)]
        tracks = [{"id": 3 + i, "box": d.box, "bridged": i == 1, "xyz": (d.x, d.y, d.z),
                   "trail": [(d.x + 0.05 * j, d.y, d.z) for j in range(4)]} for i, d in enumerate(dets)]
        return (depth, rho, grid, dets, (0.0, 0.0), [{"x": -1.0, "y": 2.0, "z": 1.0}] if k % 2 else None,
                f"frame {k}"), {"tracks": tracks if k % 3 else None}

    def rgb(png):
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    cases = [picture(k, voxel if k == 4 else ground) for k in range(6)]
    warm = [rgb(frame_picture(*a, **kw)) for a, kw in cases]
    for (a, kw), seen in zip(cases, warm):
        picture_template.cache_clear()
        assert np.array_equal(rgb(frame_picture(*a, **kw)), seen)
    assert warm[4].shape[1] > warm[0].shape[1]  # the voxel grid's side view


def test_eval_compare_leaves_the_runs_untouched(tmp_path, capsys):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress", "--set", "evaluation.plots=true"]) == 0
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "floor"),
                 "--set", "input.background=null"]) == 0
    before = {p: p.read_bytes() for p in [out / "eval.json", tmp_path / "floor" / "eval.json",
                                          *sorted((out / "plots").glob("*.png"))]}
    assert main(["eval", str(out), "--compare", str(tmp_path / "floor"), "--plots"]) == 0
    assert {p: p.read_bytes() for p in before} == before
    target = tmp_path / "eval_out_vs_floor"
    results = json.loads((target / "eval.json").read_text())
    assert len(results) == 2
    assert_picture(target / "plots" / "moda_ground.png", (300, 200), plot=True, curves=2)  # a curve a run
    assert f"curves in {target / 'eval.json'}" in capsys.readouterr().out


def test_readme_api_examples_run(monkeypatch, demo_run):
    """The README's two API snippets, run as written on demo frames."""
    import re

    monkeypatch.chdir(ROOT)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert len(blocks) >= 2
    frames = sorted((ROOT / ".cache" / "demo_people" / "frames").glob("*.png"))[:2]
    background = sorted((ROOT / ".cache" / "demo_people" / "background").glob("*.png"))[:3]
    first = {"print": lambda *a: None}
    exec(blocks[0], first)  # reads the demo's frames itself
    assert first["result"].detections and len(first["results"]) == 4
    assert first["tracks"] and first["online"].tracks is not None  # the four frames tracked both ways
    named = re.search(r"result\.timings  # seconds: (.*\n(?: +#.*\n)*)", blocks[0]).group(1)  # and its lines below
    # the comment names the keys (seconds, and a list a camera: *_s_cameras)
    assert set(re.findall(r"\w+_s(?:_cameras)?\b", named)) == set(first["result"].timings)
    second = {"depth_m": read_depth(frames[0], 0.001),
              "background_m": np.stack([read_depth(f, 0.001) for f in background])}
    exec(next(b for b in blocks if "Engine(" in b), second)
    assert second["res"].rho_star.shape == (second["geometry"].locations.shape[0],)


def test_readme_recording_example_runs(tmp_path, monkeypatch):
    """The README's recording snippet, as written, on a bag of rendered frames (rec.yaml and
    recording.bag in the current folder)."""
    import re

    import yaml
    from test_cli import small_config
    from test_recordings import camera_of, messages, recording_config, typestore, write_bag

    monkeypatch.setenv("DPOM_WARP_CACHE", str(tmp_path / "cache"))
    path = small_config(tmp_path, frames=3)
    assert main(["run", str(path), "--no-progress", "--set", "output.images=false"]) == 0  # renders the frames
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]
    cfg["input"]["background"], cfg["evaluation"]["ground_truth"] = None, None
    frames = sorted((tmp_path / "scene" / "frames").glob("*.png"))
    write_bag(tmp_path / "recording.bag", "ros1", messages(typestore(True), frames, "16UC1", camera_of(cfg)))
    recording_config(tmp_path, cfg, "recording.bag", name="rec.yaml")
    monkeypatch.chdir(tmp_path)
    block = next(b for b in re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
                 if "open_source" in b)
    scope = {}
    exec(block, scope)
    assert len(scope["results"]) == 3 and scope["times"] == pytest.approx([100.0, 100.1, 100.2])
    assert scope["tracks"] and scope["report"]["fps"] == pytest.approx(10.0)


def test_top_view_shows_the_camera_footprint():
    """A ceiling camera's map: the cells it sees are the map's colours, the others grey
    (render.OUT_OF_VIEW), the footprint the geometry gives, not a wedge."""
    from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
    from dpom_warp.render import OUT_OF_VIEW, frame_picture

    cam = Camera(128, 106, 91.0, 91.0, 63.5, 52.5, pose_from_angles(3.0, 90.0, 0.0, 0.0, 0.0, 4.0))
    grid = Grid(x=(-4, 4, 0.2), y=(0, 8, 0.2))
    geom = build_geometry(cam, grid, ObjectBox(0.4, 1.8))
    seen = (geom.rect_area > 0).reshape(grid.shape)  # what the run's pictures are given
    assert 0.05 < seen.mean() < 0.6  # below the camera only
    rho, depth = np.zeros(grid.shape), np.full((106, 128), 3.0, np.float32)

    def grey(png):
        im = np.asarray(Image.open(__import__("io").BytesIO(png)).convert("RGB"))
        return int(np.all(im == OUT_OF_VIEW, axis=-1).sum())

    assert grey(frame_picture(depth, rho, grid, [], cam.centre[:2])) == 0
    out = grey(frame_picture(depth, rho, grid, [], cam.centre[:2], in_view=seen))
    everything = grey(frame_picture(depth, rho, grid, [], cam.centre[:2], in_view=np.zeros(grid.shape, bool)))
    assert 0 < out < everything and out / everything == pytest.approx(1 - seen.mean(), abs=0.05)


def test_exclusion_defaults_to_on_for_ground_grids_and_off_in_voxel_mode():
    """model.exclusion unset: 10 on a ground grid (people), 0 in voxel mode (README: twice the
    drone demo's time); given, it is what was given, and the resolved config records it."""
    people = load_config(str(ROOT / "configs" / "demo_people.yaml"))
    drones = load_config(str(ROOT / "configs" / "demo_drones.yaml"))
    assert people.model.exclusion == 10.0 and people.resolved["model"]["exclusion"] == 10.0
    assert drones.model.exclusion == 0.0 and drones.resolved["model"]["exclusion"] == 0.0
    assert load_config(str(ROOT / "configs" / "demo_drones.yaml"), ["model.exclusion=3"]).model.exclusion == 3.0
    assert load_config(str(ROOT / "configs" / "demo_people.yaml"), ["model.exclusion=0"]).model.exclusion == 0.0


def test_eq13_cut_off_defaults_to_each_paths_own():
    """model.beta unset: -3.5 on the fast path, -2.5 on the exact path (engine.exact), which
    the tuning draw chose for each (README, Defaults and why); given, it is what was given
    on either path, and the resolved config records it."""
    people = str(ROOT / "configs" / "demo_people.yaml")
    fast, exact = load_config(people), load_config(people, ["engine.exact=true"])
    assert fast.model.beta == -3.5 and fast.resolved["model"]["beta"] == -3.5
    assert exact.model.beta == -2.5 and exact.resolved["model"]["beta"] == -2.5
    for path in ("false", "true"):
        given = load_config(people, [f"engine.exact={path}", "model.beta=-4"])
        assert given.model.beta == -4.0 and given.resolved["model"]["beta"] == -4.0


def test_camera_file_and_auto_pose_make_a_four_line_config(tmp_path, capsys):
    """The README's "your own camera" config on the real Kinect frame: `camera: FILE` fills
    the camera and input.depth_scale from a camera file (as fit-ground --camera takes), the
    pose defaults to auto, and the run gives the detections of the same config written out."""
    import shutil

    from paths import REAL

    shutil.copytree(REAL / "five_people", tmp_path / "five")
    short = {"input": {"frames": "five/depth_mm.png"}, "camera": "five/camera.yaml",
             "grid": {"x": [-1.5, 1.5, 0.1], "y": [1.0, 5.5, 0.1]}, "output": {"dir": "short"}}
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(short))
    jsonschema.validate(short, json.loads(SCHEMA.read_text()))  # editors take the short form too
    camera = yaml.safe_load((REAL / "five_people" / "camera.yaml").read_text())
    full = {**short, "input": {**short["input"], "depth_scale": camera.pop("depth_scale")},
            "camera": {**camera, "extrinsics": "auto"}, "output": {"dir": "full"}}
    (tmp_path / "full.yaml").write_text(yaml.safe_dump(full))
    assert load_config(tmp_path / "short.yaml").resolved == {**load_config(tmp_path / "full.yaml").resolved,
                                                            "output": load_config(tmp_path / "short.yaml").resolved["output"]}
    for name in ("short", "full"):
        assert main(["run", str(tmp_path / f"{name}.yaml"), "--no-progress", "--set", "output.images=false"]) == 0
    rows = csv_rows(tmp_path / "short" / "detections.csv")
    assert rows == csv_rows(tmp_path / "full" / "detections.csv")
    assert sum(0.8 <= float(r[2]) <= 4.5 for r in rows) == 5  # the five people of the corridor
    # a Kinect v1 is noisier than the default noise: each run says so, with the pair to set (README)
    said = [x for x in capsys.readouterr().out.splitlines() if x.startswith("warning: model.sensor_noise: ")]
    assert len(said) == 2 and all("set model.sensor_noise to it" in x for x in said)

    # the API holds the same floor fit as the run's summary
    det = Detector.from_config(tmp_path / "short.yaml")
    fit = json.loads((tmp_path / "short" / "summary.json").read_text())["ground_fit"]
    assert det.ground_fit["floor_xy"] == tuple(fit["floor_xy"]) and det.ground_fit["pitch_deg"] == fit["pitch_deg"]
    assert Detector.from_config(tmp_path / "full.yaml", {"camera.extrinsics": {"height": 1.3, "pitch_deg": 5}}
                                ).ground_fit is None
    # the section's own keys and input.depth_scale win over the file's
    cfg = load_config(tmp_path / "short.yaml", ["camera.intrinsics.fx=500", "input.depth_scale=0.002"])
    assert cfg.camera.fx == 500 and cfg.camera.fy == 525 and cfg.inputs.depth_scale == 0.002
    # a camera file that is not there, or not a camera file: one line naming it
    capsys.readouterr()
    for value, message in (("five/none.yaml", r"five/none.yaml: no such camera file \(camera.file\)$"),
                           ("short.yaml", r"camera.file: .*short.yaml: config: unknown keys camera, grid, input, output; expected keys among width,")):
        short.update(camera={"file": value}, output={"dir": "bad_out"})
        (tmp_path / "bad.yaml").write_text(yaml.safe_dump(short))
        assert main(["run", str(tmp_path / "bad.yaml")]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and re.search(message, err), err
        assert not (tmp_path / "bad_out").exists()


def test_package_defaults_are_the_demos_tuned_values():
    """A config that gives only frames, camera and grid gets the object, model, detection,
    engine and tracking settings the demo runs with ("Defaults and why"): the demo's config
    states nothing the package's defaults do not (object.width was 0.5 by default, 0.4 in
    the demo, for a user's own minimal config)."""
    demo = load_config(ROOT / "configs" / "demo_people.yaml").resolved
    raw = yaml.safe_load((ROOT / "configs" / "demo_people.yaml").read_text())
    mine = parse_config({"input": {"frames": "frames/*.png", "background": "background/*.png"},
                         "camera": raw["camera"], "grid": raw["grid"]}).resolved
    for section in ("object", "model", "detection", "engine", "tracking"):
        assert mine[section] == demo[section], section
    assert {k: v for k, v in mine["input"].items() if k not in ("frames", "background", "fps")} == \
        {k: v for k, v in demo["input"].items() if k not in ("frames", "background", "fps")}

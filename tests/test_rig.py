"""Several depth cameras on one map (issue 61): evidence fused in one mean field, not detections
fused after each camera has decided alone. The engine against the NumPy reference on random
rigs is in test_warp_vs_reference (test_a_rig_matches_the_reference)."""

import numpy as np
import pytest
import yaml

from dpom_warp import reference as ref
from dpom_warp.engine import Engine
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
from dpom_warp.model import ModelParams

from scenes import draw_slab


def two_cameras():
    """A 3 x 4 m grid; camera 0 at its near end 1.0 m up looking level along it (below the
    people's heads: a person right behind another is hidden whole), camera 1 at its side 2.5 m
    up looking across it."""
    grid = Grid(x=(-1.5, 1.5, 0.25), y=(1.5, 5.5, 0.25))
    obj = ObjectBox(0.5, 1.8, shape="plane")
    front = Camera(64, 48, 45.0, 45.0, 31.5, 23.5, pose_from_angles(1.0, 0.0))
    side = Camera(64, 48, 45.0, 45.0, 31.5, 23.5, pose_from_angles(2.5, 25.0, 0.0, 90.0, 4.0, 3.5))
    return grid, [build_geometry(cam, grid, obj) for cam in (front, side)]


def test_a_person_hidden_from_one_camera_is_found_by_the_rig():
    """Two people on the grid's axis, one 1.5 m behind the other: camera 0 sees only the front
    one (the one behind is hidden whole, so its own frame explains it away: rho* stays near the
    prior), camera 1 sees both side by side. One mean field over both cameras' pixels finds
    both; camera 0 alone finds one, and rendering the hidden person or not changes nothing for
    camera 0 (its pixels show only the front person)."""
    grid, geoms = two_cameras()
    params = ModelParams(prior=0.01, sigma_object=0.1, sparse_epsilon=0.0, max_iterations=100)
    p = geoms[0].locations
    near, far = (int(np.argmin(np.hypot(p[:, 0] - x, p[:, 1] - y))) for x, y in ((0.0, 2.5), (0.0, 4.0)))
    frames, bgs = [], []
    for g in geoms:
        floor = ref.floor_background(g, params)
        depth = floor.mu.copy()
        for k in (near, far):
            draw_slab(depth, g, k)
        frames.append(depth.astype(np.float32))
        bgs.append(floor)
    front_only = bgs[0].mu.copy()
    draw_slab(front_only, geoms[0], near)
    np.testing.assert_array_equal(frames[0], front_only.astype(np.float32))  # camera 0: the far one hidden
    rig = Engine(geoms, params, "cpu")
    for c, bg in enumerate(bgs):
        rig.set_background(bg, camera=c)
    fused = rig.infer(frames).rho_star
    alone = Engine(geoms[0], params, "cpu")
    alone.set_background(bgs[0])
    single = alone.infer(frames[0]).rho_star
    assert fused[near] > 0.9 and fused[far] > 0.9
    assert single[near] > 0.9 and single[far] < 0.05
    # nothing else is taken for a person: every cell above 0.5 lies within 0.3 m of one of the two
    away = np.min(np.hypot(p[:, None, 0] - p[[near, far], 0], p[:, None, 1] - p[[near, far], 1]), axis=1)
    assert (away[fused > 0.5] < 0.3).all()


def test_each_cameras_engine_time_on_the_cpu_and_from_a_gpus_events(monkeypatch):
    """A rig's timings name each camera's: its lists (the CPU's clock) and its pixels' launches
    in the loop (its Launcher's sum), within the engine's stages; where a GPU's timing events
    stand between the cameras (_camera_marks: stood in for here, none is lent), each camera's
    lists time is the events' elapsed time in seconds, recorded on the engine's device's stream
    before each camera and after the last, and the loop's per camera is None (one graph)."""
    grid, geoms = two_cameras()
    params = ModelParams(prior=0.01, sigma_object=0.1, max_iterations=20)
    rig = Engine(geoms, params, "cpu")
    frames = []
    for c, g in enumerate(geoms):
        bg = ref.floor_background(g, params)
        rig.set_background(bg, camera=c)
        frames.append(bg.mu.astype(np.float32))
    t = rig.infer(frames).timings
    assert len(t["lists_s_cameras"]) == len(t["iterations_s_cameras"]) == 2
    assert all(x > 0 for x in t["lists_s_cameras"] + t["iterations_s_cameras"])
    assert sum(t["lists_s_cameras"]) <= t["lists_s"] and sum(t["iterations_s_cameras"]) <= t["iterations_s"]
    recorded = []

    class Stream:
        def record_event(self, event):
            recorded.append(event)

    import warp as wp

    monkeypatch.setattr(rig, "_camera_marks", lambda: ["a", "b", "c"])
    monkeypatch.setattr(wp, "get_stream", lambda device: Stream())
    elapsed = {("a", "b"): 12.0, ("b", "c"): 30.0}  # milliseconds, as Warp gives them
    monkeypatch.setattr(wp, "get_event_elapsed_time", lambda a, b, synchronize=True: elapsed[(a, b)])
    for v in rig.views:
        v.launch.timed = False  # (a GPU's launches return at once)
    t = rig.infer(frames).timings
    assert recorded == ["a", "b", "c"] and t["lists_s_cameras"] == [0.012, 0.030]
    assert t["iterations_s_cameras"] is None


def test_a_rig_needs_one_grid_and_a_frame_per_camera():
    """The cameras of a rig see the same locations; frames come one a camera: one-line errors
    naming what was expected."""
    grid, geoms = two_cameras()
    other = build_geometry(Camera(64, 48, 45.0, 45.0, 31.5, 23.5, pose_from_angles(1.0, 0.0)),
                           Grid(x=(-1.5, 1.5, 0.5), y=(1.5, 5.5, 0.5)), ObjectBox(0.5, 1.8, shape="plane"))
    with pytest.raises(ValueError, match=r"^cameras\[1\]: expected the grid's 192 locations of cameras\[0\], "
                                         r"found 48 others$"):
        Engine([geoms[0], other], ModelParams(), "cpu")
    rig = Engine(geoms, ModelParams(), "cpu")
    with pytest.raises(ValueError, match=r"^depth: expected a list of 2 frames, one a camera of the rig, found 1 entries"):
        rig.infer([np.zeros((48, 64), np.float32)])


@pytest.mark.parametrize("ordered", [False, True])
def test_the_joint_test_of_a_rig_adds_every_cameras_pixels(ordered):
    """The joint test acts once per location: its log odds are the prior's and the exclusion's
    once plus every camera's evidence and behind cost (reference.joint_log_odds_rig, by the
    per-camera reference), on a random two-camera rig with the behind cost on, both ways of
    copying the lists out (ordered: the GPU's count, scan and fill, run here on the CPU). Each
    camera's own odds differ from the rig's (the other camera's pixels count)."""
    from scenes import random_rig

    geoms, params, frames, bg_frames = random_rig(3, 2, shape="solid")
    params = params.replace(behind_cost=2.0, behind_low=0.3, behind_step=1, exclusion=0.5)
    engine = Engine(geoms, params, "cpu")
    engine.ordered_joint_lists = ordered
    for c, frames_c in enumerate(bg_frames):
        engine.set_background_frames(frames_c, camera=c)
    star = np.asarray(engine.infer(frames).rho_star, np.float32)
    threshold = float(np.sort(star)[-6])
    engine.joint_threshold = threshold
    joint = engine.infer(frames).joint
    candidates = np.flatnonzero(star >= threshold)
    np.testing.assert_array_equal(joint.cells, candidates)
    bgs = [ref.background_from_frames(b, params) for b in bg_frames]
    for size in (1, 3, len(candidates)):
        cells = np.random.default_rng(size).choice(candidates, size=size, replace=False)
        want = ref.joint_log_odds_rig(frames, geoms, bgs, params, cells)
        np.testing.assert_allclose(joint.log_odds(cells), want, rtol=1e-6, atol=1e-6)
        alone = ref.joint_log_odds(frames[0], geoms[0], bgs[0], params, cells)
        assert np.abs(alone - want).max() > 1e-3
    with pytest.raises(ValueError, match="not among the frame's candidates"):
        joint.log_odds([int(np.flatnonzero(star < threshold)[0])])


# -- the rig in the config and its frames paired (issue 61, items 1 and 7) ----------------------
def rig_mapping(tmp_path):
    from test_rig_run import rig_config

    rig = rig_config(tmp_path)
    rig.pop("synthetic")
    return rig


def test_a_rig_config_is_each_camera_with_the_shared_sections(tmp_path):
    """Each camera is its own single-camera config (its input and camera, the shared grid,
    model, ...): the rig's inputs and camera are the first camera's; resolved has cameras and
    rig, not input and camera; --set reaches a camera by its index, and every camera's input
    with input.KEY."""
    from dpom_warp.config import apply_overrides
    from dpom_warp.loading import config_from_mapping

    cfg = config_from_mapping(rig_mapping(tmp_path))
    assert cfg.is_rig and [n for n, _ in cfg.cameras] == ["front", "side"]
    side = cfg.cameras[1][1]
    np.testing.assert_allclose(side.camera.centre, [3.5, 3.5, 1.4], atol=1e-12)
    assert cfg.camera is cfg.cameras[0][1].camera and side.grid == cfg.grid
    assert set(cfg.resolved) >= {"cameras", "rig"} and not {"input", "camera"} & set(cfg.resolved)
    assert cfg.resolved["rig"] == {"tolerance": None}
    moved = config_from_mapping(apply_overrides(rig_mapping(tmp_path), ["cameras.1.camera.extrinsics.x=3.0"]))
    assert moved.cameras[1][1].camera.centre[0] == 3.0 and moved.cameras[0][1].camera.centre[0] == 0.0
    # input.KEY on a rig is every camera's (--play sets input.play so); cameras.N.input.KEY one's
    both = config_from_mapping(apply_overrides(rig_mapping(tmp_path), ["input.fps=12", "cameras.1.input.fps=7"]))
    assert [m.inputs.fps for _, m in both.cameras] == [12, 7] and "input" not in both.resolved
    from dpom_warp.config import parse_config

    again = parse_config(cfg.resolved)  # a run's summary.json config parses back to the same rig
    assert again.resolved == cfg.resolved


@pytest.mark.parametrize("obj, cameras, width", [(None, 2, 0.5), ({"height": 1.8}, 2, 0.5),
                                                   ({"width": 0.45}, 2, 0.45), (None, 1, 0.4)])
def test_a_rigs_object_is_wider_unless_given(tmp_path, obj, cameras, width):
    """A rig of several cameras sees a person from every side: object.width left out is 0.5 m
    there (docs/rig.md), what the config gives where it gives one, the single camera's 0.4 for
    a rig of one; the other object keys as given; the resolved config says it."""
    from dpom_warp.loading import config_from_mapping

    rig = rig_mapping(tmp_path)
    rig.pop("object")
    rig["cameras"] = rig["cameras"][:cameras]
    if obj is not None:
        rig["object"] = obj
    cfg = config_from_mapping(rig)
    assert cfg.obj.width == width and cfg.resolved["object"]["width"] == width
    if obj and "height" in obj:
        assert cfg.obj.height == 1.8


@pytest.mark.parametrize("change, message", [
    (lambda r: r["cameras"][1].update(name="front"),
     r"^cameras\[1\]\.name: expected a name unlike the other cameras', found 'front' again \(cameras\[0\]\)$"),
    (lambda r: r["cameras"][1].update(name="side camera"),
     r"^cameras\[1\]\.name: expected a name of letters, digits, - and _, found 'side camera'$"),
    (lambda r: r.update(input={"frames": "x"}),
     r"^cameras: expected either a cameras: list or a single input and camera, found cameras: and a top-level input:"),
    (lambda r: r.update(cameras=[]), r"^cameras: expected a list of cameras, each \{name, input, camera\}, found an empty list$"),
    (lambda r: r["cameras"][1].pop("input"), r"^cameras\[1\]\.input: required key is missing"),
    (lambda r: r["cameras"][1].update(lens=1), r"^cameras\[1\]: unknown key 'lens'; expected name, input and camera$"),
    (lambda r: r["cameras"][1]["camera"].update(width=-1), r"^cameras\[1\]\.camera\.width: expected a value >= 1, found -1$"),
    (lambda r: r["cameras"][1]["input"].update(stride=2),
     r"^cameras\[1\]\.input\.stride: expected cameras\[0\]'s 'auto' \(a rig is inferred at one resolution\), found 2$"),
    (lambda r: r["cameras"][1]["input"].update(play=True),
     r"^cameras\[1\]\.input\.play: expected recorded frames as cameras\[0\]'s \(a rig is live, played or "
     r"recorded\), found frames played as a live camera's \(input\.play\)$"),
    (lambda r: r["cameras"][1]["input"].update(frames="realsense"),
     r"^cameras\[1\]\.input\.frames: expected recorded frames as cameras\[0\]'s \(a rig is live, played or "
     r"recorded\), found a live camera$"),
    (lambda r: r["cameras"][1]["camera"].update(extrinsics={"T_world_from_camera": [
        [1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, -0.5], [0, 0, 0, 1]]}),
     r"^cameras\[1\]\.camera\.extrinsics: expected a pose above the floor \(z = 0\), found the camera 0\.50 m under it$"),
    (lambda r: r.update(rig={"tolerance": 0}), r"^rig\.tolerance: expected a value > 0, found 0$"),
    (lambda r: r.update(grid={"x": [0, 0, 1], "y": [1.5, 5.5, 0.1]}), r"^grid\.x: expected min < max"),
])
def test_a_rigs_bad_config_names_the_camera_and_key(tmp_path, change, message):
    from dpom_warp.config import ConfigError
    from dpom_warp.loading import config_from_mapping

    rig = rig_mapping(tmp_path)
    change(rig)
    with pytest.raises(ConfigError, match=message):
        config_from_mapping(rig)


def test_an_override_names_the_rig_camera_it_reached(tmp_path):
    """A bad value given with --set cameras.N... is blamed on the --set item; an index beyond
    the list is a one-line error."""
    from dpom_warp.config import ConfigError
    from dpom_warp.loading import load_config

    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig_mapping(tmp_path)))
    with pytest.raises(ConfigError, match=r"^--set cameras\.1\.camera\.width=0: cameras\[1\]\.camera\.width: expected"):
        load_config(path, ["cameras.1.camera.width=0"])
    with pytest.raises(ConfigError, match=r"--set cameras\.2\.name: expected an index below 2 for the list, found '2'"):
        load_config(path, ["cameras.2.name=x"])


def test_frames_paired_by_time_and_by_order_by_hand():
    """Each first-camera frame takes another camera's nearest frame in time when it is at most
    the tolerance away (exactly the tolerance: paired), else none; by order, the frame at the
    same place until the camera's frames run out. Times are multiples of 1/8 s (exact in binary)."""
    from dpom_warp.frames import pair_by_index, pair_by_time

    first = [0.0, 0.25, 0.5, 0.75]
    other = [0.125, 0.625, 0.890625]  # each first frame 0.125 s from its nearest (0.75: 0.140625 from the third)
    assert pair_by_time(first, [other], 0.125) == [[0], [0], [1], [1]]
    assert pair_by_time(first, [other], 0.125 - 1 / 64) == [[None]] * 4
    assert pair_by_time([1.0], [[0.9375, 1.015625]], 0.05) == [[1]]
    assert pair_by_time(first, [np.array([])], 1.0) == [[None]] * 4
    assert pair_by_time([0.0, 1.0], [[0.9], [0.1, 2.0]], 0.1) == [[None, 0], [0, None]]
    assert pair_by_index(3, [2, 5]) == [[0, 0], [1, 1], [None, 2]]


def test_the_pairing_tolerance_defaults_to_half_the_first_cameras_period(tmp_path):
    from dpom_warp.frames import default_tolerance
    from dpom_warp.loading import config_from_mapping

    cfg = config_from_mapping(rig_mapping(tmp_path))
    assert default_tolerance(cfg, np.arange(10) / 30.0) == pytest.approx(1 / 60, abs=1e-15)
    assert default_tolerance(cfg, None) == 0.5 / 5  # input.fps 5: no timestamps
    rig = rig_mapping(tmp_path)
    rig["rig"] = {"tolerance": 0.02}
    assert default_tolerance(config_from_mapping(rig), np.arange(10) / 30.0) == 0.02


def test_a_camera_that_shares_no_cell_with_the_others_is_a_warning(tmp_path):
    """A camera of a rig that sees none of the cells the others see (its rectangles' areas
    against theirs) is one line naming it and its extrinsics key; views sharing one cell are
    none. By hand on four cells."""
    from types import SimpleNamespace

    from dpom_warp.loading import config_from_mapping
    from dpom_warp.session import lone_cameras

    cfg = config_from_mapping(rig_mapping(tmp_path))

    def views(*areas):
        return [SimpleNamespace(rect_area=np.array(a)) for a in areas]

    assert lone_cameras(cfg, views([5, 3, 0, 0], [0, 1, 2, 0])) == []
    lines = lone_cameras(cfg, views([5, 3, 0, 0], [0, 0, 2, 7]))
    assert lines == [f"cameras[{i}].camera.extrinsics: camera {n} sees none of the grid's cells another camera sees "
                     f"(2 cells of its own); expected views that overlap, for one map" for i, n in ((0, "front"), (1, "side"))]
    geoms = [build_geometry(m.camera, cfg.grid, cfg.obj) for _, m in cfg.cameras]
    assert lone_cameras(cfg, geoms) == []  # the test scene's two cameras overlap


def test_a_rig_camera_that_sees_none_of_the_grid_is_named(tmp_path, capsys):
    """The side camera turned away from the grid (yaw 270: it looks out of the room): the run
    stops with the grid's one-line error said of that camera, before anything is written."""
    from dpom_warp.cli import main

    rig = rig_mapping(tmp_path)
    rig["cameras"][1]["camera"]["extrinsics"]["yaw_deg"] = 270.0
    rig["evaluation"] = {}
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    scene = tmp_path / "scene"
    for name in ("front", "side"):  # frames of the right size (what they show does not matter here)
        for sub in ("frames", "background"):
            (scene / name / sub).mkdir(parents=True)
            from dpom_warp.io import write_depth_png

            write_depth_png(scene / name / sub / "0000.png", np.full((120, 160), 3.0))
    assert main(["run", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dpom-warp: error: cameras[1] (side): grid: none of its 1600 locations is in the camera's view")
    assert err.count("\n") == 1 and not (tmp_path / "out").exists()


def test_two_point_hypotheses_are_every_pair_of_pairs_by_hand():
    """calibrate.hypotheses against the loops it replaced, written out: for every frame, every
    pair i < j of the placed cameras' people at least SPAN apart, every ordered pair k != m of
    the camera's as far apart within MATCH, the Procrustes turn and shift of the two points (in
    that order, on random small sets with empty and one-person frames)."""
    from dpom_warp.calibrate import MATCH, SPAN, hypotheses, planar, procrustes

    rng = np.random.default_rng(7)
    for _ in range(5):
        src = [rng.uniform(0, 4, (rng.integers(0, 7), 2)) for _ in range(4)]
        dst = [rng.uniform(0, 4, (rng.integers(0, 7), 2)) for _ in range(4)]
        want = []
        for s_, d in zip(src, dst):
            for i in range(len(d)):
                for j in range(i + 1, len(d)):
                    span = np.linalg.norm(d[j] - d[i])
                    for k in range(len(s_)):
                        for m in range(len(s_)):
                            if span >= SPAN and k != m and abs(np.linalg.norm(s_[m] - s_[k]) - span) < MATCH:
                                want.append(procrustes(s_[[k, m]], d[[i, j]]))
        yaw, shift = hypotheses(src, dst)
        assert len(yaw) == len(want) > 0
        for got, T in zip((planar(y, *t) for y, t in zip(yaw, shift)), want):
            np.testing.assert_allclose(got, T, atol=1e-12)


def test_a_crowd_seen_by_two_cameras_gives_their_turn_and_shift():
    """calibrate.match_people on a planted crowd: 26 people a frame over 10 frames in 4.4 x 3.5 m;
    the second camera sees 20 of them (and two of its own ghosts) in its floor frame, turned by
    90 degrees and shifted by (3, 4) m, each position off by up to 3 cm. Its hundreds of thousands of
    two-point hypotheses are more than are scored (the most voted are), and the turn and shift
    come back within 0.5 degree and 3 cm, every person seen by both matched (a ghost may land
    within MATCH of someone: the RMS of the matches a few cm, theirs 2.4 cm)."""
    from dpom_warp.calibrate import MAX_SCORED, hypotheses, match_people, planar

    rng = np.random.default_rng(3)
    truth = planar(np.deg2rad(90.0), 3.0, 4.0)  # the second camera's floor frame into the world
    back = np.linalg.inv(truth)
    dst, src = [], []
    for _ in range(10):
        world = np.column_stack([rng.uniform(-2.2, 2.2, 26), rng.uniform(2.75, 6.25, 26)])
        dst.append(world)
        seen = world[rng.permutation(26)[:20]] @ back[:2, :2].T + back[:2, 3]
        ghosts = rng.uniform(-3, 3, (2, 2))
        src.append(np.concatenate([seen + rng.uniform(-0.03, 0.03, seen.shape), ghosts]))
    assert len(hypotheses(src, dst)[0]) > 10 * MAX_SCORED
    T, matched, rms = match_people(src, dst)
    turn = np.rad2deg(np.arctan2(T[1, 0], T[0, 0]))
    assert abs(turn - 90.0) < 0.5 and np.linalg.norm(T[:2, 3] - [3.0, 4.0]) < 0.03
    assert matched >= 200 and rms < 0.05


def planted_rig(rng, frames=10):
    """Three cameras' floor frames into the world (the first the world's own) and what each sees
    of 12 people a frame in 6 x 5 m, at least 0.7 m apart (more than twice MATCH: no wrong
    match at the truth), exactly, each in its own floor frame: camera 0 the left quarter
    (x < -1.5), camera 1 the left two thirds (x < 1), camera 2 the right two thirds (x > -1):
    cameras 0 and 2 share no one, camera 1 shares people with both."""
    from dpom_warp.calibrate import planar

    truth = [np.eye(4), planar(np.deg2rad(-90.0), -4.6, 4.5), planar(np.deg2rad(90.0), 4.6, 4.5)]
    sees = [lambda p: p[:, 0] < -1.5, lambda p: p[:, 0] < 1.0, lambda p: p[:, 0] > -1.0]
    seen = [[], [], []]
    for _ in range(frames):
        world = np.zeros((0, 2))
        while len(world) < 12:
            p = np.array([rng.uniform(-3, 3), rng.uniform(2, 7)])
            if not len(world) or np.linalg.norm(world - p, axis=1).min() >= 0.7:
                world = np.vstack([world, p])
        for c, T in enumerate(truth):
            back = np.linalg.inv(T)
            seen[c].append(world[sees[c](world)] @ back[:2, :2].T + back[:2, 3])
    return truth, seen


def test_joint_people_recovers_the_planted_poses_through_the_cameras_between():
    """calibrate.joint_people on three cameras that see a planted walk exactly: from the two
    free cameras' poses off by 0.6 and -0.4 degree and 5 to 8 cm (what placing them one after
    the other leaves), both come back to the truth (1e-6), camera 2 only through camera 1 (it
    shares no one with camera 0): the pairs of free cameras count. A camera not free (the
    first) is returned as given, bit for bit."""
    from dpom_warp.calibrate import joint_people, planar

    truth, seen = planted_rig(np.random.default_rng(5))
    start = [truth[0], planar(np.deg2rad(0.6), 0.05, -0.03) @ truth[1], planar(np.deg2rad(-0.4), -0.04, 0.06) @ truth[2]]
    got = joint_people(seen, start, [False, True, True])
    assert got[0] is start[0]
    for c in (1, 2):
        np.testing.assert_allclose(got[c], truth[c], atol=1e-6)


def test_joint_people_is_not_pulled_by_wrong_matches(monkeypatch):
    """The same walk with a tenth of cameras 1 and 2's detections doubled by a ghost 0.1 to 0.25 m
    away (within MATCH of the person: a wrong match each), from the same wrong start: the soft L1
    loss (scale NEAR, 5 cm) gives each ghost's residual little weight, so both cameras come back
    within 0.05 degree and 1 cm of the truth; plain least squares (the loss linear) is pulled
    farther on the same matches."""
    import scipy.optimize

    from dpom_warp.calibrate import joint_people, planar

    rng = np.random.default_rng(6)
    truth, seen = planted_rig(rng)
    for c in (1, 2):
        for f, p in enumerate(seen[c]):
            k = rng.random(len(p)) < 0.1
            angle = rng.uniform(0, 2 * np.pi, k.sum())
            ghost = p[k] + rng.uniform(0.1, 0.25, k.sum())[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
            seen[c][f] = np.concatenate([p, ghost])
    start = [truth[0], planar(np.deg2rad(0.6), 0.05, -0.03) @ truth[1], planar(np.deg2rad(-0.4), -0.04, 0.06) @ truth[2]]

    def off(T, ref):
        return (abs(np.rad2deg(np.arctan2(T[1, 0], T[0, 0]) - np.arctan2(ref[1, 0], ref[0, 0]))),
                float(np.linalg.norm(T[:2, 3] - ref[:2, 3])))

    robust = [off(T, truth[c]) for c, T in zip((1, 2), joint_people(seen, start, [False, True, True])[1:])]
    assert all(turn < 0.05 and shift < 0.01 for turn, shift in robust), robust
    solve = scipy.optimize.least_squares
    monkeypatch.setattr(scipy.optimize, "least_squares", lambda *a, **kw: solve(*a, **{**kw, "loss": "linear"}))
    pulled = [off(T, truth[c]) for c, T in zip((1, 2), joint_people(seen, start, [False, True, True])[1:])]
    assert max(s for _, s in pulled) > max(s for _, s in robust), (pulled, robust)

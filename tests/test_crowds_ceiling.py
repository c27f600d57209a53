"""Crowds and ceiling cameras (issue 19): the generator's scenes, and the solid object model
on them end to end, against the facing plane and the clustering baseline."""

import itertools
import json

import numpy as np
import pytest

from bench.baseline import score_config
from bench.robustness import PLANE
from dpom_warp.loading import load_config
from dpom_warp.pipeline import run
from dpom_warp.synthetic import generate
from paths import CONFIGS

DEMO = CONFIGS / "demo_people.yaml"

CROWD = ["synthetic.people=10", "synthetic.min_gap=0.45", "synthetic.area=[-1.6, 1.6, 2.5, 5.5]"]
CEILING = ["camera.extrinsics.height=3.5", "camera.extrinsics.pitch_deg=90", "camera.extrinsics.yaw_deg=30",
           "camera.extrinsics.y=4.0", "grid.x=[-1.8, 1.8, 0.1]", "grid.y=[2.4, 5.6, 0.1]",
           "synthetic.in_view=head", "synthetic.people=5", "synthetic.tables=1",
           "synthetic.area=[-1.5, 1.5, 2.7, 5.3]"]


def scene(tmp_path, sets, frames, seed=5):
    cache = tmp_path / "scene"
    return load_config(str(DEMO), sets + [
        f"synthetic.seed={seed}", f"synthetic.frames={frames}", "synthetic.background_frames=5",
        f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
        f"input.background={cache}/background/*.png", f"evaluation.ground_truth={cache}/ground_truth.json",
        "output.images=false", "evaluation.plots=false"])


def test_crowd_is_close_and_hides_people(tmp_path):
    cfg = scene(tmp_path, CROWD, 6)
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    truth = json.loads((tmp_path / "scene" / "ground_truth.json").read_text())
    gaps, visibility = [], []
    for frame in truth:
        pos = [(o["x"], o["y"]) for o in frame["objects"]]
        gaps += [np.hypot(a[0] - b[0], a[1] - b[1]) for a, b in itertools.combinations(pos, 2)]
        visibility += [o["visibility"] for o in frame["objects"]]
    assert min(gaps) >= 0.45 and min(gaps) < 0.6  # as close as the crowd allows, never closer
    assert min(visibility) < 0.5  # some people are mostly hidden by others


def test_ceiling_scene_has_heads_in_view_and_tables(tmp_path):
    cfg = scene(tmp_path, CEILING, 3)
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    truth = json.loads((tmp_path / "scene" / "ground_truth.json").read_text())
    for frame in truth:
        for o in frame["objects"]:
            u, v, z = cfg.camera.project(np.array([[o["x"], o["y"], o["height"]]]))
            assert 0 <= u[0] < cfg.camera.width and 0 <= v[0] < cfg.camera.height and z[0] > 0


@pytest.mark.parametrize("which", ["crowd", "ceiling"])
def test_solid_model_end_to_end(tmp_path, which):
    """The solid model finds the crowd and the people below a ceiling camera; the facing
    plane (with its own box and top-band defaults), on the same frames, finds no more and
    places them worse (measured, not assumed): with the defaults, and by more than 3 cm with
    the paper's independent prior (model.exclusion 0: the shapes alone; with the exclusion
    the plane finds fewer in the crowd and places those it finds better)."""
    cfg_sets = CROWD if which == "crowd" else CEILING
    scores = {}
    for shape, prior in itertools.product(("solid", "plane"), ("exclusion", "independent")):
        sets = cfg_sets + ([] if shape == "solid" else PLANE) + (["model.exclusion=0"] if prior == "independent" else [])
        cfg = scene(tmp_path, sets, 4)
        summary = run(cfg, str(tmp_path / shape), "cpu", progress=False, log=lambda *_: None, overwrite=True)
        scores[shape, prior] = summary["scores"]
    base = score_config(cfg)
    solid, plane = scores["solid", "exclusion"], scores["plane", "exclusion"]
    assert solid["moda"] >= 0.85, scores
    assert solid["mean_error_m"] <= 0.13, scores
    assert solid["moda"] >= plane["moda"] and solid["mean_error_m"] < plane["mean_error_m"], scores
    solid, plane = scores["solid", "independent"], scores["plane", "independent"]
    assert solid["moda"] >= plane["moda"], scores
    assert solid["mean_error_m"] < plane["mean_error_m"] - 0.03, scores
    assert base["n_gt"] == solid["n_gt"]


def test_person_hidden_but_for_head_and_shoulders_is_found():
    """A person 0.7 m straight behind another of the same height (1.8 m), seen by a camera
    2.2 m high at pitch 20 with five empty-room frames: the mean field finds them (rho 1), and
    the share of their silhouette left unhidden and supported, e of eq. 13, is about 0.05. The
    default cut-off (beta -3.5: e = 0.035) keeps them and adds no detection; an earlier one
    (beta -6.5: 0.065) cut them (README, Hidden people and eq. 13)."""
    from dpom_warp.detect import detect
    from dpom_warp.engine import Engine
    from dpom_warp.model import BEHIND_COST, ModelParams

    people = np.array([(0.0, 3.0), (0.0, 3.7)])
    cam, grid, geom, empty, depth = rendered_people(people)

    def found(params):
        engine = Engine(geom, params, "cpu")
        engine.set_background_frames(empty)
        res = engine.infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        return res, np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)

    res, dets = found(ModelParams(behind_cost=BEHIND_COST))
    near_hidden = np.hypot(*(geom.locations[:, :2] - people[1]).T) < 0.3
    best = np.flatnonzero(near_hidden)[np.argmax(res.rho[near_hidden])]
    assert res.rho[best] > 0.99 and 0.045 < res.evidence_share[best] < 0.065, (res.rho[best], res.evidence_share[best])
    assert len(dets) == 2 and all(np.hypot(*(dets - p).T).min() < 0.5 for p in people), dets
    _, old = found(ModelParams(beta=-6.5, behind_cost=BEHIND_COST))
    assert len(old) == 1 and np.hypot(*(old[0] - people[0])) < 0.5, old


def rendered_people(people, heights=None):
    """People rendered at `people` ((n, 2) metres; `heights` metres, default 1.8 m each) in a
    room with a floor and a far wall, seen by a 160 x 120 camera 2.2 m high at pitch 20, with
    sensor noise; five frames of the empty room. Returns camera, grid, geometry (0.4 m x 1.8 m
    solid), empty frames, depth."""
    from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    room = [_box((12, 14, 0.1), (0, 3, -0.05)), _box((12, 0.1, 3), (0, 7.05, 1.5))]
    empty = np.stack([sensor_noise(render(_scene(room)[0], cam)[0], SceneSpec(), np.random.default_rng(s))
                      for s in range(5)]).astype(np.float32)
    heights = [1.8] * len(people) if heights is None else heights
    meshes = room + [person_mesh(h, np.pi / 2 + 0.2 * i, 0.5 + i).translate((x, y, 0.0))
                     for i, ((x, y), h) in enumerate(zip(people, heights))]
    depth = sensor_noise(render(_scene(meshes)[0], cam)[0], SceneSpec(), np.random.default_rng(7)).astype(np.float32)
    grid = Grid(x=(-2.0, 2.0, 0.1), y=(1.5, 5.5, 0.1))
    return cam, grid, build_geometry(cam, grid, ObjectBox(0.4, 1.8)), empty, depth


def test_short_person_hidden_to_the_head_keeps_a_shorter_top_band():
    """A person of 1.56 m 0.9 m behind one of 1.66 m (0.1 m aside), seen by the rendered
    room's camera: the mean field finds them (rho 1, e of eq. 13 above its cut-off), but the
    top band of the 1.8 m solid reads the room above their head (u about top_support: rho*
    under the detection threshold, 0.31 with top_hidden 0.25) and they are lost without
    model.top_heights; with the config's rule for that solid
    (object.height - 0.15: a 1.65 m solid's band, which holds the head; with a background
    only) both people are found, and nothing more."""
    from dpom_warp.detect import detect
    from dpom_warp.engine import Engine
    from dpom_warp.model import BEHIND_COST, TOP_SHORTER, ModelParams

    people = np.array([(0.0, 4.3), (0.1, 5.2)])
    _, grid, geom, empty, depth = rendered_people(people, [1.66, 1.56])
    config = load_config(CONFIGS / "demo_people.yaml")
    assert config.model.top_heights == pytest.approx((config.obj.height - TOP_SHORTER,))
    heights = (1.8 - TOP_SHORTER,)  # the rule, for this test's 1.8 m solid
    # and off floor-only, where it lets furniture through
    assert load_config(CONFIGS / "demo_people.yaml", ["input.background=null"]).model.top_heights == ()

    def found(top_heights):
        engine = Engine(geom, ModelParams(behind_cost=BEHIND_COST, top_heights=top_heights), "cpu")
        engine.set_background_frames(empty)
        res = engine.infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        near = np.hypot(*(geom.locations[:, :2] - people[1]).T) < 0.3
        best = np.flatnonzero(near)[np.argmax(res.rho[near])]
        return res, best, np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)

    res, best, dets = found(())
    assert res.rho[best] > 0.99 and res.evidence_share[best] > 0.1 and res.rho_star[best] < 0.4, (
        res.rho[best], res.evidence_share[best], res.rho_star[best])
    assert len(dets) == 1 and np.hypot(*(dets[0] - people[0])) < 0.5, dets
    res, best, dets = found(heights)
    assert res.rho_star[best] > 0.9
    assert len(dets) == 2 and all(np.hypot(*(dets - p).T).min() < 0.5 for p in people), dets


def test_readings_behind_count_against_a_cell_beside_a_person():
    """model.behind_cost: in a rendered person's own cell few pixels of the silhouette's core
    read behind the solid, in cells 0.2 to 0.3 m beside them (half over the person, half over
    the room behind: what one person found as two cells looked like) four times as many or
    more; with the config's default cost the person is still one detection, at its place."""
    from dpom_warp import reference as ref
    from dpom_warp.detect import detect
    from dpom_warp.engine import Engine
    from dpom_warp.model import BEHIND_COST, ModelParams

    person = np.array([0.0, 3.0])
    _, grid, geom, empty, depth = rendered_people(person[None])
    params = ModelParams(behind_cost=BEHIND_COST)
    dist = np.hypot(*(geom.locations[:, :2] - person).T)
    own = int(np.argmin(dist))
    beside = np.flatnonzero((np.abs(geom.locations[:, 1] - person[1]) < 0.05)
                            & (np.abs(np.abs(geom.locations[:, 0] - person[0]) - 0.25) < 0.06))
    counts = ref.behind_count(depth, geom, params, np.isin(np.arange(len(dist)), [own, *beside]))
    assert len(beside) == 4 and counts[beside].min() > 4 * max(counts[own], 1), (counts[own], counts[beside])

    def located(p):
        engine = Engine(geom, p, "cpu")
        engine.set_background_frames(empty)
        res = engine.infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        return len(dets), dist[int(np.argmax(res.rho_star))]

    n, err = located(params)
    assert n == 1 and err < 0.2, (n, err)


def test_a_person_at_a_ceiling_cameras_edge_is_found_with_a_background():
    """A ceiling camera 3 m up looking straight down sees a person standing near the edge of
    its image from the knees down to the floor: the top band of the solid (its head and
    shoulders) lies outside the image. With a background (frames or auto) such a cell is not
    judged by the band (model.top_unseen 1, the config's default there) and the person is
    found, once; with top_unseen 0 (the floor-only default, where a table at the edge looks
    the same) they are lost, though the mean field holds them."""
    from dpom_warp.detect import detect
    from dpom_warp.engine import Engine
    from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
    from dpom_warp.model import BEHIND_COST, ModelParams
    from dpom_warp.synthetic import SceneSpec, _box, _scene, person_mesh, render, sensor_noise

    assert load_config(DEMO).model.top_unseen == 1.0
    assert load_config(DEMO, ["input.background=auto"]).model.top_unseen == 1.0
    assert load_config(DEMO, ["input.background=null"]).model.top_unseen == 0.0
    cam = Camera(160, 120, 114.0, 114.0, 79.5, 59.5, pose_from_angles(3.0, 90.0, y_m=4.0))
    floor = [_box((12, 14, 0.1), (0, 4, -0.05))]
    empty = np.stack([sensor_noise(render(_scene(floor)[0], cam)[0], SceneSpec(), np.random.default_rng(s))
                      for s in range(5)]).astype(np.float32)
    person = np.array([1.45, 4.0])
    mesh = person_mesh(1.75, 0.3, 0.5).translate((*person, 0.0))
    depth = sensor_noise(render(_scene(floor + [mesh])[0], cam)[0], SceneSpec(),
                         np.random.default_rng(7)).astype(np.float32)
    grid = Grid(x=(-2.0, 2.0, 0.1), y=(2.5, 5.5, 0.1))
    geom = build_geometry(cam, grid, ObjectBox(0.4, 1.85))

    def found(top_unseen):
        params = ModelParams(behind_cost=BEHIND_COST, top_heights=(1.7,), top_unseen=top_unseen)
        engine = Engine(geom, params, "cpu")
        engine.set_background_frames(empty)
        res = engine.infer(depth)
        dets = detect(res.rho_star.reshape(grid.shape), geom.locations, geom.rect, 0.5, 0.4)
        own = int(np.argmin(np.hypot(*(geom.locations[:, :2] - person).T)))
        return res, own, engine.prior.top_counts[4].numpy()[own], np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)

    res, own, seen, dets = found(1.0)
    assert 0 <= seen < 3, seen  # the band out of view (fewer than top_min_pixels)
    assert len(dets) == 1 and np.hypot(*(dets[0] - person)) < 0.3, dets
    res, own, seen, dets = found(0.0)
    assert res.rho[own] > 0.9 and len(dets) == 0, (res.rho[own], dets)


@pytest.fixture(scope="module")
def ceiling_3m(tmp_path_factory):
    """The held-out ceiling scene at 3.0 m, pitch 90 (bench.robustness, seed 100, 10 frames),
    rendered once: its overrides and folder."""
    from bench.robustness import VARIANTS

    cache = tmp_path_factory.mktemp("ceiling") / "scene"
    sets = VARIANTS["ceiling 3.0 m, pitch 90"] + ["synthetic.seed=100", "synthetic.frames=10",
                                                   f"synthetic.cache={cache}", "device=cpu"]
    cfg = load_config(str(DEMO), sets)
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    return sets, cache


def ceiling_frame(ceiling_3m, name: str, extra: list[str]):
    """Frame `name` of that scene through the API (background frames): its people (n, 2), the
    detections (m, 2), their view parts and the config."""
    from dpom_warp.api import Detector
    from dpom_warp.evaluate import load_ground_truth
    from dpom_warp.io import read_depth

    sets, cache = ceiling_3m
    frame = cache / "frames" / name
    people = np.array([(o["x"], o["y"]) for o in load_ground_truth(cache / "ground_truth.json")[name]])
    detector = Detector.from_config(str(DEMO), sets + [f"input.frames={frame}",
                                                       f"input.background={cache}/background/*.png", *extra])
    cfg = detector.config
    res = detector.detect(read_depth(frame, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width)))
    ks = [d.k for d in res.detections]
    return people, np.array([(d.x, d.y) for d in res.detections]), detector.worker.geometry.view_part[ks], cfg


def test_a_second_cell_at_a_ceiling_cameras_edge_is_dropped(ceiling_3m):
    """Frame 2 of the held-out ceiling scene at 3.0 m: a person of 1.57 m near the image's
    edge is found, and a cell 0.35 m beside them whose silhouette rectangle lies mostly outside
    the image too (rho* 1). detection.edge_radius (0.45 m by default) drops that cell, not the
    person, and the frame's detections are its people."""
    from dpom_warp.evaluate import match

    people, where, view, _ = ceiling_frame(ceiling_3m, "0002.png", ["detection.edge_radius=0"])
    assert len(where) == len(people) + 1
    edge = np.flatnonzero(view < 0.5)
    assert any(np.hypot(*(where[e] - where[j])) < 0.45 for e in edge for j in np.flatnonzero(view >= 0.5))
    people, where, view, cfg = ceiling_frame(ceiling_3m, "0002.png", [])
    assert cfg.detection.edge_radius == 0.45
    assert len(where) == len(people) and len(match(where, people, 0.5)) == len(people)


def test_a_second_cell_beside_a_person_seen_from_above_fails_the_top_band(ceiling_3m):
    """Frame 5 of the held-out ceiling scene at 3.0 m: a cell 0.36 m from a person of 1.76 m,
    seen from straight above, whose top band holds a sliver of the person's head and reads the
    floor elsewhere (u = 0.125): with model.top_support 0.12 its rho* passed the threshold, with
    the default 0.13 (README, How it works) it does not, and the frame's detections are its
    people."""
    from dpom_warp.evaluate import match

    people, where, _, _ = ceiling_frame(ceiling_3m, "0005.png", ["model.top_support=0.12"])
    assert len(where) == len(people) + 1 and len(match(where, people, 0.5)) == len(people)
    people, where, _, cfg = ceiling_frame(ceiling_3m, "0005.png", [])
    assert cfg.model.top_support == 0.13
    assert len(where) == len(people) and len(match(where, people, 0.5)) == len(people)


def test_a_far_table_seen_from_a_ceiling_camera_is_not_a_person_floor_only(tmp_path):
    """The held-out ceiling scene at 3.2 m, pitch 45 (bench.robustness, seed 100), first frame,
    floor-only: the top band of a cell on a table 5 to 6 m away looks at the room beyond the
    sensor's range and reads nothing there. With model.top_missing 0 those pixels count for
    none, the band is hardly judged and the tables are detected; with the default (1) a missing
    reading where the object would be read counts against it, and the detections are the
    frame's people, each found."""
    from bench.robustness import VARIANTS
    from dpom_warp.api import Detector
    from dpom_warp.evaluate import load_ground_truth, match
    from dpom_warp.io import read_depth

    cache = tmp_path / "scene"
    sets = VARIANTS["ceiling 3.2 m, pitch 45, yaw -40, 8 people"] + [
        "synthetic.seed=100", "synthetic.frames=1", f"synthetic.cache={cache}", "device=cpu",
        f"input.frames={cache}/frames/0000.png", "input.background=null"]
    cfg = load_config(str(DEMO), sets)
    generate(cfg.synthetic, cfg.camera, cache)
    people = np.array([(o["x"], o["y"]) for o in load_ground_truth(cache / "ground_truth.json")["0000.png"]])

    def found(extra):
        detector = Detector.from_config(str(DEMO), sets + extra)
        cfg = detector.config
        res = detector.detect(read_depth(cache / "frames" / "0000.png", cfg.inputs.depth_scale,
                                         (cfg.camera.height, cfg.camera.width)))
        engine = detector.engine
        where = np.array([(d.x, d.y) for d in res.detections]).reshape(-1, 2)
        missing = engine.prior.top_counts[3].numpy()[[d.k for d in res.detections]]
        seen = engine.prior.top_counts[4].numpy()[[d.k for d in res.detections]]
        return where, missing, seen, cfg

    where, missing, seen, _ = found(["model.top_missing=0"])
    far = np.array([np.hypot(*(people - w).T).min() > 0.5 for w in where])
    assert far.sum() >= 1 and len(match(where, people, 0.5)) == len(people)
    assert np.all(missing[far] > 0.5 * seen[far])  # their bands mostly read nothing
    where, _, _, cfg = found([])
    assert cfg.model.top_missing == 1.0
    assert len(where) == len(people) and len(match(where, people, 0.5)) == len(people)

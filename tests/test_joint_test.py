"""The joint test (detection.min_log_odds): each detection's log posterior odds with the other
detections present, against the model's joint probability evaluated by brute force, from the
lists the engine hands over on every device, and on rendered people."""


import numpy as np
import pytest

from dpom_warp import reference as ref
from dpom_warp.config import Detection
from dpom_warp.loading import load_config
from dpom_warp.detect import MIN_LOG_ODDS, detect_map, joint_detections
from dpom_warp.engine import Engine
from paths import CONFIGS
from scenes import random_scene


def log_joint(depth, geom, bg, params, cells):
    """log P(Z, X) - log P(Z, nothing present) for the configuration X with objects at `cells`
    and nowhere else, by brute force: each pixel is explained by the nearest present object
    whose mask holds it (MODEL.md: pixels outside every mask contribute nothing), else by the
    background; plus the prior, the readings behind each object's core and the exclusion
    prior of each pair closer than its radius."""
    pixel, loc, _, delta = ref.mask_entries(depth, geom, params, bg)  # by pixel, then near to far
    dbg = ref.background_delta(depth, bg, params).ravel()
    total = 0.0
    for p in np.unique(pixel):
        present = np.flatnonzero((pixel == p) & np.isin(loc, cells))
        if len(present):
            total += float(delta[present[0]]) - dbg[p]
    which = np.zeros(len(geom.rect), bool)
    which[cells] = True
    total -= params.behind_cost * ref.behind_count(depth, geom, params, which)[cells].sum()
    where = geom.locations[cells]
    pairs = sum(np.linalg.norm(where[a] - where[b]) < params.exclusion_radius
                for a in range(len(cells)) for b in range(a + 1, len(cells)))
    return total + len(cells) * (np.log(params.prior) - np.log1p(-params.prior)) - params.exclusion * pairs


@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(4))
def test_log_odds_are_the_joint_probability_with_and_without_each_cell(seed, shape):
    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    params = params.replace(behind_cost=2.0 if shape == "solid" else 0.0, exclusion=10.0,
                                 exclusion_radius=0.45)
    bg = ref.background_from_frames(bg_frames, params) if seed % 2 else ref.floor_background(geom, params, depth)
    _, loc, _, _ = ref.mask_entries(depth, geom, params, bg)
    listed = np.unique(loc)
    rng = np.random.default_rng(seed)
    cells = rng.choice(listed, size=min(5, len(listed)), replace=False)
    gap = np.linalg.norm(geom.locations[listed] - geom.locations[cells[0]], axis=1)
    close = [k for k in listed[(gap > 0) & (gap < params.exclusion_radius)] if k not in cells]
    cells = np.append(cells, close[:1]).astype(np.int64)  # with a pair the exclusion prior counts
    odds = ref.joint_log_odds(depth, geom, bg, params, cells)
    whole = log_joint(depth, geom, bg, params, cells)
    want = [whole - log_joint(depth, geom, bg, params, np.delete(cells, i)) for i in range(len(cells))]
    np.testing.assert_allclose(odds, want, rtol=0, atol=1e-6)
    assert np.ptp(odds) > 1.0, "the cells' odds do not differ: the comparison is not exercised"


@pytest.mark.parametrize("frames", [True, False])
def test_engine_hands_over_the_joint_tests_lists(device, frames):
    """With joint_threshold, each result carries the JointLists of the locations whose rho*
    (float32) reaches it, copied out of the engine's lists: their log odds are the
    reference's, computed from the frame and background from scratch, to 1e-6 (background
    frames, or the floor-only model completed from the frame), alone and in a batch; a cell
    that is not a candidate is refused."""
    geom, params, depth, bg_frames = random_scene(5, shape="solid")
    params = params.replace(behind_cost=2.0, exclusion=10.0, exclusion_radius=0.45,
                                 background_outside_grid=True)
    engines = [Engine(geom, params, device), Engine(geom, params, device, batch=3), Engine(geom, params, device, batch=3)]
    engines[2].ordered_joint_lists = not engines[2].ordered_joint_lists  # the other device's way
    assert engines[0].infer(depth).joint is None  # off unless asked (make_engine: min_log_odds > 0)
    if frames:
        bg = ref.background_from_frames(bg_frames, params)
        for e in engines:
            e.set_background_frames(bg_frames)
    else:
        bg = ref.floor_background(geom, params, depth)
    res = engines[0].infer(depth)
    star = np.asarray(res.rho_star, np.float32)
    threshold = float(np.sort(star)[-8])  # eight candidates at least, ties included
    for e in engines:
        e.joint_threshold = threshold
    res = engines[0].infer(depth)
    batch = engines[1].infer_batch(np.stack([bg_frames[0], depth]))  # the frame second, after another
    candidates = np.flatnonzero(star >= threshold)
    np.testing.assert_array_equal(res.joint.cells, candidates)
    np.testing.assert_array_equal(batch[1].joint.cells, candidates)
    for field in ("cells", "count", "L", "D", "dbg", "behind", "locations"):  # a batch's lists: the frame's alone
        np.testing.assert_array_equal(getattr(batch[1].joint, field), getattr(res.joint, field))
    alone = engines[0].infer(bg_frames[0]).joint  # (the first frame's, fewer candidates or none)
    other = engines[2].infer_batch(np.stack([bg_frames[0], depth]))  # (count, scan, fill or compact_once)
    for field in ("cells", "count", "L", "D", "dbg", "behind", "locations"):
        np.testing.assert_array_equal(getattr(batch[0].joint, field), getattr(alone, field))
        for f in (0, 1):
            np.testing.assert_array_equal(getattr(other[f].joint, field), getattr(batch[f].joint, field))
    rng = np.random.default_rng(0)
    for size in (1, 3, len(candidates)):
        cells = rng.choice(candidates, size=size, replace=False)
        want = ref.joint_log_odds(depth, geom, bg, params, cells)
        np.testing.assert_allclose(res.joint.log_odds(cells), want, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(batch[1].joint.log_odds(cells), want, rtol=1e-6, atol=1e-6)
    assert np.ptp(res.joint.log_odds(candidates)) > 1.0
    outside = int(np.flatnonzero(star < threshold)[0])
    with pytest.raises(ValueError, match="not among the frame's candidates"):
        res.joint.log_odds([candidates[0], outside])
    for e in (engines[0], engines[2]):  # no candidate: nothing to copy, either way
        e.joint_threshold = float(star.max()) + 1e-3
        none = e.infer(depth).joint
        assert len(none.cells) == 0 and none.count.size == 0 and len(none.log_odds([])) == 0


def test_defaults_and_bad_values():
    for name in ("demo_people.yaml", "demo_drones.yaml"):
        assert load_config(CONFIGS / name).detection.min_log_odds == MIN_LOG_ODDS > 0
    assert load_config(CONFIGS / "demo_people.yaml", ["detection.min_log_odds=0"]).detection.min_log_odds == 0
    from dpom_warp.config import ConfigError

    with pytest.raises(ConfigError, match="min_log_odds"):
        load_config(CONFIGS / "demo_people.yaml", ["detection.min_log_odds=-1"])


def test_cells_the_test_rejects_leave_the_map_until_every_detection_passes():
    """Two rendered people, each worth over a thousand nats with the other present; with a
    bar between the two, the weaker person's peak leaves the map, then each cell of their blob
    that rises as a detection in its place, and the stronger is the one detection left; the
    map returned holds the removed cells at 0 and detects to the same detections."""
    from test_crowds_ceiling import rendered_people
    from dpom_warp.model import BEHIND_COST, ModelParams

    people = np.array([(-0.6, 4.0), (0.6, 4.5)])
    _, grid, geom, empty, depth = rendered_people(people)
    params = ModelParams(behind_cost=BEHIND_COST, exclusion=10.0)
    engine = Engine(geom, params, "cpu")
    engine.joint_threshold = Detection().threshold
    engine.set_background_frames(empty)
    res = engine.infer(depth)
    rho_map = res.rho_star.reshape(grid.shape)
    calls = []

    def log_odds(cells):
        calls.append(list(cells))
        return res.joint.log_odds(cells)

    default = Detection(edge_radius=0.45, min_log_odds=MIN_LOG_ODDS)
    kept_map, dets = joint_detections(rho_map, geom, default, log_odds)
    assert kept_map is rho_map and len(dets) == 2 and len(calls) == 1  # both pass at once
    odds = log_odds([d.k for d in dets])
    assert odds.min() > 1000
    bar = Detection(edge_radius=0.45, min_log_odds=float(odds.mean()))
    before = rho_map.copy()
    out, left = joint_detections(rho_map, geom, bar, log_odds)
    np.testing.assert_array_equal(rho_map, before)  # the run's map is not changed in place
    strong = dets[int(np.argmax(odds))]
    assert [d.k for d in left] == [strong.k]
    removed = np.flatnonzero(out.ravel() != before.ravel())
    assert len(removed) >= 1 and np.all(out.ravel()[removed] == 0) and np.all(before.ravel()[removed] >= 0.5)
    other = people[1 - int(np.argmin([np.hypot(*(p - (strong.x, strong.y))) for p in people]))]
    assert np.all(np.hypot(*(geom.locations[removed, :2] - other).T) < 0.5)  # the weaker one's blob
    assert [d.k for d in detect_map(out, geom, bar)] == [strong.k]
    assert log_odds([strong.k])[0] >= bar.min_log_odds
    off = Detection(edge_radius=0.45, min_log_odds=0.0)
    assert joint_detections(rho_map, geom, off, log_odds)[0] is rho_map

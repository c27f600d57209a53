"""Several depth cameras on one map (issue 61): evidence fused in one mean field, not detections
fused after each camera has decided alone. The engine against the NumPy reference on random
rigs is in test_warp_vs_reference (test_a_rig_matches_the_reference)."""

import numpy as np
import pytest

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

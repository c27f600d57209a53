"""The benchmark's timing of one scene, on a small rendered scene (not its speed)."""

import numpy as np
import pytest

from bench.__main__ import kernel_times, time_scene
from dpom_warp.loading import load_config
from dpom_warp.io import read_depth
from dpom_warp.sources import expand
from dpom_warp.worker import make_engine
from dpom_warp.synthetic import generate

from test_cli import small_config


def test_bench_times_every_stage_and_batches_honestly(tmp_path):
    cfg = load_config(small_config(tmp_path), [])
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    shape = (cfg.camera.height, cfg.camera.width)
    frames = np.stack([read_depth(f, cfg.inputs.depth_scale, shape)
                       for f in expand(cfg.inputs.frames, "input.frames")])
    bg = np.stack([read_depth(f, cfg.inputs.depth_scale, shape)
                   for f in expand(cfg.inputs.background, "input.background")])
    cfg = load_config(small_config(tmp_path), ["input.stride=2"])
    r, warm = time_scene(cfg, frames[0], bg, "cpu", 2, batch=3, sequence=(frames, bg))
    assert set(r["median_s"]) == {"background model (kernel)", "masks, Delta, lists, sort", "one iteration",
                                  "whole frame", "whole frame, graph", "per frame, batched"}
    assert all(t > 0 for t in r["median_s"].values())
    assert r["mask_entries"] == warm.entries > 0 and r["engine_memory_mb"] > 0
    assert r["image"] == [64, 53] and r["stride"] == 2  # frames reduced as a run reduces them
    alone = make_engine(cfg, cfg.camera, "cpu", 1)
    alone.set_background_frames(alone.resolution.frames(bg))
    assert r["batch_iterations"] == [alone.infer(alone.resolution.frames(f)).iterations for f in frames]
    assert r["frames_per_s_batched"] == 1 / r["median_s"]["per frame, batched"]


def test_kernel_times_count_every_launch_of_a_frame(tmp_path):
    """bench --kernels: each kernel's launches in a frame (the evidence pass and the update
    once an iteration), every one timed, and Warp's launch functions given back after."""
    import warp as wp

    from dpom_warp.engine.launch import Launcher

    cfg = load_config(small_config(tmp_path), ["input.stride=2"])
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    shape = (cfg.camera.height, cfg.camera.width)
    depth = read_depth(expand(cfg.inputs.frames, "input.frames")[0], cfg.inputs.depth_scale, shape)
    bg = np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in expand(cfg.inputs.background, "input.background")])
    launch, recorded = wp.launch, Launcher.__call__
    times = kernel_times(cfg, depth, bg, "cpu", 3)
    assert wp.launch is launch and Launcher.__call__ is recorded
    engine = make_engine(cfg, cfg.camera, "cpu", 1)
    engine.set_background_frames(engine.resolution.frames(bg))
    iterations = engine.infer(engine.resolution.frames(depth)).iterations
    assert times["evidence_pass"][1] == times["update_rho"][1] == iterations > 1
    assert times["pixel_entries_once"][1] == 1 and all(ms > 0 for ms, _ in times.values())
    assert list(times)[-1] == "rest of the call" and times["rest of the call"][1] == 0
    ms = [ms for ms, _ in list(times.values())[:-1]]
    assert ms == sorted(ms, reverse=True)  # the most costly first
    # two frames a call: the launches are a call's, the times a frame's
    frames = np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in expand(cfg.inputs.frames, "input.frames")])
    two = kernel_times(cfg, frames[:2], bg, "cpu", 3, batch=2)
    assert two["pixel_entries_once"][1] == 1 and two["evidence_pass"][1] >= iterations
    assert all(ms > 0 for ms, _ in two.values())


def test_batch_sweep_times_each_batch_size(tmp_path):
    """bench --batch-sweep: a time a frame and its parts for each batch size, sizes above the
    sequence's length taking its frames again."""
    from bench.__main__ import batch_sweep

    cfg = load_config(small_config(tmp_path), ["input.stride=2"])
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    shape = (cfg.camera.height, cfg.camera.width)
    frames = np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in expand(cfg.inputs.frames, "input.frames")])
    bg = np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in expand(cfg.inputs.background, "input.background")])
    n = len(frames)
    per_frame, parts = batch_sweep(cfg, (frames, bg), "cpu", 2, [1, n + 1])
    assert list(per_frame) == list(parts) == [1, n + 1] and all(t > 0 for t in per_frame.values())
    for b, p in parts.items():
        assert set(p) == {"lists_s", "iterations_s", "threshold_s", "joint_lists_s", "rest_s"}
        whole = p["lists_s"] + p["iterations_s"] + p["threshold_s"] + p["rest_s"]
        assert whole <= per_frame[b] * 1.5  # parts of the call (medians: not a sum exactly)
        assert p["lists_s"] > 0 and p["iterations_s"] > 0 and 0 < p["joint_lists_s"] <= p["threshold_s"]


def test_errors_sorts_each_error_by_its_kind(tmp_path):
    """bench.errors' kinds: a miss by the stage that lost the person, a false detection by
    its band and its distance to the people; cell_values reads a real frame's engine."""
    from bench.errors import cell_values, false_kind, miss_kind
    from dpom_warp.api import Detector

    cell = dict(rho=1.0, before=1.0, rho_star=1.0, out_of_view=False)
    assert miss_kind(None, 0.5) == "no support in the mean field"
    assert miss_kind({**cell, "rho": 0.2, "before": 0.2, "rho_star": 0.2}, 0.5) == "no support in the mean field"
    assert miss_kind({**cell, "before": 0.3, "rho_star": 0.3}, 0.5) == "cut by eq. 13"
    assert miss_kind({**cell, "rho_star": 0.1}, 0.5) == "cut by the top band"
    assert miss_kind(cell, 0.5) == "found as one with a neighbour"
    assert false_kind({**cell, "out_of_view": True}, 0.2, 0.5) == "band out of view"
    assert false_kind(cell, 0.3, 0.5) == "second cell beside a person"
    assert false_kind(cell, 0.8, 0.5) == "elsewhere"
    # the strongest cell near a missed person and how far the nearest detection lies from it
    from bench.errors import strongest_near
    locs = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.6, 0.0]])
    assert strongest_near(np.array([0.2, 0.9, 0.4, 1.0]), locs, np.array([0, 1, 2]),
                          np.array([[0.5, 0.0], [2.0, 0.0]])) == pytest.approx((0.9, 0.4))
    assert strongest_near(np.array([0.2, 0.9, 0.4, 1.0]), locs, np.array([0, 2]), np.zeros((0, 2)))[1] == np.inf

    # --bands: u of a band no pixel supports (the five-people frame's low object: 0.25 x 130 / 198)
    from bench.errors import unsupported_u
    assert unsupported_u((0, 61, 130, 7, 198), 0.25, 1.0) == pytest.approx(32.5 / 198)
    assert unsupported_u((0, 61, 130, 7, 198), 0.25, 0.0) == pytest.approx(32.5 / 191)
    assert unsupported_u((1, 61, 130, 7, 198), 0.25, 1.0) is None and unsupported_u((0, 0, 0, 0, 0), 0.25, 1.0) is None

    det = Detector.from_config(small_config(tmp_path), ["device=cpu"])
    cfg = det.config
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    frame = expand(cfg.inputs.frames, "input.frames")[0]
    result = det.detect(read_depth(frame, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width)))
    k = int(np.argmax(result.rho_star))
    v = cell_values(det, result, k)
    assert v["rho_star"] == float(result.rho_star.ravel()[k]) and v["rho"] == float(result.rho.ravel()[k])
    assert v["before"] >= v["rho_star"] - 1e-9  # the top band's factor is at most 1


def test_detection_level_fusion_of_the_rig_bench_by_hand():
    """bench.rig's detection fusion (the comparison the rig table makes): each camera's
    detections merged greedily into the first group whose mean is within 0.4 m and holds none
    of that camera's, kept where `agree` cameras found it, at the group's mean. Worked by hand:
    camera A (0, 0) and (2, 2); B (0.3, 0) joins A's first (0.3 m), (5, 5) alone; C (0.1, 0.35)
    is 0.354 m from that group's mean (0.15, 0) and joins it; A's second detection 0.2 m from
    its first starts a group of its own (one camera, one vote)."""
    from bench.rig import fuse_detections

    a = {"f": np.array([[0.0, 0.0], [2.0, 2.0]]), "g": np.array([[0.0, 0.0], [0.2, 0.0]])}
    b = {"f": np.array([[0.3, 0.0], [5.0, 5.0]]), "g": np.zeros((0, 2))}
    c = {"f": np.array([[0.1, 0.35]]), "g": np.zeros((0, 2))}
    one, two = fuse_detections([a, b, c], 1), fuse_detections([a, b, c], 2)
    np.testing.assert_allclose(one["f"], [[0.4 / 3, 0.35 / 3], [2.0, 2.0], [5.0, 5.0]], atol=1e-12)
    np.testing.assert_allclose(two["f"], [[0.4 / 3, 0.35 / 3]], atol=1e-12)
    np.testing.assert_allclose(one["g"], [[0.0, 0.0], [0.2, 0.0]], atol=1e-12)
    assert two["g"].shape == (0, 2)


def test_support_pieces_give_back_a_rendered_panel_and_drop_small_ones():
    """bench.support: a 0.4 x 1.1 m upright panel at y = 4 (x 0.2 to 0.6, 0.5 to 1.6 m high)
    before a far wall, seen from 1.3 m up, comes back as one piece with its spans (to a pixel's
    width, 4 / 120 m, and the percentiles' trim), the floor under it left out by the height
    range, and its top its own (the wall shows above it) at 1.6 m except where a bar nearer the
    camera (y = 3, x 0.3 to 0.4, 1.5 to 1.7 m high: it hides x 0.4 to 0.53 of the panel's top)
    lies over it; a 0.1 m square (about 9 pixels) is no piece at 40."""
    from bench.support import box_share, pieces
    from dpom_warp.geometry import Camera, pose_from_angles

    cam = Camera(160, 120, 120.0, 120.0, 79.5, 59.5, pose_from_angles(1.3, 5.0))
    d, c = cam.rays(), cam.centre
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(d[..., 2] < 0, -c[2] / d[..., 2], np.inf)
        t3, t4, t6 = ((y - c[1]) / d[..., 1] for y in (3.0, 4.0, 6.0))
    p3, p4 = c + t3[..., None] * d, c + t4[..., None] * d
    panel = (p4[..., 0] >= 0.2) & (p4[..., 0] <= 0.6) & (p4[..., 2] >= 0.5) & (p4[..., 2] <= 1.6)
    square = (p4[..., 0] >= -0.3) & (p4[..., 0] <= -0.2) & (p4[..., 2] >= 1.0) & (p4[..., 2] <= 1.1)
    bar = (p3[..., 0] >= 0.3) & (p3[..., 0] <= 0.4) & (p3[..., 2] >= 1.5) & (p3[..., 2] <= 1.7)
    depth = np.minimum(floor, np.where(bar, t3, np.where(panel | square, t4, t6)))
    seen = panel & ~bar
    found = pieces(depth, cam, (0.4, 4.0), 0.4, (0.08, 2.15))
    assert len(found) == 1
    (p,) = found
    assert p["pixels"] == int(seen.sum())
    assert abs(p["y"] - 4.0) < 1e-9
    assert p["x"][0] == pytest.approx(0.2, abs=0.04) and p["x"][1] == pytest.approx(0.6, abs=0.04)
    assert p["z"][0] == pytest.approx(0.5, abs=0.04) and p["z"][1] == pytest.approx(1.6, abs=0.04)
    v, u = np.nonzero(seen)
    assert (p["u"], p["v"]) == ((u.min(), u.max()), (v.min(), v.max()))
    assert box_share(found, (u.min(), v.min(), u.max(), v.max())) == pytest.approx(
        seen.sum() / ((u.max() - u.min() + 1) * (v.max() - v.min() + 1)))
    top = p["top"]
    hidden = {int(k) for k in np.unique(np.nonzero(bar & panel)[1])}  # columns where the bar covers the top
    assert hidden and top["columns"] == len(set(u.tolist()) - hidden)
    assert top["x"][0] == pytest.approx(0.2, abs=0.04) and top["x"][1] == pytest.approx(0.6, abs=0.04)
    assert 1.6 - 4.0 / 120 <= top["z"][0] <= top["z"][1] <= 1.6
    assert 5 <= square.sum() < 40 and pieces(depth, cam, (-0.25, 4.0), 0.4, (0.08, 2.15)) == []

"""The fast path: reduced resolution, sparse iterations and warm starts, against the exact path
and the NumPy reference."""

import dataclasses
import math

import numpy as np
import pytest

from dpom_warp import reference as ref
from dpom_warp.config import ConfigError
from dpom_warp.loading import load_config
from dpom_warp.engine import Engine
from dpom_warp.kernels import PRUNED
from dpom_warp.geometry import Camera, Grid, ObjectBox, pose_from_angles
from dpom_warp.resolution import (AUTO_MIN_PIXELS, REDUCERS, auto_stride, farthest_object_pixels,
                                  reduce_depth, strided_camera)

from scenes import random_scene
from paths import CONFIGS

DEMO = CONFIGS / "demo_people.yaml"

# The stated bound of the sparse path (model.sparse_epsilon = eps, with the pruning bound):
# rho* moves by at most eps from the exact path's on the random test scenes (measured: 0.41 eps
# at most over 20 scenes, eps 1e-5 to 1e-3; 0.65 eps with the pruning bound over 12), and by at
# most 20 eps on rendered people frames (measured 11 eps on the demo at stride 4). `python -m
# bench` prints the distance on its scenes.
BOUND_RANDOM = 1.0
BOUND_RENDERED = 20.0


def reduce_loop(depth, s, how, z_max=np.inf, min_share=0.25):
    """reduce_depth, one block at a time."""
    h, w = depth.shape[0] // s, depth.shape[1] // s
    out = np.zeros((h, w), np.float32)
    for v in range(h):
        for u in range(w):
            block = depth[v * s:(v + 1) * s, u * s:(u + 1) * s]
            if how == "nearest":
                out[v, u] = block[s // 2, s // 2]
                continue
            vals = np.sort(block[(block > 0) & (block <= z_max)].ravel())
            if len(vals) < max(1, int(np.ceil(min_share * s * s))):
                continue
            out[v, u] = vals[0] if how == "min" else vals[(len(vals) - 1) // 2]
    return out


@pytest.mark.parametrize("how", REDUCERS)
@pytest.mark.parametrize("stride", [2, 3, 4, 5, 6, 8])
@pytest.mark.parametrize("network_max", [0, 64])  # every block sorted by np.sort / by the network
def test_reduce_depth_matches_block_loop(how, stride, network_max, rng):
    depth = rng.uniform(0.5, 9.0, (37, 43)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.4] = 0  # many holes: some blocks fall under min_share
    depth[rng.random(depth.shape) < 0.2] = 3.0  # ties
    depth[rng.random(depth.shape) < 0.05] = 12.0  # beyond z_max: missing
    depth[:8, :8] = 0  # a whole block without readings at every stride
    got = reduce_depth(depth, stride, how, z_max=10.0, network_max=network_max)
    want = reduce_loop(depth, stride, how, z_max=10.0)
    assert got.shape == (37 // stride, 43 // stride)
    np.testing.assert_array_equal(got, want)
    if how != "nearest":
        assert (got == 0).any() and (got > 0).any()
    both = reduce_depth(np.stack([depth, depth[::-1].copy()]), stride, how, z_max=10.0, network_max=network_max)
    np.testing.assert_array_equal(both[1], reduce_loop(depth[::-1], stride, how, 10.0))


def ragged_depth(rng, shape):
    """Depth frames with what a reduction must get right: holes (some blocks below the readings
    a median needs, one block with none), ties, readings beyond z_max = 10 m."""
    depth = rng.uniform(0.5, 9.0, shape).astype(np.float32)
    depth[rng.random(depth.shape) < 0.4] = 0
    depth[rng.random(depth.shape) < 0.2] = 3.0
    depth[rng.random(depth.shape) < 0.05] = 12.0
    depth[..., :8, :8] = 0
    return depth


@pytest.mark.parametrize("how", REDUCERS)
def test_reduce_frames_kernel_matches_reduce_depth(device, how, rng):
    """kernels.frames.reduce_frames (the engine's reduction on a GPU) gives
    resolution.reduce_depth's frames bit for bit: strides 2 to 8, a finite and an infinite
    z_max, two frames in one launch."""
    import warp as wp

    from dpom_warp import kernels as K
    from dpom_warp.resolution import min_readings

    depth = ragged_depth(rng, (2, 37, 43))
    full = wp.array(depth, dtype=wp.float32, device=device)
    for stride in (2, 3, 4, 5, 6, 8):
        for z_max in (10.0, np.inf):
            out = wp.zeros((2, 37 // stride, 43 // stride), dtype=wp.float32, device=device)
            wp.launch(K.reduce_frames, dim=out.shape, device=device,
                      inputs=[full, stride, K.frames.HOW[how], z_max, min_readings(stride), out])
            want = reduce_depth(depth, stride, how, z_max=z_max)
            np.testing.assert_array_equal(out.numpy(), want, err_msg=f"stride {stride}, z_max {z_max}")
            if how != "nearest":
                assert (want == 0).any() and (want > 0).any()


@pytest.mark.parametrize("on_device", [False, True])
def test_engine_takes_full_resolution_frames(device, on_device, rng):
    """An engine with a stride takes frames at the camera's full resolution (what a run and the
    API pass) and reduces them itself: by kernels.frames where asked (a GPU's default; on the
    CPU here by setting it), else by NumPy. Its frames, and so its rho, are those of the frames
    reduced beforehand; a frame of neither shape is refused, naming both."""
    from conftest import assert_same_sums
    from dpom_warp.resolution import Resolution

    geom, params, depth, _ = random_scene(4)
    s = 3
    full = np.repeat(np.repeat(depth, s, 0), s, 1)
    full = np.pad(full, ((0, 2), (0, 1)))  # a full-resolution size the stride does not divide
    jitter = rng.random(full.shape) < 0.3
    full[jitter] += rng.normal(0.0, 0.02, jitter.sum()).astype(np.float32) * (full[jitter] > 0)
    full[rng.random(full.shape) < 0.1] = 0  # dropouts
    frames = np.stack([full, full[:, ::-1]])
    resolution = Resolution(stride=s, reduce="median", z_max=8.0)
    engine = Engine(geom, params, device, batch=2, resolution=resolution)
    view = engine.views[0]
    view.reduce_on_device = on_device if device == "cpu" else view.reduce_on_device
    assert view.reduce_on_device == (on_device or device != "cpu")
    small = resolution.frames(frames)
    assert small.shape[1:] == depth.shape and not np.array_equal(small[0], depth)
    got = engine.infer_batch(frames)
    np.testing.assert_array_equal(engine.views[0].depth.numpy(), small)
    want = Engine(geom, params, device, batch=2, resolution=resolution).infer_batch(small)
    for a, b in zip(got, want):
        assert a.entries == b.entries > 0
        assert_same_sums(a.rho, b.rho, device)
    with pytest.raises(ValueError, match=r"H, W = 40, 48 \(or a full-resolution frame at stride 3\), found \(1, 40, 47\)"):
        engine.infer(depth[:, :-1])


def test_sorting_networks_sort(rng):
    """resolution.sorting_network(n) sorts any n keys (ties and +inf included) as np.sort does,
    for every block size a stride up to 8 gives and the sizes between."""
    from dpom_warp.resolution import sort_rows, sorting_network

    for n in range(1, 65):
        keys = rng.integers(0, 6, (n, 200)).astype(np.float32)
        keys[rng.random(keys.shape) < 0.3] = np.inf
        want = np.sort(keys, axis=0)
        np.testing.assert_array_equal(sort_rows(keys.copy(), network_max=64), want)
        assert all(0 <= a < b < n for a, b in sorting_network(n))


@pytest.mark.parametrize("stride", [2, 3, 4])
def test_strided_camera_rays_pass_through_block_centres(stride):
    cam = Camera(64, 50, 55.0, 57.0, 31.2, 24.9, pose_from_angles(2.0, 20.0, 3.0, 5.0),
                 distortion=(-0.2, 0.05, 0.001, -0.001, 0.0))
    small = strided_camera(cam, stride)
    assert (small.width, small.height) == (64 // stride, 50 // stride)
    uu, vv = np.meshgrid(np.arange(small.width), np.arange(small.height))
    x, y = cam.normalised(stride * uu + (stride - 1) / 2, stride * vv + (stride - 1) / 2)
    want = np.stack([x, y, np.ones_like(x)], -1) @ cam.R_wc.T
    np.testing.assert_allclose(small.rays(), want, rtol=0, atol=1e-12)


def test_auto_stride_keeps_enough_pixels_on_the_farthest_object():
    cfg = load_config(str(DEMO))
    px = farthest_object_pixels(cfg.camera, cfg.grid, cfg.obj)
    assert 20 < px < 23  # the 0.4 m solid at ~7 m with fx = 365
    s = auto_stride(cfg.camera, cfg.grid, cfg.obj)
    assert s == 3 and px / s >= AUTO_MIN_PIXELS > px / (s + 1)
    near = Grid(x=(-1, 1, 0.1), y=(1.0, 2.0, 0.1))  # close by: objects are big
    far = Grid(x=(-1, 1, 0.1), y=(1.0, 30.0, 0.5))  # far away: full resolution
    assert auto_stride(cfg.camera, near, cfg.obj) == 8
    assert auto_stride(cfg.camera, far, cfg.obj) == 1
    small = Camera(40, 30, 30.0, 30.0, 19.5, 14.5, cfg.camera.T_world_from_camera)
    assert auto_stride(small, near, ObjectBox(0.5, 1.8)) == 1  # never below 16 pixels a side


def test_config_stride_reduce_and_exact(tmp_path):
    cfg = load_config(str(DEMO))
    assert cfg.inputs.stride == "auto" and cfg.inputs.reduce == "median" and cfg.engine.batch == "auto"
    assert cfg.model.sparse_epsilon == 1e-4 and not cfg.model.warm_start
    exact = load_config(str(DEMO), ["engine.exact=true", "input.stride=3",
                                                     "model.warm_start=true"])
    assert exact.inputs.stride == 1 and exact.model.sparse_epsilon == 0 and not exact.model.warm_start
    assert load_config(str(DEMO), ["model.sparse_epsilon=1e-6"]).model.sparse_epsilon == 1e-6
    for sets, message in [(["input.stride=fast"], "input.stride: expected auto or an integer >= 1, found 'fast'"),
                          (["input.stride=0"], "input.stride: expected a value >= 1, found 0"),
                          (["engine.batch=0"], "engine.batch: expected a value >= 1, found 0"),
                          (["engine.batch=many"], "engine.batch: expected auto or an integer >= 1, found 'many'"),
                          (["input.reduce=mean"], "input.reduce: expected one of median, nearest, min, found 'mean'"),
                          (["model.sparse_epsilon=-1"], "model.sparse_epsilon: expected a value >= 0, found -1")]:
        with pytest.raises(ConfigError) as e:
            load_config(str(DEMO), sets)
        assert str(e.value) == f"--set {sets[0]}: {message}"  # blamed on the --set, not the file


def check_bound_against_reference(device, seed, shape, step=0.3, behind_cost=0.0):
    """The pruning bound's kernels, with the global scratch and with the stack's in one size
    and in three (CPU), equal reference.evidence_bound (with `behind_cost`, its readings-behind
    term: the counts of every location in a list); returns the per-pixel list lengths."""
    from dpom_warp.kernels.mean_field import ONE_STACK, SIZED_STACK

    geom, params, depth, bg_frames = random_scene(seed, shape=shape, step=step)
    params = params.replace(sparse_epsilon=1e-3, bound_rounds=1 + seed % 3, behind_cost=behind_cost,
                                 behind_side=0.2, behind_low=0.3)
    valid, L, D, dbg, _ = ref.pixel_lists(depth, geom, ref.background_from_frames(bg_frames, params), params)
    start = np.random.default_rng(seed).uniform(0, 2 * params.prior, len(geom.rect))  # a warm start
    behind = ref.behind_evidence(depth, geom, params, valid, L)
    want = ref.evidence_bound(valid, L, D, dbg, start, params, behind)
    if behind_cost > 0:  # not vacuous: the term prunes a location the bound alone keeps
        alone = ref.evidence_bound(valid, L, D, dbg, start, params)
        assert ((want < params.sparse_epsilon) & (alone >= params.sparse_epsilon)).any()
    if params.bound_rounds > 1:  # not vacuous: the last round starts with settled locations
        before = ref.evidence_bound(valid, L, D, dbg, start, params.replace(
            bound_rounds=params.bound_rounds - 1), behind)
        assert ((before < params.sparse_epsilon) & (before <= start)).sum() > 10
    for local in (0, ONE_STACK, SIZED_STACK):
        engine = Engine(geom, params, device)
        engine.local_scratch = local
        engine.set_background_frames(bg_frames)
        engine.build_lists(depth)
        lengths = engine.views[0].lists.counts.numpy().copy()
        engine.rho.assign(start)
        engine.done.zero_()
        engine.prune(math.log(params.prior) - math.log1p(-params.prior))
        np.testing.assert_allclose(engine.upper.numpy(), want, rtol=1e-6, atol=1e-12)
        pruned = engine.live.numpy() == PRUNED
        np.testing.assert_array_equal(pruned, want < params.sparse_epsilon)
        assert 0 < pruned.sum() < len(pruned)
        assert (engine.rho.numpy()[pruned] == 0).all()
    return lengths


@pytest.mark.parametrize("behind_cost", [0.0, 3.0])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(4))
def test_pruning_bound_kernel_matches_reference(device, seed, shape, behind_cost):
    check_bound_against_reference(device, seed, shape, behind_cost=behind_cost)


def test_pruning_bound_stack_scratch_of_every_size(device):
    """On a 0.06 m grid the lists fill every stack size of the bound pass and the global
    scratch; both paths still equal the reference."""
    from dpom_warp.kernels.mean_field import LOCAL_ENTRIES, LOCAL_MEDIUM, LOCAL_SHORT

    lengths = check_bound_against_reference(device, 2, "plane", step=0.06)
    tiers = np.digitize(lengths[lengths > 0], [LOCAL_SHORT + 1, LOCAL_MEDIUM + 1, LOCAL_ENTRIES + 1])
    assert set(tiers) == {0, 1, 2, 3}, np.bincount(tiers)


@pytest.mark.parametrize("behind_cost", [0.0, 3.0])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(6))
def test_pruning_bound_holds_at_every_iteration_of_the_exact_path(seed, shape, behind_cost):
    """The bound's promise (reference.evidence_bound): from the start, no iteration's rho_new
    exceeds it, whatever the other locations do; so a location pruned (bound < epsilon) never
    reaches epsilon. With model.behind_cost the bound subtracts the readings behind each
    location, as every update does."""
    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    params = params.replace(behind_cost=behind_cost, behind_side=0.2, behind_low=0.3)
    bg = ref.background_from_frames(bg_frames, params)
    valid, L, D, dbg, _ = ref.pixel_lists(depth, geom, bg, params)
    params = params.replace(bound_rounds=4)
    behind = ref.behind_evidence(depth, geom, params, valid, L)
    upper = ref.evidence_bound(valid, L, D, dbg, np.full(len(geom.rect), params.prior), params, behind)
    trace = []
    ref.mean_field(depth, geom, bg, params.replace(sparse_epsilon=0.0), trace=trace)
    assert len(trace) > 10
    assert max((rho_new - upper).max() for rho_new in trace) <= 1e-12
    assert (upper < 1e-3).sum() > len(upper) // 4  # not vacuous: it prunes
    assert (upper > 0.5).any()  # and it is not a guess: some can rise


@pytest.mark.parametrize("graph", [None, True])  # the device's default; the loop as a graph (CUDA's default)
@pytest.mark.parametrize("streak", [1.0, 1.1])  # model.damping_streak: off, and on (cap 0.6)
@pytest.mark.parametrize("seed", range(4))
def test_sparse_path_matches_sparse_reference(device, seed, streak, graph):
    geom, params, depth, bg_frames = random_scene(seed)
    params = params.replace(sparse_epsilon=1e-3, damping_streak=streak, damping_streak_max=0.6)
    engine = Engine(geom, params, device, graph=graph)
    engine.set_background_frames(bg_frames)
    want = ref.mean_field(depth, geom, ref.background_from_frames(bg_frames, params), params)
    got = engine.infer(depth)
    assert got.iterations == want["iterations"] and got.live == want["live"]
    assert got.pruned == want["pruned"] > 0 and got.kept_entries < got.entries
    assert got.live < len(geom.rect) // 2, "nothing was dropped: the sparse path is not exercised"
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    # the passes over the lists ran over the pixels with entries after the pruning, all of them
    # (their count as the device wrote it: a loop captured as a graph, CUDA's default, reads
    # nothing back, and launches over every pixel)
    held = np.flatnonzero(engine.views[0].lists.counts.numpy())
    n_listed = int(engine.views[0].n_listed_out.numpy()[0])
    assert engine.views[0].n_listed == (None if engine.graph else n_listed)
    listed = engine.views[0].listed.numpy()[:n_listed]
    assert 0 < n_listed < engine.views[0].n_pixels
    np.testing.assert_array_equal(np.sort(listed), held)
    if device == "cpu":
        np.testing.assert_array_equal(listed, held)  # in pixel order: the sums' order


def test_direct_launches_give_warps_launches_results():
    """A Launcher on the CPU calls the iteration's kernels through argument blocks it keeps
    (engine.launch._direct): the same rho and rho*, bit for bit, as Warp's Launch.launch, frame after
    frame with other depths, a batch and lists that grow (new arrays in the blocks); and an
    engine switched to a graph afterwards replays what Warp's launches give."""
    geom, params, depth, bg_frames = random_scene(3, shape="solid")
    params = params.replace(sparse_epsilon=1e-3)
    rng = np.random.default_rng(7)
    frames = [depth, np.where(rng.random(depth.shape) < 0.1, 0.0, depth * 0.97), depth[::-1].copy()]
    got = {}
    for direct in (True, False):
        engine = Engine(geom, params, "cpu", batch=2)
        engine.direct_launch = direct
        engine.set_background_frames(bg_frames)
        engine.views[0]._allocate_lists(16)  # grown by the first frame: the blocks see new arrays
        got[direct] = [engine.infer(f) for f in frames] + engine.infer_batch(np.stack(frames[:2]))
        used = [rec.direct is not None for launcher in engine.launchers() for rec in launcher.recorded.values()]
        assert all(used) if direct else not any(used)
        assert engine.grown
        if direct:  # the loop captured as a graph after direct launches: each launch recorded
            engine.graph = True
            got[direct].append(engine.infer(frames[0]))
            got[direct].append(engine.infer(frames[0]))  # replayed
            assert not any(rec.direct is not None for launcher in engine.launchers()
                           for rec in launcher.recorded.values())
        else:
            got[direct] += [got[direct][0], got[direct][0]]
    for a, b in zip(got[True], got[False]):
        np.testing.assert_array_equal(a.rho, b.rho)
        np.testing.assert_array_equal(a.rho_star, b.rho_star)
        assert a.iterations == b.iterations


@pytest.mark.parametrize("eps", [1e-3, 1e-4])
@pytest.mark.parametrize("seed", range(8))
def test_sparse_path_stays_within_bound_of_exact(seed, eps):
    geom, params, depth, bg_frames = random_scene(seed)
    engine = Engine(geom, params.replace(sparse_epsilon=eps), "cpu")
    exact = Engine(geom, params.replace(sparse_epsilon=0.0), "cpu")
    for e in (engine, exact):
        e.set_background_frames(bg_frames)
    fast, slow = engine.infer(depth), exact.infer(depth)
    assert slow.live == len(geom.rect) and slow.pruned == 0 and fast.pruned > 0
    assert np.abs(fast.rho_star - slow.rho_star).max() <= BOUND_RANDOM * eps
    assert np.abs(fast.rho - slow.rho).max() <= BOUND_RANDOM * eps


def test_sparse_path_within_bound_on_rendered_people(tmp_path):
    """Rendered people at 128x106 (tests/test_cli's small scene): the sparse path's rho* within
    BOUND_RENDERED eps of the exact path's, and the same detections."""
    from dpom_warp.detect import detect
    from dpom_warp.geometry import build_geometry
    from dpom_warp.sources import expand
    from dpom_warp.worker import make_engine, read_frame
    from dpom_warp.synthetic import generate

    from test_cli import small_config

    cfg = load_config(small_config(tmp_path))
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    frames = [read_frame(cfg, f) for f in expand(cfg.inputs.frames, "input.frames")]
    bg = np.stack([read_frame(cfg, f) for f in expand(cfg.inputs.background, "input.background")])
    geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    eps = cfg.model.sparse_epsilon
    engines = []
    for e in (0.0, eps):
        c = dataclasses.replace(cfg, model=cfg.model.replace(sparse_epsilon=e))
        engine = make_engine(c, cfg.camera, "cpu", 1)
        engine.set_background_frames(engine.resolution.frames(bg))
        engines.append(engine)
    for depth in frames:
        slow, fast = (e.infer(e.resolution.frames(depth)) for e in engines)
        assert fast.live < 0.5 * len(geom.rect)
        assert np.abs(fast.rho_star - slow.rho_star).max() <= BOUND_RENDERED * eps
        found = [detect(r.rho_star.reshape(cfg.grid.shape), geom.locations, geom.rect, 0.5, 0.4)
                 for r in (slow, fast)]
        # the same people, each at most one cell apart: rho* of neighbouring cells on a person
        # can tie at 1 within the bound above, and then either is the maximum
        a, b = (geom.locations[[d.k for d in f], :2] for f in found)
        gap = np.abs(a[:, None] - b[None]).max(-1)  # cells apart, each axis (Chebyshev)
        cell = max(cfg.grid.x[2], cfg.grid.y[2]) + 1e-9
        assert len(a) == len(b) > 0 and gap.min(1).max() <= cell and gap.min(0).max() <= cell


def test_mask_index_option_gives_the_same_results(tmp_path):
    """engine.mask_index: the run's engine takes the pixel table with a solid on auto, the
    tiles when told (and with facing planes), and both give the same rho* on rendered people;
    an unknown index is a one-line config error."""
    from dpom_warp.sources import expand
    from dpom_warp.worker import make_engine, read_frame
    from dpom_warp.synthetic import generate

    from test_cli import small_config

    cfg = load_config(small_config(tmp_path))
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    depth = read_frame(cfg, expand(cfg.inputs.frames, "input.frames")[0])
    results = {}
    for index, want in [("auto", True), ("table", True), ("tiles", False)]:
        c = dataclasses.replace(cfg, engine=cfg.engine.model_copy(update={"mask_index": index}))
        engine = make_engine(c, cfg.camera, "cpu", 1)
        assert engine.views[0].use_table == want
        results[index] = engine.infer(engine.resolution.frames(depth))
    assert results["auto"].entries > 1000
    for index in ("table", "tiles"):
        np.testing.assert_array_equal(results[index].rho_star, results["auto"].rho_star)
    plane = dataclasses.replace(cfg, obj=cfg.obj.model_copy(update={"shape": "plane"}))
    assert not make_engine(plane, cfg.camera, "cpu", 1).views[0].use_table
    with pytest.raises(ConfigError) as e:
        load_config(small_config(tmp_path), ["engine.mask_index=grid"])
    assert "engine.mask_index: expected one of auto, table, tiles, found 'grid'" in str(e.value)


def test_warm_start_starts_from_the_previous_frame_capped_at_the_prior(device):
    geom, params, depth, bg_frames = random_scene(2)
    params = params.replace(warm_start=True)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    bg = ref.background_from_frames(bg_frames, params)
    first = engine.infer(depth)
    np.testing.assert_allclose(first.rho, ref.mean_field(depth, geom, bg, params)["rho"], atol=1e-6)
    second_depth = np.roll(depth, 2, axis=1)
    second = engine.infer(second_depth)
    start = np.minimum(first.rho, params.prior)
    want = ref.mean_field(second_depth, geom, bg, params, start=start)
    np.testing.assert_allclose(second.rho, want["rho"], rtol=0, atol=1e-6)
    cold = ref.mean_field(second_depth, geom, bg, params.replace(warm_start=False))
    assert np.abs(cold["rho"] - want["rho"]).max() > 1e-9  # the start really differs


def test_the_engine_takes_a_list_of_cameras_and_keeps_each_cameras_launches_its_own():
    """Engine takes a list of cameras' geometries over one grid (one today): a list of one gives
    bit for bit what the geometry alone gives, the per-pixel state lives in the camera's view
    and the per-location state once in the engine; a kernel given a camera's arrays is launched
    through that camera's Launcher, the engine's own launches take none of them; a rig's cameras
    must see one grid, and its frames come as a list (one-line errors)."""
    import warp as wp

    geom, params, depth, bg_frames = random_scene(5, shape="solid")
    params = params.replace(sparse_epsilon=1e-3)
    got = []
    for given in (geom, [geom]):
        engine = Engine(given, params, "cpu")
        engine.set_background_frames(bg_frames)
        got.append(engine.infer(depth))
    np.testing.assert_array_equal(got[0].rho, got[1].rho)
    np.testing.assert_array_equal(got[0].rho_star, got[1].rho_star)
    assert got[0].iterations == got[1].iterations and got[0].entries == got[1].entries > 0
    (view,) = engine.views
    L, P = len(geom.rect), depth.size
    assert view.lists.counts.shape == (P,) and view.bg.shape == (P, 4) and view.depth.shape == (1,) + depth.shape
    assert engine.rho.shape == engine.evidence.shape == engine.live.shape == (L,)
    np.testing.assert_array_equal(engine.area.numpy(), geom.area)  # one camera: its silhouettes' area
    owned = {id(a) for a in vars(view).values() if isinstance(a, wp.array) or hasattr(a, "_cls")}
    owned |= {id(a) for s in (view.lists, view.compact_lists) for a in (s.counts, s.offsets, s.loc, s.delta)}
    engine_inputs = [x for rec in engine._launch.recorded.values() for x in rec.inputs]
    assert engine.launchers()[0].recorded and not any(id(x) in owned for x in engine_inputs)
    assert view.launch.recorded and all(any(id(x) in owned for x in rec.inputs)
                                        for rec in view.launch.recorded.values())
    other, *_ = random_scene(6, shape="solid", step=0.25)  # another grid
    with pytest.raises(ValueError, match=r"^cameras\[1\]: expected the grid's \d+ locations of cameras\[0\]") as err:
        Engine([geom, other], params, "cpu")
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r"^depth: expected a list of 2 frames, one a camera of the rig"):
        Engine([geom, geom], params, "cpu").infer(depth)


def test_the_people_tests_are_a_prior_the_engine_is_given():
    """An engine given people.Prior (nothing added to the mean field) gives bit for bit what the
    default people.PeoplePrior gives with the people-only tests off (behind_cost 0, top_support
    0, no shorter bands, no joint lists); with them on, the default prior counts readings behind,
    where the plain prior counts none, and they push rho down (the tests are exercised)."""
    from dpom_warp.engine import PeoplePrior, Prior

    geom, params, depth, bg_frames = random_scene(3, shape="solid")
    people = params.replace(sparse_epsilon=1e-3, behind_cost=3.0, behind_low=0.3, behind_step=1, top_support=0.3,
                            top_heights=(0.8 * geom.height,))
    off = people.replace(behind_cost=0.0, top_support=0.0, top_heights=())
    got = {}
    for name, p, prior in (("plain", people, Prior(people)), ("off", off, None), ("on", people, None),
                           ("given", people, PeoplePrior(people))):
        engine = Engine(geom, p, "cpu", prior=prior)
        engine.set_background_frames(bg_frames)
        engine.joint_threshold = 0.5 if name != "off" else None
        got[name] = (engine.infer(depth), engine.prior.n_behind.numpy().copy())
    plain, off_, on, given = (got[k][0] for k in ("plain", "off", "on", "given"))
    np.testing.assert_array_equal(plain.rho_star, off_.rho_star)
    np.testing.assert_array_equal(plain.rho, off_.rho)
    assert plain.iterations == off_.iterations and plain.joint is None and off_.joint is None
    assert not got["plain"][1].any() and got["on"][1].max() > 0
    assert (on.rho < plain.rho - 1e-6).any() and on.joint is not None  # readings behind push rho down
    np.testing.assert_array_equal(on.rho_star, given.rho_star)  # the default is the params' PeoplePrior

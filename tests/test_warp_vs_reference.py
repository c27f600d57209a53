"""The Warp kernels against the plain NumPy reference, on random small scenes, every device."""


import numpy as np
import pytest

from conftest import assert_same_sums, assert_top_counts
from dpom_warp import reference as ref
from dpom_warp.engine import Engine
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
from dpom_warp.model import ModelParams

from scenes import random_scene


@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("path", ["exact", "sparse"])
@pytest.mark.parametrize("seed", range(6))
def test_rho_matches_reference(device, seed, path, shape):
    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4)
    engine = Engine(geom, params, device)
    use_frames = seed % 2 == 0
    if use_frames:
        engine.set_background_frames(bg_frames)
        bg = ref.background_from_frames(bg_frames, params)
    else:
        bg = ref.floor_background(geom, params, depth)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    assert want["entries"] > 100, "scene too easy: no mask entries"
    assert got.entries == want["entries"]
    assert got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.evidence_share, want["evidence_share"], rtol=0, atol=1e-9)
    assert np.all((got.rho >= 0) & (got.rho <= 1)) and np.all(np.isfinite(got.rho))
    assert got.rho.max() > 0.5, "no location became occupied: the comparison is not exercised"


def lists_as_entries(engine):
    """(pixel, loc, mu, delta) of the engine's lists, in list order."""
    counts, offsets = engine.views[0].lists.counts.numpy(), engine.views[0].lists.offsets.numpy()
    order = np.concatenate([np.arange(o, o + c) for o, c in zip(offsets, counts) if c])
    pixel = np.repeat(np.arange(len(counts)), counts)
    return (pixel, engine.views[0].lists.loc.numpy()[order], engine.views[0].lists.mu.numpy()[order],
            engine.views[0].lists.delta.numpy()[order])


def distorted_voxel_scene(seed, shape="plane"):
    """A rolled camera with lens distortion over a voxel grid whose first rows reach under and
    behind the camera, random readings, and a background that occludes some voxels; with
    shape 'solid', discs seen from below, beside and above."""
    rng = np.random.default_rng(seed)
    cam = Camera(56, 44, 40.0, 41.0, 27.0, 22.5, pose_from_angles(1.6, 25.0, 5.0, 10.0),
                 distortion=(-0.25, 0.08, 0.001, -0.002, -0.01))
    grid = Grid(x=(-1.5, 1.5, 0.25), y=(-0.5, 4.0, 0.25), mode="voxel", z=(0.2, 2.0, 0.3))
    geom = build_geometry(cam, grid, ObjectBox(0.3, 0.2, shape=shape, height_spread=0.03))
    params = ModelParams(sigma_object=0.05, background_occludes=True)
    depth = (rng.uniform(0.5, 5.0, (44, 56)) * (rng.random((44, 56)) > 0.05)).astype(np.float32)
    return geom, params, depth


@pytest.mark.parametrize("one_pass", [False, True])
@pytest.mark.parametrize("tile", [1, 5, 8, 64, "table"])
def test_sorted_lists_match_reference(device, tile, one_pass):
    """The static index (the tile index whatever the tile, or the pixel table) finds exactly
    the reference's masks, in its order, with the lists built in two passes (count, scan,
    fill) or in one (the CPU's)."""
    table = tile == "table"
    seed = 3 if table else tile
    for geom, params, depth, bg in [random_scene(11)[:3] + (None,), distorted_voxel_scene(seed) + (None,),
                                    random_scene(11 + seed, shape="solid")[:3] + (None,),
                                    distorted_voxel_scene(seed, "solid") + (None,)]:
        engine = Engine(geom, params, device, tile=8 if table else tile, table=table)
        assert engine.views[0].use_table == table and (engine.views[0].n_table > 0) == table
        engine.one_pass_lists = one_pass
        if params.background_occludes:
            frames = np.stack([np.roll(depth, 3 * i, axis=1) for i in range(3)])
            engine.set_background_frames(frames)
            bg = ref.background_from_frames(frames, params)
        total = engine.build_lists(depth)
        want = ref.mask_entries(depth, geom, params, bg)
        assert total == len(want[0]) > 100
        got = lists_as_entries(engine)
        for a, b in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(got[3], want[3], rtol=1e-6, atol=1e-6)


def test_pixel_table_window_matches_reference(device):
    """The pixel table's walk keys (kernels.masks.table_window) equal the reference's, are
    monotonic along each pixel's pairs, and bracket every pair: a reading that passes a pair's
    test lies inside the window the keys give, so the walk misses no entry."""
    geom, params, depth, _ = random_scene(7, shape="solid")
    engine = Engine(geom, params, device, table=True)
    t = engine.views[0].table
    start, pair, key = t.start.numpy(), t.pair.numpy(), t.key.numpy()
    assert len(pair) > 1000
    np.testing.assert_array_equal(key, ref.table_window(start, pair["mu"], pair["half"]))
    half = pair["half"].astype(np.float64)
    assert np.all(key[:, 0] >= pair["mu"] + half) and np.all(key[:, 1] <= pair["mu"] - half)
    same = np.repeat(np.arange(len(start) - 1), np.diff(start))
    along = same[1:] == same[:-1]  # consecutive pairs of one pixel
    assert np.all(np.diff(key[:, 0])[along] >= 0) and np.all(np.diff(key[:, 1])[along] >= 0)


def test_background_kernels_match_reference(device):
    geom, params, depth, frames = random_scene(3)
    frames[:, :5, :5] = 0  # never a reading: broad distribution
    engine = Engine(geom, params, device)
    want = ref.floor_background(geom, params)
    got = engine.background()
    for name in ("mu", "sigma", "missing", "outlier"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-12, atol=1e-12)
    engine.set_background_frames(frames)
    want = ref.background_from_frames(frames, params)
    got = engine.background()
    for name in ("mu", "sigma", "missing", "outlier"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-6, atol=1e-6,
                                   err_msg=name)
    assert np.all(got.outlier[:5, :5] == 1.0)
    np.testing.assert_allclose(engine.views[0].delta_bg.numpy().size, depth.size)


@pytest.mark.parametrize("outside", [False, True])  # the floor-only model completed from each frame or not
def test_background_delta_follows_every_change_of_background(device, outside):
    """Delta_bg (kernels.background_delta keeps the background's logarithms from frame to
    frame) equals the reference on the engine's background of the moment, frame after frame,
    after each way of setting it: frames, the floor-only model, a given distribution, frames
    again."""
    from dpom_warp.model import Background

    geom, params, depth, frames = random_scene(3)
    params = params.replace(background_outside_grid=outside)
    engine = Engine(geom, params, device)
    given = ref.background_from_frames(frames[::-1] * 1.05, params)
    given = Background(mu=given.mu, sigma=2 * given.sigma, missing=np.full_like(given.missing, 0.2),
                       outlier=np.clip(given.outlier, 0.05, 1.0))
    before = None
    for setting in ("frames", "floor", "given", "frames"):
        if setting == "frames":
            engine.set_background_frames(frames)
        elif setting == "floor":
            engine.set_floor_background()
        else:
            engine.set_background(given)
        for frame in (depth, np.roll(depth, 5, axis=1) * 1.1):
            engine.build_lists(frame)
            got = engine.views[0].delta_bg.numpy().copy()  # (on the CPU a view of the engine's array)
            want = ref.background_delta(frame, engine.background(), params).ravel()
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
            assert before is None or not np.array_equal(got, before)
            before = got


def test_a_reading_at_exactly_0_and_z_max(device):
    """MODEL.md: the sensor's range is (0, z_max]; 0 is no reading. A pixel reading exactly z_max
    is a reading (its Delta_bg is the background's density there, not the missing term); one
    reading the next float32 above z_max counts as no reading, as 0 does; the kernel and the
    reference agree at each. By hand: with the background's mu at z_max, the pixel at z_max is
    the most likely reading there, so its Delta_bg is above the no-reading pixels'."""
    from dpom_warp.model import Background

    geom, params, depth, frames = random_scene(4)
    h, w = depth.shape
    z_max = np.float32(params.z_max)
    assert float(z_max) == params.z_max  # representable: the frame holds z_max exactly
    bg = Background(mu=np.full((h, w), float(z_max)), sigma=np.full((h, w), 0.05), missing=np.full((h, w), 0.1),
                    outlier=np.full((h, w), 0.05))
    engine = Engine(geom, params, device)
    engine.set_background(bg)
    frame = np.zeros((h, w), np.float32)
    frame[:, 1::4] = z_max
    frame[:, 2::4] = np.nextafter(z_max, np.float32(np.inf))
    frame[:, 3::4] = z_max - np.float32(0.5)
    engine.build_lists(frame)
    got = engine.views[0].delta_bg.numpy().reshape(h, w)
    np.testing.assert_allclose(got, ref.background_delta(frame, bg, params), rtol=1e-12, atol=1e-12)
    none, at_max, beyond, inside = got[:, 0::4], got[:, 1::4], got[:, 2::4], got[:, 3::4]
    np.testing.assert_array_equal(beyond, none)  # beyond z_max: no reading, as 0
    assert (at_max > none).all() and (at_max > inside).all()  # z_max itself: a reading, the likeliest
    assert ref.valid_reading(np.array([0.0, z_max, np.nextafter(z_max, np.float32(np.inf))]), params).tolist() == [
        False, True, False]


def test_lists_longer_than_the_one_pass_buffer(device):
    """Pixels with more entries than pixel_entries_once keeps on its stack are filled by the
    two-pass kernel, alone; the lists are the reference's either way."""
    from dpom_warp.kernels.masks import LOCAL_MATCHES

    geom, params, depth, _ = random_scene(4)
    geom = build_geometry(Camera(24, 20, 20.0, 20.0, 11.5, 9.5, pose_from_angles(2.2, 15.0, 0.0)),
                          Grid(x=(-1.5, 1.5, 0.1), y=(1.5, 5.0, 0.1)), ObjectBox(0.5, 1.8))
    params = params.replace(sigma_object=3.0)  # every box claims every reading
    depth = np.random.default_rng(4).uniform(1.0, 6.0, (20, 24)).astype(np.float32)
    want = ref.mask_entries(depth, geom, params, None)
    lists = []
    for one_pass in (False, True):
        for table in (False, True):
            engine = Engine(geom, params, device, entries_per_pixel=1.0, table=table)
            engine.one_pass_lists = one_pass
            assert engine.build_lists(depth) == len(want[0])
            lists.append(lists_as_entries(engine))
    counts = np.bincount(want[0])
    assert counts.max() > LOCAL_MATCHES >= counts[counts > 0].min()  # both kinds of pixel
    for got in lists:
        for a, b in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(got[3], want[3], rtol=1e-6, atol=1e-6)


def test_static_index_choice_and_memory(device):
    """table=None takes the pixel table where it fits the budget and the tiles where it does
    not; memory_bytes counts whichever is held, and both give the same result."""
    from dpom_warp.engine import TABLE_BYTES, TABLE_PIXEL_BYTES, memory_estimate

    geom, params, depth, _ = random_scene(2, shape="solid")
    table = Engine(geom, params, device)
    t = table.views[0]
    assert t.use_table and 0 < t.n_table < geom.rect_area.sum()
    tiles = Engine(geom, params, device, table=False)
    s = tiles.views[0]
    assert not s.use_table and s.n_table == 0 and s.n_pairs > 0
    held = t.n_table * TABLE_BYTES + t.n_pixels * TABLE_PIXEL_BYTES
    assert table.memory_bytes() - held == tiles.memory_bytes() - s.n_pairs * memory_estimate(0, 0, 0, 1)
    # a budget the lists and the tile index fit, but not the pixel table at its largest
    need = tiles.memory_bytes() + geom.rect_area.sum() * TABLE_BYTES // 2
    small = Engine(geom, params, device, memory_gb=need / 2**30)
    assert not small.views[0].use_table
    a, b = table.infer(depth), small.infer(depth)
    assert a.entries == b.entries > 100 and a.iterations == b.iterations
    assert_same_sums(a.rho, b.rho, device)
    assert_same_sums(a.rho_star, b.rho_star, device)


@pytest.mark.parametrize("one_pass", [False, True])
def test_list_capacity_grows_and_is_reported(device, one_pass):
    geom, params, depth, _ = random_scene(5)
    engine = Engine(geom, params, device, entries_per_pixel=0.01)
    engine.one_pass_lists = one_pass
    small = engine.views[0].capacity
    want = ref.mean_field(depth, geom, ref.floor_background(geom, params, depth), params)
    assert want["entries"] > small
    got = engine.infer(depth)
    assert engine.grown == [want["entries"]] and engine.views[0].capacity >= want["entries"]
    np.testing.assert_allclose(got.rho, want["rho"], atol=1e-6)


def test_list_overflow_is_refused_not_truncated(device):
    from dpom_warp.engine import ListOverflow

    geom, params, depth, _ = random_scene(5)
    engine = Engine(geom, params, device, entries_per_pixel=0.01, max_entries=1500)
    with pytest.raises(ListOverflow, match="mask entries"):
        engine.infer(depth)


@pytest.mark.parametrize("outside", [True, False])
def test_floor_background_per_frame_matches_reference(device, outside):

    geom, params, depth, _ = random_scene(8)
    params = params.replace(background_outside_grid=outside)
    engine = Engine(geom, params, device)
    got = engine.infer(depth)
    bg = ref.floor_background(geom, params, depth)
    np.testing.assert_allclose(engine.background().mu, bg.mu, atol=1e-6)
    want = ref.mean_field(depth, geom, bg, params)
    np.testing.assert_allclose(got.rho, want["rho"], atol=1e-6)
    static = (bg.outlier < 1) & (depth > 0) & ~np.isclose(bg.mu, ref.floor_background(geom, params).mu)
    assert static.any() == outside  # the slabs' tops or the far floor are out of every box


def batch_frames(seed, n):
    """n different frames over one random scene's geometry (its depth, shifted and thinned)."""
    geom, params, depth, frames = random_scene(seed)
    rng = np.random.default_rng(seed)
    out = [depth]
    for i in range(1, n):
        d = np.roll(depth, 2 * i, axis=1) * (rng.random(depth.shape) > 0.1 * i)
        out.append(d.astype(np.float32))
    return geom, params, np.stack(out), frames


@pytest.mark.parametrize("graph", [False, True])
def test_batch_gives_each_frame_its_own_result(device, graph):
    """Frames run side by side (and the loop as a replayed graph) stop at their own iteration
    and get exactly what they get alone; a short batch is padded."""
    geom, params, depths, frames = batch_frames(6, 3)  # converging at 28, 26 and 30 iterations alone
    alone = Engine(geom, params, device)
    alone.set_background_frames(frames)
    want = [alone.infer(d) for d in depths]
    assert len({w.iterations for w in want}) > 1, "frames should converge at different iterations"
    engine = Engine(geom, params, device, batch=4, graph=graph)
    engine.set_background_frames(frames)
    calls = []
    for n in (3, 2):
        got = engine.infer_batch(depths[:n])
        calls.append((got, [g.rho.copy() for g in got]))
        assert len(got) == n
        for g, w in zip(got, want):
            assert (g.iterations, g.entries, g.live, g.pruned, g.kept_entries) == (
                w.iterations, w.entries, w.live, w.pruned, w.kept_entries)
            np.testing.assert_allclose(g.rho, w.rho, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g.rho_star, w.rho_star, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g.max_change, w.max_change, rtol=0, atol=1e-12)
    for got, rho in calls:  # a call's results are its own: the next call changes none of them
        for g, r in zip(got, rho):
            np.testing.assert_array_equal(g.rho, r)
    assert not np.shares_memory(calls[0][0][0].rho, calls[1][0][0].rho)


def test_graph_is_recaptured_when_the_lists_grow(device):
    geom, params, depth, _ = random_scene(5)
    want = ref.mean_field(depth, geom, ref.floor_background(geom, params, depth), params)
    engine = Engine(geom, params, device, entries_per_pixel=0.01, graph=True)
    small = engine.infer(np.zeros_like(depth))  # captured with the first, small lists
    assert small.entries == 0 and engine.grown == []
    np.testing.assert_allclose(small.rho, params.prior, rtol=1e-12)  # no reading, no evidence
    got = engine.infer(depth)
    assert engine.grown == [want["entries"]]
    assert got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)


def test_evidence_scratch_on_stack_or_global_agree(device):
    """Every scratch path of the evidence pass (the global array, as on GPUs and for long
    lists; the stack in one size; the stack in three sizes by the list's length) gives the
    reference's result, on a grid fine enough (0.06 m) that lists of every size occur."""
    from dpom_warp.kernels.mean_field import LOCAL_ENTRIES, LOCAL_MEDIUM, LOCAL_SHORT, ONE_STACK, SIZED_STACK

    geom, params, depth, _ = random_scene(2, step=0.06)
    want = ref.mean_field(depth, geom, ref.floor_background(geom, params, depth), params)
    for local in (0, ONE_STACK, SIZED_STACK):
        engine = Engine(geom, params, device)
        engine.local_scratch = local
        got = engine.infer(depth)
        assert got.iterations == want["iterations"]
        np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    lengths = engine.views[0].lists.counts.numpy()
    tiers = np.digitize(lengths[lengths > 0], [LOCAL_SHORT + 1, LOCAL_MEDIUM + 1, LOCAL_ENTRIES + 1])
    assert set(tiers) == {0, 1, 2, 3}, np.bincount(tiers)  # every stack size and the global scratch


@pytest.mark.parametrize("path", ["exact", "sparse", "graph"])
@pytest.mark.parametrize("seed", [0, 2])
def test_exclusion_matches_reference(device, seed, path):
    """model.exclusion (neighbours above the gate push a location's evidence down) on the
    Warp path (full and sparse passes, the loop as a graph) equals the reference, on a scene
    with two objects 0.3 m apart, both occupied without it and one with it."""
    from scenes import draw_slab

    geom, params, depth, bg_frames = random_scene(seed, shape="solid")
    bg = ref.background_from_frames(bg_frames, params)
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4)
    k = int(np.argmax(ref.mean_field(depth, geom, bg, params)["rho"]))
    near = np.linalg.norm(geom.locations - geom.locations[k], axis=1)
    other = int(np.flatnonzero((near > 0.2) & (near < 0.35) & (geom.rect_area > 0))[0])
    draw_slab(depth, geom, other)
    params = params.replace(exclusion=100.0, exclusion_radius=0.45, exclusion_gate=0.2)
    engine = Engine(geom, params, device, graph=path == "graph")
    engine.set_background_frames(bg_frames)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    assert got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    plain = ref.mean_field(depth, geom, bg, params.replace(exclusion=0.0))["rho"]
    assert min(plain[k], plain[other]) > 0.9 and min(want["rho"][k], want["rho"][other]) < 0.1


def test_neighbour_lists_are_the_locations_within_the_radius():
    from dpom_warp.geometry import neighbour_lists

    rng = np.random.default_rng(0)
    locs = rng.uniform(0, 2, (60, 3))
    start, nbrs = neighbour_lists(locs, 0.5)
    for k in range(60):
        d = np.linalg.norm(locs - locs[k], axis=1)
        want = np.flatnonzero((d < 0.5) & (np.arange(60) != k))
        np.testing.assert_array_equal(nbrs[start[k]:start[k + 1]], want)
    start, _ = neighbour_lists(locs, 0.0)
    assert start.shape == (61,) and not start.any()


@pytest.mark.parametrize("graph", [False, True])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(3))
def test_sparse_drop_matches_reference(device, seed, shape, graph):
    """model.sparse_drop (a full pass sets to 0 and drops the locations whose rho_new is below
    sparse_epsilon and whose rho is below sparse_drop) on the Warp path, driven from the host
    or as a graph, equals the reference; it changes the iterations' course somewhere."""
    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    params = params.replace(sparse_epsilon=1e-4, sparse_drop=0.5)
    engine = Engine(geom, params, device, graph=graph)
    engine.set_background_frames(bg_frames)
    bg = ref.background_from_frames(bg_frames, params)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    assert got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    plain = ref.mean_field(depth, geom, bg, params.replace(sparse_drop=0.0))
    assert np.abs(plain["rho"] - want["rho"]).max() > 1e-9, "nothing was dropped: the option is not exercised"


def test_place_active_is_flatnonzero_in_order(device):
    """kernels.sparse.has_entries, an inclusive scan and place_active give the pixels with
    entries in pixel order and their counts, as np.flatnonzero, on every device (no atomics:
    a GPU's order too); none, and all, included."""
    import warp as wp
    from dpom_warp import kernels as K

    rng = np.random.default_rng(3)
    for counts in (rng.integers(0, 4, 5000) * (rng.random(5000) < 0.3), np.zeros(64, int), np.ones(64, int)):
        counts = counts.astype(np.int32)
        live_counts = wp.array(counts, dtype=wp.int32, device=device)
        flag, rank, active, active_counts = (wp.zeros(len(counts), dtype=wp.int32, device=device) for _ in range(4))
        wp.launch(K.has_entries, len(counts), [live_counts, flag], device=device)
        wp.utils.array_scan(flag, rank, inclusive=True)
        wp.launch(K.place_active, len(counts), [live_counts, rank, active, active_counts], device=device)
        n = int(rank.numpy()[-1])
        want = np.flatnonzero(counts)
        np.testing.assert_array_equal(active.numpy()[:n], want)
        np.testing.assert_array_equal(active_counts.numpy()[:n], counts[want])


def test_frame_tally_is_numpys_per_frame_sum_and_count(device):
    """kernels.sparse.frame_tally adds each frame's sum of its values (TALLY_SUM) or count of
    one code into its slot, as NumPy's per-row sum and count, on every device: the counts a
    batch's results report (entries, live, pruned, kept)."""
    import warp as wp
    from dpom_warp import kernels as K

    rng = np.random.default_rng(5)
    frames, per_frame = 5, 997
    values = rng.integers(-2, 40, frames * per_frame).astype(np.int32)
    values[per_frame:2 * per_frame] = 0  # a frame with nothing
    out = wp.zeros((4, frames), dtype=wp.int32, device=device)
    a = wp.array(values, dtype=wp.int32, device=device)
    for slot, code in enumerate((K.TALLY_SUM, 1, K.PRUNED, K.IDLE)):
        wp.launch(K.frame_tally, len(values), [a, per_frame, code, out, slot], device=device)
    rows = values.reshape(frames, per_frame)
    got = out.numpy()
    np.testing.assert_array_equal(got[0], rows.sum(1))
    for slot, code in ((1, 1), (2, K.PRUNED), (3, K.IDLE)):
        np.testing.assert_array_equal(got[slot], (rows == code).sum(1))
    assert got[0, 1] == 0 and (got[1:, 0] > 0).all()


@pytest.mark.parametrize("path", ["exact", "sparse", "graph"])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed, cameras", [(1, 2), (2, 3)])
def test_a_rig_matches_the_reference(device, seed, cameras, shape, path):
    """Several cameras on one map (issue 61): the engine given a rig's geometries and frames
    sums every camera's pixels into each location's evidence, readings behind, area and top
    band, and updates each location once: the reference's mean_field_rig (the cameras' lists
    one after the other) at 1e-6, the same iterations and entries, on the exact path, the sparse
    one with its pruning bound, and a captured graph; with the people tests (behind cost, top
    band with a shorter band) on the solid. The fused map is no single camera's."""
    from scenes import random_rig

    geoms, params, frames, bg_frames = random_rig(seed, cameras, shape=shape)
    if shape == "solid":
        params = params.replace(behind_cost=2.0, behind_low=0.3, behind_step=1, top_support=0.3,
                                top_heights=(round(0.85 * geoms[0].height, 6),))
    if path != "exact":
        params = params.replace(sparse_epsilon=1e-3)
    engine = Engine(geoms, params, device, graph=path == "graph")
    for c, frames_c in enumerate(bg_frames):
        engine.set_background_frames(frames_c, camera=c)
    got = engine.infer(frames)
    bgs = [ref.background_from_frames(b, params) for b in bg_frames]
    want = ref.mean_field_rig(frames, geoms, bgs, params)
    assert got.iterations == want["iterations"] and got.entries == want["entries"] > 0
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    assert_top_counts(engine, want)
    alone = ref.mean_field(frames[0], geoms[0], bgs[0], params)
    assert np.abs(alone["rho"] - want["rho"]).max() > 1e-3  # the other cameras' pixels count
    assert got.entries == sum(ref.pixel_lists(f, g, b, params)[4] for f, g, b in zip(frames, geoms, bgs))

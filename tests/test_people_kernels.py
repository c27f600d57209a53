"""The people kernels (kernels/people.py: readings behind each cell's solid, the top band and the
soft threshold with it) against the NumPy reference (reference_people.py), on random small
scenes, every device."""

import numpy as np
import pytest

from conftest import assert_top_counts
from dpom_warp import reference as ref
from dpom_warp.engine import Engine
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles

from scenes import random_scene


@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(3))
def test_unhidden_share_matches_reference(device, seed, shape):
    """model.share_of: unhidden (eq. 13's e over the pixels not hidden by something nearer)
    on the Warp path equals the reference, and differs from the silhouette share somewhere."""
    geom, params, depth, _ = random_scene(seed, shape=shape)
    params = params.replace(share_of="unhidden")
    bg = ref.floor_background(geom, params, depth)
    want = ref.mean_field(depth, geom, bg, params)
    engine = Engine(geom, params, device)
    for by_row in (False, True):  # the band's counts a thread a location or a rectangle's row
        engine.top_band_by_row = by_row
        got = engine.infer(depth)
        np.testing.assert_allclose(got.evidence_share, want["evidence_share"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    plain = ref.mean_field(depth, geom, bg, params.replace(share_of="silhouette"))
    assert np.any(want["evidence_share"] > plain["evidence_share"] + 1e-3)


@pytest.mark.parametrize("seed", range(2))
def test_behind_table_serves_every_frame_and_counts_in_memory(device, seed):
    """The core's lattice points are found once per engine (people.PeoplePrior.add_camera): frames
    with other readings, one after another, each get the reference's counts, and the table
    is in memory_bytes (BEHIND_POINT_BYTES a point, beside an engine without the cost)."""
    from dpom_warp.engine import BEHIND_POINT_BYTES

    geom, params, depth, bg_frames = random_scene(seed, shape="solid")
    params = params.replace(sparse_epsilon=0.0, behind_cost=3.0, behind_low=0.3, behind_step=1)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    everyone = np.ones(len(geom.rect), bool)
    rng = np.random.default_rng(seed)
    for frame in (depth, depth * rng.uniform(1.0, 1.3, depth.shape), depth):
        engine.infer(frame)
        listed = engine.per_location.numpy() > 0
        want = ref.behind_count(frame, geom, params, everyone)
        np.testing.assert_array_equal(engine.prior.n_behind.numpy()[listed], want[listed])
        assert want[listed].max() > 0, "no reading behind any listed location: the count is not exercised"
    assert engine.prior.cameras[0].points == len(engine.prior.cameras[0].mu) > 0
    plain = Engine(geom, params.replace(behind_cost=0.0), device)
    assert engine.memory_bytes() - plain.memory_bytes() == BEHIND_POINT_BYTES * engine.prior.cameras[0].points


def test_behind_count_at_the_mask_tests_edge(device):
    """behind_count classes a reading from the point's stored half-width W (kernels.mean_field):
    readings a millionth of W inside and outside mu +- W, in front and behind, get the
    reference's classes (the mask test itself), so the counts are the reference's."""
    geom, params, depth, bg_frames = random_scene(1, shape="solid")
    params = params.replace(sparse_epsilon=0.0, behind_cost=3.0, behind_low=0.3, behind_step=1)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    pixel, mu, half = (a.numpy() for a in (engine.prior.cameras[0].pixel, engine.prior.cameras[0].mu, engine.prior.cameras[0].half))
    rng = np.random.default_rng(1)
    frame = depth.copy().reshape(-1)
    pick = rng.permutation(len(pixel))
    side = rng.choice([-1.0, 1.0], len(pixel)) * rng.choice([1 - 1e-6, 1 + 1e-6], len(pixel))
    frame[pixel[pick]] = (mu[pick] + side[pick] * half[pick]).astype(np.float32)  # the last pick of a pixel stays
    frame = frame.reshape(depth.shape)
    engine.infer(frame)
    listed = engine.per_location.numpy() > 0
    want = ref.behind_count(frame, geom, params, np.ones(len(geom.rect), bool))
    np.testing.assert_array_equal(engine.prior.n_behind.numpy()[listed], want[listed])
    near = np.abs(np.abs(frame.reshape(-1)[pixel] - mu) / half - 1) < 1e-5
    assert near.sum() > 100 and want[listed].max() > 0  # many readings at the edge, some behind


@pytest.mark.parametrize("path", ["exact", "sparse", "graph"])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", range(3))
def test_behind_cost_matches_reference(device, seed, shape, path):
    """model.behind_cost (each location loses evidence for the pixels of its silhouette's core
    that read behind its object) on the Warp path equals the reference: the counts of every
    location in a list (before the pruning bound, which subtracts them too), and rho / rho*
    after the iterations; the location with the most such readings gets a lower first update
    than without the cost."""
    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4, behind_cost=3.0,
                                 behind_side=0.2, behind_low=0.3, behind_step=1 + seed % 2)
    engine = Engine(geom, params, device, graph=path == "graph")
    engine.set_background_frames(bg_frames)
    bg = ref.background_from_frames(bg_frames, params)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    valid, L = ref.pixel_lists(depth, geom, bg, params)[:2]
    listed = np.bincount(L[valid], minlength=len(geom.rect)) > 0  # in a list before the bound
    counts = ref.behind_count(depth, geom, params, listed)
    np.testing.assert_array_equal(engine.prior.n_behind.numpy()[listed], counts[listed])
    assert counts.max() > 0, "no reading behind any location: the count is not exercised"
    assert got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    first, first_plain = [], []  # each iteration's rho_new: the first from the same start
    exact = params.replace(sparse_epsilon=0.0)  # (the model's update, nothing pruned)
    ref.mean_field(depth, geom, bg, exact, trace=first)
    ref.mean_field(depth, geom, bg, exact.replace(behind_cost=0.0), trace=first_plain)
    k = int(np.argmax(np.where(listed, counts, -1)))
    assert first[0][k] < first_plain[0][k], "the location with the most readings behind it lost nothing"


@pytest.mark.parametrize("path", ["exact", "sparse"])
@pytest.mark.parametrize("shape", ["plane", "solid"])
@pytest.mark.parametrize("seed", [2, 3, 4])  # (0 and 1: the solid's bands are out of view)
def test_shorter_top_bands_match_reference(device, seed, shape, path):
    """model.top_heights (the top band of shorter solids, the largest factor kept) on the Warp
    path equals the reference: each location's kept counts and rho*; on a scene with an
    object shorter than the rest, somewhere a shorter band is kept and raises rho*."""
    from scenes import draw_slab

    geom, params, depth, bg_frames = random_scene(seed, shape=shape)
    heights = (0.85 * geom.height, 0.7 * geom.height)
    seen = np.flatnonzero(geom.rect_area > 0)
    for k in seen[len(seen) // 4::len(seen) // 4]:  # short people, in front of what is there
        draw_slab(depth, geom, k, below=0.72 * geom.height)
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4, top_heights=heights)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    bg = ref.background_from_frames(bg_frames, params)
    want = ref.mean_field(depth, geom, bg, params)
    for by_row in (False, True):  # a thread a location (the CPU's) or a rectangle's row (a GPU's)
        engine.top_band_by_row = by_row
        got = engine.infer(depth)
        assert_top_counts(engine, want)
        np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    plain = ref.mean_field(depth, geom, bg, params.replace(top_heights=()))
    kept_shorter = np.any([want[k] != plain[k] for k in ("top_support", "top_against", "top_hidden")], axis=0)
    assert kept_shorter.any(), "no location kept a shorter band: the choice is not exercised"
    assert np.all(want["rho_star"] >= plain["rho_star"] - 1e-12)
    assert np.any(want["rho_star"] > plain["rho_star"] + 1e-6)


@pytest.mark.parametrize("path", ["exact", "sparse"])
@pytest.mark.parametrize("seed", [0, 1])  # the solid's bands are out of view
def test_unseen_band_share_matches_reference(device, seed, path):
    """model.top_unseen_share (where a location's top band is out of view, rho* also x
    sigmoid(top_slope (e - share))) on the Warp path equals the reference; against the same
    scene with the share off, exactly the locations whose band is out of view change, by that
    factor (the share set between their e values, so that some are cut and some kept)."""
    geom, params, depth, bg_frames = random_scene(seed, shape="solid")
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4, top_unseen=1.0,
                                 top_unseen_share=0.0)
    bg = ref.background_from_frames(bg_frames, params)
    off = ref.mean_field(depth, geom, bg, params)
    unseen = ref.band_out_of_view(off["top_seen"], geom.area, params)
    judged = unseen & (off["rho_star"] > 1e-3)
    assert judged.sum() >= 2, "fewer than two locations with their band out of view: not exercised"
    share = float(np.median(off["evidence_share"][judged]))
    params = params.replace(top_unseen_share=share)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    np.testing.assert_array_equal(engine.prior.top_counts[4].numpy(), want["top_seen"])
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    factor = ref.sigmoid(params.top_slope * (want["evidence_share"] - share))
    np.testing.assert_allclose(want["rho_star"], np.where(unseen, off["rho_star"] * factor, off["rho_star"]),
                               rtol=0, atol=1e-12)
    assert np.any(judged & (want["rho_star"] < 0.6 * off["rho_star"]))
    assert np.any(judged & (want["rho_star"] >= 0.5 * off["rho_star"]))


@pytest.mark.parametrize("path", ["exact", "sparse"])
@pytest.mark.parametrize("seed", [2, 3])
def test_band_partly_out_of_view_matches_reference(device, seed, path):
    """model.top_unseen_part (a band with fewer than this share of |S_k| in the image counts
    as out of view) on the Warp path equals the reference, with a shorter band tried beside
    (keep_better_top); the share set between the counted locations' seen / |S_k|, so that
    some bands with top_min_pixels or more in view become out of view and take top_unseen
    (0 here: their rho* falls to 0)."""
    from scenes import draw_slab

    geom, params, depth, bg_frames = random_scene(seed, shape="solid")
    seen = np.flatnonzero(geom.rect_area > 0)
    for k in seen[len(seen) // 4::len(seen) // 4]:  # people whose bands are counted
        draw_slab(depth, geom, k, below=0.9 * geom.height)
    params = params.replace(sparse_epsilon=0.0 if path == "exact" else 1e-4, top_unseen=0.0,
                                 top_unseen_part=0.0, top_heights=(0.85 * geom.height,))
    bg = ref.background_from_frames(bg_frames, params)
    off = ref.mean_field(depth, geom, bg, params)
    counted = (off["top_seen"] >= params.top_min_pixels) & (geom.area > 0)
    assert counted.sum() >= 2, "fewer than two bands counted: not exercised"
    part = float(np.median(off["top_seen"][counted] / geom.area[counted]))
    params = params.replace(top_unseen_part=part)
    engine = Engine(geom, params, device)
    engine.set_background_frames(bg_frames)
    want = ref.mean_field(depth, geom, bg, params)
    got = engine.infer(depth)
    assert_top_counts(engine, want)
    np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
    partly = ref.band_out_of_view(want["top_seen"], geom.area, params) & (want["top_seen"] >= params.top_min_pixels)
    assert partly.any(), "no band partly out of view"
    assert np.all(want["rho_star"][partly] == 0.0)  # top_unseen 0: not a detection
    assert np.any(off["rho_star"][partly] > 1e-3)


def test_shorter_solid_lies_inside_the_silhouettes():
    """Geometry.shorter: shoulder and top scaled above the bottom, the radii and legs kept, so
    the shorter solid's projection lies inside each silhouette rectangle (the kernels walk
    only the rectangle) where its head is no wider than its body; a height above the
    object's is refused."""
    cam = Camera(64, 48, 50.0, 50.0, 31.5, 23.5, pose_from_angles(2.6, 35.0, 2.0))
    geom = build_geometry(cam, Grid(x=(-1.5, 1.5, 0.3), y=(1.5, 5.0, 0.3)),
                          ObjectBox(0.4, 1.8, shape="solid", head_radius=0.11, depth_radius=0.12,
                                    leg_radius=0.14, hip=0.45))
    short = geom.shorter(1.5)
    assert short.height == 1.5
    assert (short.shape.shoulder, short.shape.top) == pytest.approx((0.8 * 1.5, 1.5))
    kept = ("bottom", "body_radius", "head_radius", "height_spread", "leg_radius", "hip", "depth_radius")
    assert [getattr(short.shape, x) for x in kept] == [getattr(geom.shape, x) for x in kept]
    inside = 0
    for k in np.flatnonzero(geom.rect_area > 0):
        mu_short, _ = short.object_depth(k, geom.rays)
        u0, v0, u1, v1 = geom.rect[k]
        hit = np.argwhere(mu_short > 0)
        assert np.all((hit[:, 0] >= v0) & (hit[:, 0] <= v1) & (hit[:, 1] >= u0) & (hit[:, 1] <= u1))
        inside += len(hit)
    assert inside > 0
    with pytest.raises(ValueError, match="expected a height in"):
        geom.shorter(1.9)

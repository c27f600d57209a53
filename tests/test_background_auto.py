"""`input.background: auto`: the streamed per-pixel estimate against its NumPy reference, what
it finds behind moving people, its fallback pixels, and the run that uses it."""

import json

import numpy as np
import pytest

from conftest import assert_same_sums
from dpom_warp import reference as ref
from dpom_warp.background import BackgroundEstimator, sample_frames
from dpom_warp.cli import main
from dpom_warp.engine import Engine
from dpom_warp.model import AutoBackground, ModelParams

from scenes import random_scene
from test_cli import small_config

PARAMS = ModelParams()


def crowd_sequence(seed, n=24, shape=(30, 36), visible=0.35):
    """A static wall/floor depth per pixel, and frames where moving people (rectangles at
    random depths in front of it) cover each pixel in about 1 - `visible` of the frames;
    noise, dropouts, a corner never read, a still person in the lower right."""
    rng = np.random.default_rng(seed)
    h, w = shape
    static = rng.uniform(2.0, 6.0, shape)
    frames = np.empty((n,) + shape)
    for f in range(n):
        z = static + rng.normal(size=shape) * PARAMS.sensor_sigma(static)
        covered = rng.random(shape) > visible
        person = rng.uniform(0.8, 0.9, shape) * static  # always in front of the static surface
        z = np.where(covered, person, z)
        z[rng.random(shape) < 0.03] = 0
        frames[f] = z
    frames[:, :3, :3] = 0  # never a reading
    frames[:, -4:, -4:] = 1.5 + rng.normal(0, 0.004, (n, 4, 4))  # someone standing still
    return static, frames.astype(np.float32)


@pytest.mark.parametrize("seed, slots, chunks", [(0, 4, [24]), (1, 2, [5, 1, 18]), (2, 3, [7, 7, 10])])
def test_estimate_matches_reference(device, seed, slots, chunks):
    """Streamed in chunks on every device, the estimate equals the reference over the whole
    sequence: same clusters (including evictions with few slots), same fallback pixels."""
    _, frames = crowd_sequence(seed)
    auto = AutoBackground(slots=slots, min_frames=5)
    want, want_fallback = ref.background_clusters(frames, PARAMS, auto)
    est = BackgroundEstimator(*frames.shape[1:], PARAMS, auto, device)
    start = 0
    for c in chunks:
        est.add(frames[start:start + c])
        start += c
    assert est.frames == len(frames)
    got, fallback = est.result()
    np.testing.assert_array_equal(fallback, want_fallback)
    for name in ("mu", "sigma", "missing", "outlier"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-12, atol=1e-12,
                                   err_msg=name)
    assert (want.outlier < 1).mean() > 0.5, "too few pixels found a background: nothing compared"


def test_background_found_behind_moving_people():
    """Where the static surface shows in at least min_share of the frames (a third on
    average here), the estimate is that surface, not the people in front, who are scattered
    over 10 % of its depth; pixels never read have a broad background."""
    static, frames = crowd_sequence(5, n=30)
    auto = AutoBackground()
    bg, fallback = ref.background_clusters(frames, PARAMS, auto)
    sigma = PARAMS.sensor_sigma(static)
    shown = (np.abs(frames - static) < 4 * sigma).sum(0) >= auto.min_share * len(frames)
    shown[:3, :3] = shown[-4:, -4:] = False
    assert shown.mean() > 0.9
    assert np.all(bg.outlier[shown] < 1)
    err = np.abs(bg.mu - static)[shown]
    assert np.median(err) < 0.5 * np.median(sigma)
    assert np.all(err < 4 * sigma[shown] / np.sqrt(auto.min_share * len(frames)))
    assert np.all(bg.sigma >= PARAMS.sensor_sigma(bg.mu))  # floored by the sensor noise
    assert np.median(bg.sigma[shown] / sigma[shown]) < 1.5
    assert np.all(bg.outlier[:3, :3] == 1) and not fallback[:3, :3].any()  # absent: broad
    assert np.all(bg.missing[:3, :3] == 1 - PARAMS.missing_clip)
    # a person still in every frame is the only surface there: taken as background (the
    # documented limit)
    np.testing.assert_allclose(bg.mu[-4:, -4:], 1.5, atol=0.01)


@pytest.mark.parametrize("still", [0.70, 0.85])
def test_someone_still_in_more_than_1_minus_min_share_of_the_frames_is_background(device, still):
    """The README's limit, on both sides of it: a wall at 4 m with someone standing still at
    1.5 m in front of it in a share `still` of 40 frames (spread over the sequence). With the
    wall in at least min_share (0.2) of the frames (still = 0.70) the wall is the background;
    with it in less (still = 0.85, more than 1 - min_share) the person is."""
    rng = np.random.default_rng(7)
    n, shape = 40, (6, 8)
    auto = AutoBackground()
    assert auto.min_share == 0.2
    here = rng.permutation(n) < round(still * n)  # the frames the person is in
    wall = 4.0 + rng.normal(size=(n,) + shape) * PARAMS.sensor_sigma(4.0)
    person = 1.5 + rng.normal(size=(n,) + shape) * PARAMS.sensor_sigma(1.5)
    frames = np.where(here[:, None, None], person, wall).astype(np.float32)
    est = BackgroundEstimator(*shape, PARAMS, auto, device)
    est.add(frames[:16])
    est.add(frames[16:])
    got, fallback = est.result()
    want, _ = ref.background_clusters(frames, PARAMS, auto)
    np.testing.assert_allclose(got.mu, want.mu, rtol=1e-12, atol=1e-12)
    assert not fallback.any() and np.all(got.outlier < 1)
    surface = 4.0 if still < 1 - auto.min_share else 1.5  # the wall, or the person standing still
    shown = min(here.sum(), n - here.sum())  # readings of that surface, at least
    np.testing.assert_allclose(got.mu, surface, atol=4 * PARAMS.sensor_sigma(surface) / np.sqrt(shown))


def test_pixels_without_a_stable_surface_fall_back():
    """Readings scattered over depths with no surface in min_share of the frames, or fewer
    frames than min_frames: the floor-only model's pixels."""
    rng = np.random.default_rng(0)
    steps = np.stack([rng.permutation(20) for _ in range(42)], -1).reshape(20, 6, 7)
    frames = (1.0 + 0.3 * steps).astype(np.float32)  # 20 depths 0.3 m apart: nothing stable
    frames[:, 0, 0] = 3.0  # but here
    auto = AutoBackground(min_frames=8)
    bg, fallback = ref.background_clusters(frames, PARAMS, auto)
    assert fallback.sum() == 41 and not fallback[0, 0]
    bg, fallback = ref.background_clusters(frames[:7], PARAMS, auto)
    assert fallback.all()


def test_few_frames_is_the_floor_only_model(device):
    """A single frame (fewer than min_frames) leaves every pixel to the floor-only model:
    the same rho as a floor-only engine, and every pixel counted as a fallback."""
    geom, params, depth, _ = random_scene(2)
    floor = Engine(geom, params, device)
    want = floor.infer(depth)
    engine = Engine(geom, params, device, background_auto=AutoBackground())
    est = BackgroundEstimator(*depth.shape, params, AutoBackground(), device)
    est.add(depth)
    assert engine.set_background_estimate(est) == depth.size
    got = engine.infer(depth)
    assert_same_sums(got.rho, want.rho, device)
    assert engine.memory_bytes() == floor.memory_bytes() + AutoBackground().state_bytes(depth.size)


def test_mixed_background_matches_reference(device):
    """Some pixels estimated, the others on the floor-only model completed from each frame:
    the engine's background and rho equal the reference's mix of the two."""
    geom, params, depth, bg_frames = random_scene(4)
    params = params.replace(sparse_epsilon=0.0)
    rng = np.random.default_rng(4)
    frames = np.concatenate([bg_frames, bg_frames[:3]])
    frames[:, :, :20] = rng.uniform(0.5, 8, frames[:, :, :20].shape)  # left part: nothing stable
    auto = AutoBackground(min_frames=5)
    est = BackgroundEstimator(*depth.shape, params, auto, device)
    est.add(frames)
    engine = Engine(geom, params, device)
    n_fallback = engine.set_background_estimate(est)
    got = engine.infer(depth)
    bg, fallback = ref.background_clusters(frames, params, auto)
    assert n_fallback == fallback.sum() and 0 < n_fallback < depth.size
    floor = ref.floor_background(geom, params, depth)
    for name in ("mu", "sigma", "missing", "outlier"):
        setattr(bg, name, np.where(fallback, getattr(floor, name), getattr(bg, name)))
        np.testing.assert_allclose(getattr(engine.background(), name), getattr(bg, name),
                                   rtol=1e-12, atol=1e-12, err_msg=name)
    want = ref.mean_field(depth, geom, bg, params)
    assert got.entries == want["entries"] and got.iterations == want["iterations"]
    np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)


def test_sample_frames_spreads_evenly():
    assert sample_frames(5, 100) == [0, 1, 2, 3, 4]
    s = sample_frames(1000, 10)
    assert len(s) == 10 and s[0] == 0 and s[-1] == 999
    assert max(np.diff(s)) - min(np.diff(s)) <= 1


def test_run_with_auto_background(tmp_path):
    """`input.background: auto` end to end: no background frames read, the estimate's
    fallback pixels in summary.json, people found; with one frame, all pixels fall back."""
    path = small_config(tmp_path)
    sets = ["--set", "input.background=auto", "--set", "input.background_auto.min_frames=3",
            "--set", "synthetic.frames=6", "--set", "output.images=false"]
    assert main(["run", str(path), "--no-progress"] + sets) == 0
    s = json.load(open(tmp_path / "out" / "summary.json"))
    auto = s["background_auto"]
    w, h = s["inference"]["image"]
    assert auto["frames"] == 6 and auto["pixels"] == w * h
    assert 0 <= auto["fallback_pixels"] < 0.2 * auto["pixels"]
    assert s["background"].startswith("auto from 6 of the frames")
    assert auto["memory_bytes"] == AutoBackground().state_bytes(auto["pixels"])
    assert s["scores"]["recall"] > 0.7
    one = ["--set", "input.frames=" + str(tmp_path / "scene" / "frames" / "0000.png")]
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "one")] + sets + one) == 0
    s = json.load(open(tmp_path / "one" / "summary.json"))
    assert s["background_auto"]["fallback_pixels"] == s["background_auto"]["pixels"]


def test_auto_background_with_workers_and_fitted_pose(tmp_path):
    """--workers 2 gives the single-process files (the workers take the run's estimate), and
    with extrinsics: auto the floor is fitted on the estimated background."""
    path = small_config(tmp_path)
    sets = ["--set", "input.background=auto", "--set", "input.background_auto.min_frames=3",
            "--set", "synthetic.frames=6", "--set", "output.images=false"]
    assert main(["run", str(path), "--no-progress"] + sets) == 0
    assert main(["run", str(path), "--no-progress", "--workers", "2", "--output",
                 str(tmp_path / "two")] + sets) == 0
    one = (tmp_path / "out" / "detections.csv").read_text()
    assert one == (tmp_path / "two" / "detections.csv").read_text() and one.count("\n") > 3
    posed = sets + ["--set", "synthetic=null", "--set", "camera.extrinsics=auto",
                    "--set", "evaluation.ground_truth=null"]
    assert main(["run", str(path), "--no-progress", "--output", str(tmp_path / "fit")] + posed) == 0
    fit = json.load(open(tmp_path / "fit" / "summary.json"))["ground_fit"]
    assert fit["frames"] == "estimated background of 6 frames"
    assert abs(fit["camera_height"] - 2.2) < 0.03 and abs(fit["pitch_deg"] - 20.0) < 0.5
    assert "depth_noise" not in fit  # a median of frames is quieter than the sensor: no noise said


def test_auto_background_samples_max_frames_in_chunks_of_16(tmp_path, monkeypatch):
    """At most max_frames frames, evenly spread, are read for the estimate, 16 at a time;
    summary.json states the share of fallback pixels and the estimate's time."""
    path = small_config(tmp_path)
    batches = []
    real = BackgroundEstimator.add

    def add(self, depths):
        batches.append(len(depths))
        return real(self, depths)

    monkeypatch.setattr(BackgroundEstimator, "add", add)
    sets = ["--set", "input.background=auto", "--set", "input.background_auto.min_frames=3",
            "--set", "input.background_auto.max_frames=18", "--set", "synthetic.frames=24",
            "--set", "output.images=false", "--set", "tracking.method=off"]
    assert main(["run", str(path), "--no-progress"] + sets) == 0
    auto = json.load(open(tmp_path / "out" / "summary.json"))["background_auto"]
    assert auto["frames"] == 18 and batches == [16, 2]
    assert auto["fallback_share"] == pytest.approx(auto["fallback_pixels"] / auto["pixels"])
    assert auto["estimate_s"] > 0
    assert sample_frames(24, 18) == sorted(set(sample_frames(24, 18))) and len(sample_frames(24, 18)) == 18


def test_fitted_pose_with_too_few_frames_for_an_estimate(tmp_path):
    """extrinsics: auto with background: auto but fewer frames than min_frames: every pixel
    falls back to the floor-only model and the floor is fitted on the first frames."""
    path = small_config(tmp_path)
    sets = ["--set", "input.background=auto", "--set", "input.background_auto.min_frames=10",
            "--set", "synthetic.frames=4", "--set", "output.images=false", "--set", "camera.extrinsics=auto",
            "--set", "synthetic=null"]
    import yaml

    cfg = yaml.safe_load(path.read_text())
    from dpom_warp.loading import load_config
    from dpom_warp.frames import render_synthetic

    render_synthetic(load_config(path, ["synthetic.frames=4"]), lambda *_: None)  # the frames first
    assert main(["run", str(path), "--no-progress"] + sets) == 0
    s = json.load(open(tmp_path / "out" / "summary.json"))
    assert s["background_auto"]["fallback_pixels"] == s["background_auto"]["pixels"]
    assert len(s["ground_fit"]["frames"]) == 4 and abs(s["ground_fit"]["camera_height"] - 2.2) < 0.1
    assert cfg["camera"]["extrinsics"]["height"] == 2.2

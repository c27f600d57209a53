"""The benchmark's timing of one scene, on a small rendered scene (not its speed)."""

import numpy as np

from bench.__main__ import time_scene
from dpom_warp.config import load_config
from dpom_warp.io import read_depth
from dpom_warp.pipeline import expand, make_engine
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

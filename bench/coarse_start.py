"""Coarse-to-fine: does a coarser stride's solution, as the start of the fine one, save time?

For every scene of bench.robustness's tuning draw (background frames, the demo's defaults)
each frame is inferred two ways, timed in turn on one core:

- plain: the fast path as a run does it (stride s from `input.stride: auto`);
- coarse-to-fine: first at stride `--factor` x s (at most 8), then at stride s starting from
  the coarse rho, with the damping schedule entered at iteration `--skip` (lambda =
  damping x growth^skip: the start is no longer the prior, so the small early steps are
  skipped).

Prints false detections and misses at 0.5 m over all frames, the summed iterations (the
coarse ones counted at their share of the pixels, 1 / factor^2) and the median time a
frame of each.

    python -m bench.coarse_start [--skip 30] [--factor 2] [--frames 10] [--scenes NAME ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

from bench.robustness import VARIANTS, scene_sets


def score(res, cfg, geometry, truth) -> tuple[int, int]:
    """(false detections, misses) at 0.5 m of one frame's engine result, detected as a
    run detects it (worker.detections_of: the joint test on the lists the engine hands over)."""
    from dpom_warp.evaluate import match
    from dpom_warp.worker import detections_of

    _, dets = detections_of(res, geometry, cfg)
    found = np.array([(d.x, d.y) for d in dets]).reshape(-1, 2)
    people = np.array([(o["x"], o["y"]) for o in truth]).reshape(-1, 2)
    matched = len(match(found, people, 0.5))
    return len(found) - matched, len(people) - matched


def main():
    from dpom_warp.loading import load_config
    from dpom_warp.evaluate import load_ground_truth
    from dpom_warp.geometry import build_geometry
    from dpom_warp.io import read_depth
    from dpom_warp.sources import expand
    from dpom_warp.worker import make_engine
    from dpom_warp.synthetic import generate

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--skip", type=int, default=30, help="damping schedule entered at this iteration")
    ap.add_argument("--factor", type=int, default=2, help="the coarse stride: factor x the fine one (at most 8)")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--scenes", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    a = ap.parse_args()
    totals = {"plain": [0, 0, 0.0, []], "coarse-to-fine": [0, 0, 0.0, []]}
    for name in a.scenes:
        cfg = load_config("configs/demo_people.yaml", scene_sets(name, VARIANTS[name], a.frames, "frames", True))
        generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
        fine = make_engine(cfg, cfg.camera, "cpu", 1)
        stride = fine.resolution.stride
        coarse_cfg = dataclasses.replace(cfg, inputs=cfg.inputs.model_copy(update={"stride": min(8, a.factor * stride)}))
        coarse = make_engine(coarse_cfg, cfg.camera, "cpu", 1)
        later = cfg.model.replace(damping=cfg.model.damping * cfg.model.damping_growth ** a.skip)
        warm = make_engine(dataclasses.replace(cfg, model=later), cfg.camera, "cpu", 1)
        shape = (cfg.camera.height, cfg.camera.width)
        empty = np.stack([read_depth(f, cfg.inputs.depth_scale, shape)
                          for f in expand(cfg.inputs.background, "input.background")])
        for engine in (fine, coarse, warm):
            engine.set_background_frames(engine.resolution.frames(empty))
        truth = load_ground_truth(cfg.evaluation.ground_truth)
        geometry = build_geometry(cfg.camera, cfg.grid, cfg.obj)
        share = (coarse.resolution.stride / stride) ** -2
        for f in expand(cfg.inputs.frames, "input.frames")[:a.frames]:
            depth = read_depth(f, cfg.inputs.depth_scale, shape)
            for key, total in totals.items():
                t = time.perf_counter()
                if key == "plain":
                    res = fine.infer(fine.resolution.frames(depth))
                    iterations = res.iterations
                else:
                    first = coarse.infer(coarse.resolution.frames(depth))
                    res = warm.infer(warm.resolution.frames(depth), start=first.rho)
                    iterations = share * first.iterations + res.iterations
                total[3].append(time.perf_counter() - t)
                false, missed = score(res, cfg, geometry, truth[f.name])
                total[0] += false
                total[1] += missed
                total[2] += iterations
    print(f"tuning draw, {len(a.scenes)} scenes x {a.frames} frames, background frames; coarse stride x{a.factor}, "
          f"schedule entered at iteration {a.skip}")
    for key, (false, missed, iterations, times) in totals.items():
        print(f"{key}: {false} false, {missed} missed; {iterations:.0f} iterations (coarse ones at their share of "
              f"the pixels); median {1000 * statistics.median(times):.1f} ms a frame")


if __name__ == "__main__":
    main()

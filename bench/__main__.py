"""Kernel benchmark: time per stage of one frame, Warp against the NumPy reference.

    python -m bench [--device cpu] [--repeats 5] [--reference] [--output runs/bench]

Scene: the people demo (Kinect v2-like 512x424, 6 x 6.5 m ground grid at 0.1 m), its first
frame. Each Warp figure is the median of `--repeats` runs after a warm-up run (which also
compiles the kernels); the NumPy reference, when asked for, runs once.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="configs/demo_people.yaml")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--reference", action="store_true", help="also time the NumPy reference (slow)")
    ap.add_argument("--output", default="runs/bench")
    a = ap.parse_args()

    import warp as wp

    from dpom_warp import kernels as K
    from dpom_warp import reference as ref
    from dpom_warp.config import load_config
    from dpom_warp.engine import Engine, resolve_device
    from dpom_warp.geometry import build_geometry
    from dpom_warp.io import read_depth
    from dpom_warp.pipeline import expand
    from dpom_warp.synthetic import generate

    cfg = load_config(a.config)
    if cfg.synthetic is not None:
        generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    device = resolve_device(a.device)
    scale = cfg.inputs.depth_scale
    depth = read_depth(expand(cfg.inputs.frames, "input.frames")[0], scale)
    bg_frames = np.stack([read_depth(f, scale) for f in expand(cfg.inputs.background, "input.background")])
    geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    engine = Engine(geom, cfg.model, device, cfg.engine.entries_per_pixel)
    engine.set_background_frames(bg_frames)
    warm = engine.infer(depth)  # compiles kernels, sizes the lists

    def one_iteration():
        wp.launch(K.evidence_pass, dim=engine.n_pixels, device=device,
                  inputs=[engine.offsets, engine.counts, engine.entry_loc, engine.entry_delta,
                          engine.delta_bg, engine.rho, engine.behind, engine.evidence])
        wp.launch(K.update_rho, dim=engine.n_locations, device=device,
                  inputs=[0.0, 0.1, 0, engine.evidence, engine.rho, engine.max_change])
        wp.synchronize_device(device)

    rows = {
        "background model (kernel)": median_time(lambda: (engine.set_background_frames(bg_frames),
                                                           wp.synchronize_device(device)), a.repeats),
        "masks, Delta, lists, sort": median_time(lambda: (engine.build_lists(depth),
                                                          wp.synchronize_device(device)), a.repeats),
        "one iteration": median_time(one_iteration, a.repeats),
        "whole frame": median_time(lambda: engine.infer(depth), a.repeats),
    }
    result = {"machine": f"{platform.machine()}, {platform.node()}", "device": device,
              "python": platform.python_version(), "warp": wp.__version__,
              "scene": {"image": [cfg.camera.width, cfg.camera.height], "grid": list(cfg.grid.shape),
                        "locations": int(cfg.grid.size), "mask_entries": warm.entries,
                        "iterations": warm.iterations},
              "repeats": a.repeats, "median_s": rows}
    if a.reference:
        bg = ref.background_from_frames(bg_frames, cfg.model)
        t = time.perf_counter()
        want = ref.mean_field(depth, geom, bg, cfg.model)
        result["reference_whole_frame_s"] = time.perf_counter() - t
        result["reference_max_rho_difference"] = float(np.abs(want["rho"] - warm.rho).max())
        result["speedup_vs_reference"] = result["reference_whole_frame_s"] / rows["whole frame"]
    lines = [f"Machine: {result['machine']}; device {device}; Warp {wp.__version__}; "
             f"{result['scene']['locations']} locations, {warm.entries} mask entries, "
             f"{warm.iterations} iterations; median of {a.repeats} runs", "",
             "| stage | median time |", "|---|---|"]
    lines += [f"| {k} | {1000 * v:.1f} ms |" for k, v in rows.items()]
    if a.reference:
        lines.append(f"| NumPy reference, whole frame (1 run) | {1000 * result['reference_whole_frame_s']:.0f} ms |")
        lines.append(f"\nWarp / NumPy speed-up: {result['speedup_vs_reference']:.1f}x "
                     f"(max |rho difference| {result['reference_max_rho_difference']:.1e})")
    print("\n".join(lines))
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"bench_{device.replace(':', '')}.json").write_text(json.dumps(result, indent=2))
    (out / f"bench_{device.replace(':', '')}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

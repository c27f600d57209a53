"""Kernel benchmarks: time per stage on standard scenes, Warp against the NumPy reference.

    python -m bench [--device cpu] [--repeats 5] [--batch 4] [--reference] [--sweep] [--output runs/bench]

Scenes (rendered once into .cache/bench/, seeded):
- kinect_v2: 512x424, people, 6 x 6.5 m ground grid at 0.1 m (the people demo);
- kinect_v1: 640x480, people, the same area at 0.05 m;
- drones: 512x424, 4 x 4.5 x 2.4 m voxel grid at 0.1 m (the drone demo's room).
Each Warp figure is the median of `--repeats` runs after a warm-up run (which compiles the
kernels and sizes the lists); the NumPy reference, with --reference, runs once on kinect_v2.
Whole frames are timed three ways: the iteration loop driven from Python (a host check every
check_every iterations), the loop replayed as a captured graph (no host sync), and `--batch`
different frames of the scene in one engine call (time per frame = batch time / batch).
--sweep also times whole frames against the number of locations (grid step) and the image
resolution on kinect_v2, and plots both.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

SCENES = {
    "kinect_v2": ("configs/demo_people.yaml", []),
    "kinect_v1": ("configs/demo_people.yaml", [
        "camera.width=640", "camera.height=480",
        "camera.intrinsics={fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5}",
        "grid.x=[-3.0, 3.0, 0.05]", "grid.y=[0.5, 7.0, 0.05]", "model.sensor_noise=[0.002, 0.0025]"]),
    "drones": ("configs/demo_drones.yaml", ["grid.z=[0.0, 2.4, 0.1]", "grid.x=[-2.0, 2.0, 0.1]",
                                            "grid.y=[1.5, 6.0, 0.1]"]),
}


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def load_scene(name, extra=()):
    """(config, first frame, background frames) of a standard scene, rendered if needed."""
    from dpom_warp.config import load_config
    from dpom_warp.io import read_depth
    from dpom_warp.pipeline import expand
    from dpom_warp.synthetic import generate

    path, sets = SCENES[name]
    cache = f".cache/bench/{name}"
    sets = list(sets) + [f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
                         f"input.background={cache}/background/*.png", "synthetic.frames=2",
                         "synthetic.background_frames=5"] + list(extra)
    cfg = load_config(path, sets)
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    scale, shape = cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width)
    depth = read_depth(expand(cfg.inputs.frames, "input.frames")[0], scale, shape)
    bg = np.stack([read_depth(f, scale, shape) for f in expand(cfg.inputs.background, "input.background")])
    return cfg, depth, bg


def scene_frames(name, n):
    """(frames (n, H, W), background frames) of an n-frame sequence of a standard scene
    (rendered once into .cache/bench/<name>_seq)."""
    from dpom_warp.io import read_depth
    from dpom_warp.pipeline import expand

    cache = f".cache/bench/{name}_seq"
    cfg, _, bg = load_scene(name, [f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
                                   f"input.background={cache}/background/*.png", f"synthetic.frames={n}"])
    shape = (cfg.camera.height, cfg.camera.width)
    files = expand(cfg.inputs.frames, "input.frames")[:n]
    return np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in files]), bg


def time_scene(cfg, depth, bg, device, repeats, batch=1, sequence=None):
    """Per-stage medians of one frame on `device`; with batch > 1 also the frames of
    `sequence` = (frames (batch, H, W), their background frames) in one engine call."""
    import warp as wp

    from dpom_warp.engine import Engine
    from dpom_warp.geometry import build_geometry

    geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    t = time.perf_counter()
    engine = Engine(geom, cfg.model, device, cfg.engine.entries_per_pixel, graph=False)
    engine.set_background_frames(bg)
    setup = time.perf_counter() - t
    warm = engine.infer(depth)

    def one_iteration():
        engine.iterate(0, 0.0, 0.1)
        wp.synchronize_device(device)

    stages = {
        "background model (kernel)": median_time(
            lambda: (engine.set_background_frames(bg), wp.synchronize_device(device)), repeats),
        "masks, Delta, lists, sort": median_time(
            lambda: (engine.build_lists(depth), wp.synchronize_device(device)), repeats),
    }
    engine.done.zero_()  # after infer every frame is done and the pass would skip it
    stages["one iteration"] = median_time(one_iteration, repeats)
    stages["whole frame"] = median_time(lambda: engine.infer(depth), repeats)
    engine.graph = True
    engine.infer(depth)  # captures the graph
    stages["whole frame, graph"] = median_time(lambda: engine.infer(depth), repeats)
    result = {"image": [cfg.camera.width, cfg.camera.height], "grid": list(cfg.grid.shape),
              "locations": int(cfg.grid.size), "mask_entries": warm.entries,
              "iterations": warm.iterations, "engine_setup_s": setup,
              "engine_memory_mb": engine.memory_bytes() / 2**20, "median_s": stages}
    if batch > 1:
        del engine
        frames, seq_bg = sequence
        many = Engine(geom, cfg.model, device, cfg.engine.entries_per_pixel, batch=batch)
        many.set_background_frames(seq_bg)
        got = many.infer_batch(frames)
        stages["per frame, batched"] = median_time(lambda: many.infer_batch(frames), repeats) / batch
        result.update(batch=batch, batch_iterations=[r.iterations for r in got],
                      batch_memory_mb=many.memory_bytes() / 2**20,
                      frames_per_s_batched=1.0 / stages["per frame, batched"])
    return result, geom, warm


def sweep(device, repeats, out):
    """Whole-frame time against the number of locations and against the image resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = {"locations": [], "resolution": []}
    for step in (0.2, 0.15, 0.1, 0.075, 0.05):
        cfg, depth, bg = load_scene("kinect_v2", [f"grid.x=[-3.0, 3.0, {step}]", f"grid.y=[0.5, 7.0, {step}]"])
        r, _, _ = time_scene(cfg, depth, bg, device, repeats)
        rows["locations"].append({"step": step, "locations": r["locations"], "entries": r["mask_entries"],
                                  "whole_frame_s": r["median_s"]["whole frame"], "iterations": r["iterations"]})
    for scale in (0.25, 0.5, 1.0):
        w, h = int(512 * scale), int(424 * scale)
        f = 365.0 * scale
        cfg, depth, bg = load_scene("kinect_v2", [
            f"camera.width={w}", f"camera.height={h}",
            f"camera.intrinsics={{fx: {f}, fy: {f}, cx: {(w - 1) / 2}, cy: {(h - 1) / 2}}}",
            f"synthetic.cache=.cache/bench/kinect_v2_{w}", f"input.frames=.cache/bench/kinect_v2_{w}/frames/*.png",
            f"input.background=.cache/bench/kinect_v2_{w}/background/*.png"])
        r, _, _ = time_scene(cfg, depth, bg, device, repeats)
        rows["resolution"].append({"pixels": w * h, "image": [w, h], "entries": r["mask_entries"],
                                   "whole_frame_s": r["median_s"]["whole frame"], "iterations": r["iterations"]})
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), dpi=90)
    a.loglog([x["locations"] for x in rows["locations"]], [x["whole_frame_s"] for x in rows["locations"]], "o-")
    a.set_xlabel("locations (grid step 0.2 to 0.05 m)")
    a.set_ylabel("whole frame (s)")
    b.loglog([x["pixels"] for x in rows["resolution"]], [x["whole_frame_s"] for x in rows["resolution"]], "o-")
    b.set_xlabel("pixels (128x106 to 512x424)")
    for ax in (a, b):
        ax.grid(alpha=0.3, which="both")
    fig.suptitle(f"dpom-warp whole-frame time, {device}, median of {repeats}")
    fig.tight_layout()
    fig.savefig(out / f"scaling_{device.replace(':', '')}.png")
    plt.close(fig)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=4, help="frames per engine call for the batched figure (1: none)")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--reference", action="store_true", help="also time the NumPy reference on kinect_v2 (slow)")
    ap.add_argument("--sweep", action="store_true", help="time against locations and resolution, with a plot")
    ap.add_argument("--output", default="runs/bench")
    a = ap.parse_args()

    import warp as wp

    from dpom_warp import reference as ref
    from dpom_warp.engine import resolve_device

    device = resolve_device(a.device)
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    result = {"machine": f"{platform.machine()}, {platform.node()}", "device": device,
              "device_name": wp.get_device(device).name, "python": platform.python_version(),
              "warp": wp.__version__, "repeats": a.repeats, "scenes": {}}
    lines = [f"Machine: {result['machine']}; device {device} ({result['device_name']}); Warp "
             f"{wp.__version__}; median of {a.repeats} runs after a warm-up", "",
             "| scene | image | locations | mask entries | iterations | engine MB | background | "
             "masks+lists | one iteration | whole frame | with graph | batched, per frame |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in a.scenes:
        cfg, depth, bg = load_scene(name)
        sequence = scene_frames(name, a.batch) if a.batch > 1 else None
        r, geom, warm = time_scene(cfg, depth, bg, device, a.repeats, a.batch, sequence)
        if a.reference and name == "kinect_v2":
            params = dataclasses.replace(cfg.model)
            t = time.perf_counter()
            want = ref.mean_field(depth, geom, ref.background_from_frames(bg, params), params)
            r["reference_whole_frame_s"] = time.perf_counter() - t
            r["reference_max_rho_difference"] = float(np.abs(want["rho"] - warm.rho).max())
            r["speedup_vs_reference"] = r["reference_whole_frame_s"] / r["median_s"]["whole frame"]
        result["scenes"][name] = r
        m = r["median_s"]
        lines.append(f"| {name} | {r['image'][0]}x{r['image'][1]} | {r['locations']} | {r['mask_entries']} | "
                     f"{r['iterations']} | {r['engine_memory_mb']:.0f} | {1000 * m['background model (kernel)']:.0f} ms | "
                     f"{1000 * m['masks, Delta, lists, sort']:.0f} ms | {1000 * m['one iteration']:.1f} ms | "
                     f"{1000 * m['whole frame']:.0f} ms | {1000 * m['whole frame, graph']:.0f} ms | "
                     + (f"{1000 * m['per frame, batched']:.0f} ms (x{a.batch}, {r['frames_per_s_batched']:.1f} fps) |"
                        if a.batch > 1 else "- |"))
        print(lines[-1], flush=True)
    v2 = result["scenes"].get("kinect_v2", {})
    if "speedup_vs_reference" in v2:
        lines.append(f"\nkinect_v2: NumPy reference {v2['reference_whole_frame_s']:.1f} s, Warp "
                     f"{v2['median_s']['whole frame']:.2f} s: {v2['speedup_vs_reference']:.1f}x "
                     f"(max |rho difference| {v2['reference_max_rho_difference']:.1e})")
    if a.sweep:
        result["sweep"] = sweep(device, a.repeats, out)
        lines.append(f"\nscaling plot: {out / ('scaling_' + device.replace(':', '') + '.png')}")
    print("\n".join(lines))
    (out / f"bench_{device.replace(':', '')}.json").write_text(json.dumps(result, indent=2))
    (out / f"bench_{device.replace(':', '')}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

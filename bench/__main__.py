"""Kernel benchmarks: time per stage on standard scenes, Warp against the NumPy reference.

    python -m bench [--device cpu] [--repeats 5] [--batch 4] [--batch-sweep N ...] [--moda-frames 8] [--reference]
                    [--whole-run] [--sweep] [--output runs/bench]
    python -m bench --kernels [--scenes ...] [--repeats 5] [--kernels-batch N]

Scenes (rendered once into .cache/bench/, seeded):
- kinect_v2: 512x424, people, 6 x 6.5 m ground grid at 0.1 m (the people demo);
- kinect_v2_far: the same camera 2 m high, pitch 15, six people, the grid 7 x 7 m reaching
  7.5 m (a realistic people scene: more of the room in view, more entries a frame);
- kinect_v1: 640x480, people, the same area at 0.05 m;
- drones: 512x424, 4 x 4.5 x 2.4 m voxel grid at 0.1 m (the drone demo's room).
Each scene runs two ways: the fast defaults (input.stride auto, sparse iterations) and the
exact path (engine.exact: full resolution, every pass full), each scored for MODA over the
first --moda-frames frames of the scene's sequence; the sparse iterations, the pruning bound,
the pixel table and the sized stack scratch are measured against full passes, no bound, the tile
index and one stack size at the same stride (time and max |rho* difference|). Each Warp figure is
the median of `--repeats` runs after a warm-up run (which compiles the kernels and sizes the
lists); the NumPy reference, with --reference, runs once on kinect_v2 and kinect_v2_far (full
resolution).
Whole frames are timed three ways: the iteration loop driven from Python (a host check every
check_every iterations), the loop replayed as a captured graph (no host sync), and `--batch`
different frames of the scene in one engine call (time per frame = batch time / batch);
--batch-sweep N... adds the fast path's time per frame for each batch size N (the graph as
configured), split into the engine's lists (with the reduction), iterations, threshold and the
rest of the call.
--whole-run times `dpom-warp run` with pictures on kinect_v2 and kinect_v2_far (32 frames against
2: the marginal frame; the engine's setup, ~2 s and noisy, cancels). --sweep also times whole
frames against the number of locations (grid step) and the image resolution on kinect_v2, and
plots both. --kernels instead times each kernel of the fast path's frame (every launch followed
by a device sync, so the sum exceeds the whole frame a little), summed over a frame, median of
--repeats frames; with --kernels-batch N, of N frames in one engine call, per frame.
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

from bench.scenes import SCENES, load_scene, scene_frames

def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def time_scene(cfg, depth, bg, device, repeats, batch=1, sequence=None):
    """Per-stage medians of one frame on `device` with the config's inference path (stride,
    sparse iterations); with batch > 1 also the frames of `sequence` = (frames (batch, H, W),
    their background frames) in one engine call. Frames are given at full resolution and
    reduced by the engine inside the timed whole frame, as a run does (on a GPU by a kernel)."""
    import warp as wp

    from dpom_warp.worker import make_engine

    cfg = dataclasses.replace(cfg, engine=cfg.engine.model_copy(update={"graph": "off"}))
    t = time.perf_counter()
    engine = make_engine(cfg, cfg.camera, device, 1)
    reduce = engine.resolution.frames
    engine.set_background_frames(reduce(bg))
    setup = time.perf_counter() - t
    warm = engine.infer(depth)
    lengths = engine.views[0].lists.counts.numpy()  # after the bound: what the passes walk
    median_list = float(np.median(lengths[lengths > 0])) if (lengths > 0).any() else 0.0
    small = reduce(depth)

    def one_iteration():
        engine.iterate(0, 0.0, 0.1)
        wp.synchronize_device(device)

    stages = {
        "background model (kernel)": median_time(
            lambda: (engine.set_background_frames(reduce(bg)), wp.synchronize_device(device)), repeats),
        "masks, Delta, lists, sort": median_time(
            lambda: (engine.build_lists(small), wp.synchronize_device(device)), repeats),
    }
    engine.done.zero_()  # after infer every frame is done and the pass would skip it
    stages["one iteration"] = median_time(one_iteration, repeats)
    stages["whole frame"] = median_time(lambda: engine.infer(depth), repeats)
    engine.graph = True
    graph_error = None
    try:
        engine.infer(depth)  # captures the graph
        stages["whole frame, graph"] = median_time(lambda: engine.infer(depth), repeats)
    except Exception as e:  # reported in the table and the JSON, not hidden
        graph_error = f"{type(e).__name__}: {e}"
        stages["whole frame, graph"] = float("nan")
        engine.graph = False
    r = engine.resolution
    result = {"image": [engine.views[0].width, engine.views[0].height], "stride": r.stride, "reduce": r.reduce,
              "sparse_epsilon": cfg.model.sparse_epsilon, "grid": list(cfg.grid.shape),
              "locations": int(cfg.grid.size), "mask_entries": warm.entries,
              "entries_after_bound": warm.kept_entries, "pruned_locations": warm.pruned,
              "live_locations_at_end": warm.live, "iterations": warm.iterations,
              "median_list_entries": median_list,
              "engine_setup_s": setup, "engine_memory_mb": engine.memory_bytes() / 2**20,
              "mask_index": "table" if engine.views[0].use_table else "tiles",
              "median_s": stages, "graph_error": graph_error}
    if batch > 1:
        del engine
        frames, seq_bg = sequence
        many = make_engine(cfg, cfg.camera, device, batch)
        many.set_background_frames(reduce(seq_bg))
        got = many.infer_batch(frames)
        stages["per frame, batched"] = median_time(lambda: many.infer_batch(frames), repeats) / batch
        result.update(batch=batch, batch_iterations=[r.iterations for r in got],
                      batch_memory_mb=many.memory_bytes() / 2**20,
                      frames_per_s_batched=1.0 / stages["per frame, batched"])
    return result, warm


INGREDIENTS = {"full_passes": ["model.sparse_epsilon=0"], "no_bound": ["model.bound_rounds=0"],
               "tiles": ["engine.mask_index=tiles"], "one_stack": [], "fast": []}


def ingredient_times(name, stride, device, repeats, table=True):
    """{ingredient: (median whole-frame seconds, rho*, median lists seconds)} at the fast
    path's stride: every pass full, sparse iterations without the pruning bound, the lists
    from the tile index instead of the pixel table (only where the fast path has a `table`),
    the passes' stack scratch in one size instead of sized to each list (CPU only), and the
    fast path; the engines are timed in turn, `repeats` rounds, so each median sees
    the same machine."""
    import dataclasses as dc

    from dpom_warp import kernels as K
    from dpom_warp.worker import make_engine

    engines = {}
    for key, sets in INGREDIENTS.items():
        if key == "tiles" and not table:  # the fast path's lists come from the tiles already
            continue
        cfg, depth, bg = load_scene(name, [f"input.stride={stride}"] + sets)
        cfg = dc.replace(cfg, engine=cfg.engine.model_copy(update={"graph": "off"}))
        engine = make_engine(cfg, cfg.camera, device, 1)
        if key == "one_stack":  # the passes' stack scratch in one size (CPU; a GPU has none)
            if engine.local_scratch == 0:
                continue
            engine.local_scratch = K.ONE_STACK
        engine.set_background_frames(engine.resolution.frames(bg))
        engines[key] = (engine, depth, engine.infer(depth).rho_star, [], [])
    for _ in range(repeats):
        for engine, depth, _, times, lists in engines.values():
            t = time.perf_counter()
            r = engine.infer(depth)
            times.append(time.perf_counter() - t)
            lists.append(r.timings["lists_s"])
    return {key: (statistics.median(times), rho_star, statistics.median(lists))
            for key, (_, _, rho_star, times, lists) in engines.items()}


def batch_sweep(cfg, seq, device, repeats, sizes):
    """({batch: median seconds a frame}, {batch: {part: median seconds a frame}}) of the config's
    path (its graph setting: a CUDA graph on a GPU) for each batch size: `batch` frames of the
    sequence seq = (frames, background) in one engine call at full resolution, reduced by the
    engine as in a run; sizes above the sequence's length take its frames again in order (the
    same work a frame: the figure is time, not MODA). The parts are Engine.infer_batch's
    timings (the lists with the reduction, the iterations, the threshold and within it the joint
    test's lists) and the rest of the call (its results' copies)."""
    from dpom_warp.worker import make_engine

    frames, bg = seq[0], seq[1]
    out, parts = {}, {}
    for b in sizes:
        engine = make_engine(cfg, cfg.camera, device, b)
        engine.set_background_frames(engine.resolution.frames(bg))
        many = frames[np.arange(b) % len(frames)]
        engine.infer_batch(many)  # compiles, sizes the lists, captures the graph
        calls = []

        def call():
            t = time.perf_counter()
            timings = engine.infer_batch(many)[0].timings
            calls.append(dict(timings, rest_s=time.perf_counter() - t - timings["total_s"]))
        out[b] = median_time(call, repeats) / b
        parts[b] = {k: statistics.median(c[k] for c in calls) / b
                    for k in ("lists_s", "iterations_s", "threshold_s", "joint_lists_s", "rest_s")}
        engine = None  # its buffers go before the next batch size's
    return out, parts


def sweep_parts(parts: dict) -> str:
    """'lists L, iterations I, threshold T (joint lists J), rest R ms' of batch_sweep's parts
    of a frame (the joint test's lists are part of the threshold step)."""
    ms = {k: 1000 * v for k, v in parts.items()}
    joint = f" (joint lists {ms['joint_lists_s']:.2f})" if "joint_lists_s" in ms else ""
    return (f"lists {ms['lists_s']:.2f}, iterations {ms['iterations_s']:.2f}, threshold "
            f"{ms['threshold_s']:.2f}{joint}, rest {ms['rest_s']:.2f} ms")


def score_scene(cfg, device, seq, n):
    """MODA, precision, recall and mean position error of the config's path over the first
    `n` frames of a rendered sequence seq = scene_frames(..., with_truth=True), and each
    frame's rho*."""
    from dpom_warp.evaluate import score_frames
    from dpom_warp.geometry import build_geometry
    from dpom_warp.worker import make_engine
    from dpom_warp.worker import detections_of

    frames, bg, names, truth = seq
    frames, names = frames[:n], names[:n]
    geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    engine = make_engine(cfg, cfg.camera, device, 1)
    engine.set_background_frames(engine.resolution.frames(bg))
    dims = 3 if cfg.grid.mode == "voxel" else 2
    found, maps = {}, []
    for f, depth in zip(names, frames):
        res = engine.infer(depth)
        maps.append(res.rho_star)  # (the engine's, before the joint test)
        _, dets = detections_of(res, geom, cfg)  # as a run detects them
        found[f] = np.array([[d.x, d.y, d.z][:dims] for d in dets]).reshape(-1, dims)
    s = score_frames(found, {f: truth[f] for f in names}, cfg.evaluation.match_distance,
                     cfg.evaluation.hidden_visibility, geom.centre[:2])
    return {k: s[k] for k in ("moda", "precision", "recall", "mean_error_m", "n_gt")}, maps


LONG_RUN = 32  # whole_run_marginal: frames of the long run


def kernel_times(cfg, depth, bg, device, repeats, batch=1):
    """{kernel: (median ms a frame, launches a frame)} of `cfg`'s frame `depth` (background
    frames `bg`): every launch (wp.launch and the engine's recorded ones) timed with a device
    sync after it, summed over the frame; the most costly first. With batch > 1, `depth` holds
    that many frames (n, H, W), inferred in one engine call, and the times are per frame. The
    row "rest of the call" is the call's median time less its launches' (host work and copies)."""
    import warp as wp

    from dpom_warp.engine.launch import Launcher
    from dpom_warp.worker import make_engine

    cfg = dataclasses.replace(cfg, engine=cfg.engine.model_copy(update={"graph": "off"}))
    engine = make_engine(cfg, cfg.camera, device, batch)
    engine.set_background_frames(engine.resolution.frames(bg))
    infer = engine.infer_batch if batch > 1 else engine.infer
    infer(depth)  # at full resolution, reduced by the engine as in a run
    frames, calls, acc = [], [], {}

    def timed(key, launch):
        t = time.perf_counter()
        out = launch()
        wp.synchronize_device(device)
        acc.setdefault(key, []).append(time.perf_counter() - t)
        return out

    launch, recorded = wp.launch, Launcher.__call__
    wp.launch = lambda kernel, *x, **k: timed(kernel.key, lambda: launch(kernel, *x, **k))
    Launcher.__call__ = lambda self, kernel, *x: timed(kernel.key, lambda: recorded(self, kernel, *x))
    try:
        for _ in range(repeats):
            acc = {}
            t = time.perf_counter()
            infer(depth)
            calls.append(time.perf_counter() - t)
            frames.append(acc)
    finally:
        wp.launch, Launcher.__call__ = launch, recorded
    keys = sorted({k for f in frames for k in f}, key=lambda k: -statistics.median(sum(f.get(k, [0])) for f in frames))
    out = {k: (1000 * statistics.median(sum(f.get(k, [0])) for f in frames) / batch,
               statistics.median(len(f.get(k, [])) for f in frames)) for k in keys}
    rest = statistics.median(c - sum(sum(v) for v in f.values()) for c, f in zip(calls, frames))
    out["rest of the call"] = (1000 * rest / batch, 0)
    return out


def whole_run_marginal(repeats, name="kinect_v2"):
    """Marginal per-frame time of `dpom-warp run` on a people scene with pictures on, the
    defaults otherwise: (time for LONG_RUN frames - time for 2) / (LONG_RUN - 2), medians of
    `repeats` runs after an untimed round."""
    import tempfile

    from dpom_warp.loading import load_config
    from dpom_warp.pipeline import run

    path, sets = SCENES[name]
    cache = f".cache/bench/run{LONG_RUN}" + ("" if name == "kinect_v2" else f"_{name}")
    times = {2: [], LONG_RUN: []}
    for i in range(repeats + 1):  # the first round renders the frames and compiles: untimed
        for n in (2, LONG_RUN):
            frames = f"{cache}/frames/*.png" if n == LONG_RUN else f"{cache}/frames/000[01].png"
            cfg = load_config(path, list(sets) + [
                f"synthetic.cache={cache}", f"synthetic.frames={LONG_RUN}", f"input.frames={frames}",
                f"input.background={cache}/background/*.png", "evaluation.ground_truth=null",
                "output.images=true"])
            with tempfile.TemporaryDirectory() as out:
                t = time.perf_counter()
                run(cfg, out, "cpu", progress=False, log=lambda *_: None)
                if i:
                    times[n].append(time.perf_counter() - t)
    t2, tn = statistics.median(times[2]), statistics.median(times[LONG_RUN])
    return {"two_frames_s": t2, "long_run_frames": LONG_RUN, "long_run_s": tn,
            "marginal_per_frame_s": (tn - t2) / (LONG_RUN - 2)}


def sweep(device, repeats, out):
    """Whole-frame time against the number of locations and against the image resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = {"locations": [], "resolution": []}
    for step in (0.2, 0.15, 0.1, 0.075, 0.05):
        cfg, depth, bg = load_scene("kinect_v2", [f"grid.x=[-3.0, 3.0, {step}]", f"grid.y=[0.5, 7.0, {step}]",
                                                  "engine.exact=true"])
        r, _ = time_scene(cfg, depth, bg, device, repeats)
        rows["locations"].append({"step": step, "locations": r["locations"], "entries": r["mask_entries"],
                                  "whole_frame_s": r["median_s"]["whole frame"], "iterations": r["iterations"]})
    for scale in (0.25, 0.5, 1.0):
        w, h = int(512 * scale), int(424 * scale)
        f = 365.0 * scale
        cfg, depth, bg = load_scene("kinect_v2", [
            f"camera.width={w}", f"camera.height={h}",
            f"camera.intrinsics={{fx: {f}, fy: {f}, cx: {(w - 1) / 2}, cy: {(h - 1) / 2}}}",
            f"synthetic.cache=.cache/bench/kinect_v2_{w}", f"input.frames=.cache/bench/kinect_v2_{w}/frames/*.png",
            f"input.background=.cache/bench/kinect_v2_{w}/background/*.png", "engine.exact=true"])
        r, _ = time_scene(cfg, depth, bg, device, repeats)
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


PATHS = {"fast": [], "exact": ["engine.exact=true"]}
WHOLE_RUN_SCENES = ("kinect_v2", "kinect_v2_far")  # --whole-run: the people scenes
REFERENCE_SCENES = ("kinect_v2", "kinect_v2_far")


def arguments():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=4, help="frames per engine call for the batched figure (1: none)")
    ap.add_argument("--batch-sweep", type=int, nargs="+", default=[], metavar="N",
                    help="also time the fast path with N frames per engine call for each N (graph as configured)")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--moda-frames", type=int, default=8,
                    help="frames of each scene's sequence scored for MODA, both paths (0: none)")
    ap.add_argument("--reference", action="store_true",
                    help=f"also time the NumPy reference on {' and '.join(REFERENCE_SCENES)} (slow)")
    ap.add_argument("--whole-run", action="store_true",
                    help="marginal per-frame time of dpom-warp run on the people scenes given, pictures on (CPU)")
    ap.add_argument("--sweep", action="store_true", help="time against locations and resolution, with a plot")
    ap.add_argument("--kernels", action="store_true",
                    help="only: each kernel's time in the fast path's frame of each scene (a sync after each launch)")
    ap.add_argument("--kernels-batch", type=int, default=1, metavar="N",
                    help="with --kernels: N frames of the scene's sequence in one engine call (times per frame)")
    ap.add_argument("--output", default="runs/bench")
    return ap.parse_args()


def kernels_table(a, device: str, out: Path) -> None:
    """--kernels: each kernel's ms a frame and launches in each scene, to OUTPUT/kernels_DEVICE.md."""
    import warp as wp

    times = {}
    for name in a.scenes:
        cfg, depth, bg = load_scene(name)
        if a.kernels_batch > 1:
            depth, bg = scene_frames(name, a.kernels_batch)
            depth = depth[:a.kernels_batch]
        times[name] = kernel_times(cfg, depth, bg, device, a.repeats, a.kernels_batch)
    first = times[a.scenes[0]]
    kernels = list(first) + sorted({k for t in times.values() for k in t} - set(first))
    lines = [f"Machine: {platform.machine()}, {platform.node()}; device {device} ({wp.get_device(device).name}); "
             f"Warp {wp.__version__}; {a.kernels_batch} frame(s) an engine call, launches counted a call", "",
             "| kernel | " + " | ".join(f"{name}: ms a frame | launches" for name in a.scenes) + " |",
             "|---|" + "---|---|" * len(a.scenes)]
    for k in kernels:
        lines.append(f"| `{k}` | " + " | ".join(f"{t[k][0]:.2f} | {t[k][1]:g}" if k in t else "- | -"
                                               for t in times.values()) + " |")
    lines.append("| all | " + " | ".join(f"**{sum(ms for ms, _ in t.values()):.1f}** | "
                                         f"{sum(n for _, n in t.values()):g}" for t in times.values()) + " |")
    print("\n".join(lines))
    (out / f"kernels_{device.replace(':', '')}.md").write_text("\n".join(lines) + "\n")


def scene_rows(a, name: str, device: str) -> dict:
    """One scene's figures, {path: results} for the fast and exact paths (with --reference, the
    NumPy reference's time beside the exact path; with --batch-sweep, the fast path's sweep)."""
    from dpom_warp import reference as ref
    from dpom_warp.geometry import build_geometry

    seq = scene_frames(name, max(a.batch, a.moda_frames, 1), with_truth=True)
    sequence = (seq[0][:a.batch], seq[1]) if a.batch > 1 else None
    rows = {}
    for path, extra in PATHS.items():
        cfg, depth, bg = load_scene(name, extra)
        r, warm = time_scene(cfg, depth, bg, device, a.repeats, a.batch, sequence)
        r["rho_star"] = warm.rho_star
        if a.moda_frames:
            r["scores"], r["maps"] = score_scene(cfg, device, seq, a.moda_frames)
        rows[path] = r
        if a.reference and name in REFERENCE_SCENES and path == "exact":
            params = dataclasses.replace(cfg.model)
            geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
            t = time.perf_counter()
            want = ref.mean_field(depth, geom, ref.background_from_frames(bg, params), params)
            r["reference_whole_frame_s"] = time.perf_counter() - t
            r["reference_max_rho_difference"] = float(np.abs(want["rho"] - warm.rho).max())
    if a.batch_sweep:
        sweep_s, parts = batch_sweep(load_scene(name)[0], seq, device, a.repeats, a.batch_sweep)
        rows["fast"]["batch_sweep_per_frame_s"] = {str(b): t for b, t in sweep_s.items()}
        rows["fast"]["batch_sweep_parts_per_frame_s"] = {str(b): p for b, p in parts.items()}
    fast, exact = rows["fast"], rows["exact"]
    # what the sparse iterations and the pruning bound contribute, at the fast path's stride:
    # every pass full, then sparse iterations without the bound
    ingredients = ingredient_times(name, fast["stride"], device, max(5, a.repeats),
                                   table=fast["mask_index"] == "table")
    for key, (seconds, rho_star, lists) in ingredients.items():
        fast[f"{key}_same_stride_whole_frame_s"] = seconds
        fast[f"{key}_same_stride_lists_s"] = lists
        if key != "fast":
            fast[f"{key}_vs_fast_max_rho_star_difference"] = float(np.abs(ingredients["fast"][1] - rho_star).max())
    fast["fast_vs_exact_max_rho_star_difference"] = float(np.abs(fast["rho_star"] - exact["rho_star"]).max())
    if a.moda_frames:
        fast["fast_vs_exact_max_rho_star_difference_sequence"] = float(max(
            np.abs(x - y).max() for x, y in zip(fast.pop("maps"), exact.pop("maps"))))
    for r in rows.values():
        r.pop("rho_star")
    return rows


def table_row(name: str, path: str, r: dict, batch: int) -> str:
    m, sc = r["median_s"], r.get("scores")
    return (f"| {name} | {path} | {r['image'][0]}x{r['image'][1]} | {r['mask_entries']} | "
            f"{r['entries_after_bound'] if r['entries_after_bound'] is not None else '-'} | {r['iterations']} | "
            f"{r['live_locations_at_end']} | {1000 * m['masks, Delta, lists, sort']:.1f} ms | "
            f"{1000 * m['one iteration']:.2f} ms | **{1000 * m['whole frame']:.1f} ms** | "
            f"{1000 * m['whole frame, graph']:.1f} ms | "
            + (f"{1000 * m['per frame, batched']:.1f} ms (x{batch}) | " if batch > 1 else "- | ")
            + (f"{sc['moda']:.3f} | {sc['mean_error_m']:.3f} m |" if sc else "- | - |"))


def scene_notes(result: dict, repeats: int) -> list[str]:
    """The lines under the table: each scene's paths and ingredients, its batch sweep, the
    NumPy reference's time (and each path's speed-up over it, added to `result`)."""
    notes = []
    for name, rows in result["scenes"].items():
        f, e = rows["fast"], rows["exact"]
        notes.append(f"{name}: fast {1000 * f['median_s']['whole frame']:.1f} ms vs exact "
                     f"{1000 * e['median_s']['whole frame']:.1f} ms ({e['median_s']['whole frame'] / f['median_s']['whole frame']:.1f}x); "
                     f"at stride {f['stride']}, every pass full {1000 * f['full_passes_same_stride_whole_frame_s']:.1f} ms, "
                     f"sparse iterations {1000 * f['no_bound_same_stride_whole_frame_s']:.1f} ms, with the pruning bound "
                     f"{1000 * f['fast_same_stride_whole_frame_s']:.1f} ms (timed in turn, median of "
                     f"{max(5, repeats)}; {f['pruned_locations']} of {f['locations']} locations "
                     f"pruned, {f['entries_after_bound']} of {f['mask_entries']} entries left); max |rho* difference| "
                     f"against every pass full {f['full_passes_vs_fast_max_rho_star_difference']:.1e}, against no bound "
                     f"{f['no_bound_vs_fast_max_rho_star_difference']:.1e} (epsilon {f['sparse_epsilon']:g}); "
                     + (f"lists from the tile index {1000 * f['tiles_same_stride_lists_s']:.1f} ms against the "
                        f"pixel table's {1000 * f['fast_same_stride_lists_s']:.1f} ms (whole frame "
                        f"{1000 * f['tiles_same_stride_whole_frame_s']:.1f} ms; the same lists: max |rho* "
                        f"difference| {f['tiles_vs_fast_max_rho_star_difference']:.0e}); " if f["mask_index"] == "table"
                        else "lists from the tile index (facing planes: no pixel table); ")
                     + (f"the passes' stack scratch in one size (2 KiB zeroed a pixel) "
                        f"{1000 * f['one_stack_same_stride_whole_frame_s']:.1f} ms, sized to the list "
                        f"{1000 * f['fast_same_stride_whole_frame_s']:.1f} ms (lists of median "
                        f"{f['median_list_entries']:.0f} entries after the bound; max |rho* difference| "
                        f"{f['one_stack_vs_fast_max_rho_star_difference']:.0e}); "
                        if "one_stack_same_stride_whole_frame_s" in f else "")
                     + 
                     f"fast vs exact max |rho* difference| {f['fast_vs_exact_max_rho_star_difference']:.2f} "
                     "(another resolution: judged by MODA)")
    for name, rows in result["scenes"].items():
        if "batch_sweep_per_frame_s" in rows["fast"]:
            notes.append(f"{name}: fast path, frames per engine call (graph as configured): " + ", ".join(
                f"x{b} {1000 * t:.2f} ms a frame ({1 / t:.0f} frames/s: " + sweep_parts(
                    rows["fast"]["batch_sweep_parts_per_frame_s"][b]) + ")"
                for b, t in rows["fast"]["batch_sweep_per_frame_s"].items()))
    for name, rows in result["scenes"].items():
        if "reference_whole_frame_s" not in rows["exact"]:
            continue
        ref_s = rows["exact"]["reference_whole_frame_s"]
        for path in PATHS:
            rows[path]["speedup_vs_reference"] = ref_s / rows[path]["median_s"]["whole frame"]
        notes.append(f"{name}: NumPy reference {ref_s:.1f} s (full resolution, exact); fast path "
                     f"**{rows['fast']['speedup_vs_reference']:.0f}x**, exact path "
                     f"{rows['exact']['speedup_vs_reference']:.1f}x (exact rho vs reference: max difference "
                     f"{rows['exact']['reference_max_rho_difference']:.1e})")
    return notes


def main():
    a = arguments()
    import warp as wp

    from dpom_warp.engine import resolve_device

    device = resolve_device(a.device)
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    if a.kernels:
        kernels_table(a, device, out)
        return
    result = {"machine": f"{platform.machine()}, {platform.node()}", "device": device,
              "device_name": wp.get_device(device).name, "python": platform.python_version(),
              "warp": wp.__version__, "repeats": a.repeats, "scenes": {}}
    lines = [f"Machine: {result['machine']}; device {device} ({result['device_name']}); Warp "
             f"{wp.__version__}; median of {a.repeats} runs after a warm-up", "",
             "| scene | path | image | mask entries | after the bound | iterations | live at end | masks+lists | "
             "one full iteration | whole frame | with graph | batched, per frame | MODA | mean error |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in a.scenes:
        result["scenes"][name] = rows = scene_rows(a, name, device)
        for path, r in rows.items():
            lines.append(table_row(name, path, r, a.batch))
            print(lines[-1], flush=True)
    notes = scene_notes(result, a.repeats)
    if a.whole_run:
        result["whole_run"] = {}
        for name in [n for n in a.scenes if n in WHOLE_RUN_SCENES]:
            result["whole_run"][name] = w = whole_run_marginal(max(1, min(a.repeats, 3)), name)
            notes.append(f"dpom-warp run, {name}, pictures on: 2 frames {w['two_frames_s']:.2f} s, "
                         f"{LONG_RUN} frames {w['long_run_s']:.2f} s: **{1000 * w['marginal_per_frame_s']:.0f} ms per extra "
                         f"frame** (fast path; the frame's inference alone: "
                         f"{1000 * result['scenes'][name]['fast']['median_s']['whole frame']:.0f} ms above)")
    lines += [""] + notes
    if a.sweep:
        result["sweep"] = sweep(device, a.repeats, out)
        lines.append(f"\nscaling plot (exact path): {out / ('scaling_' + device.replace(':', '') + '.png')}")
    print("\n".join([""] + notes))
    (out / f"bench_{device.replace(':', '')}.json").write_text(json.dumps(result, indent=2))
    (out / f"bench_{device.replace(':', '')}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

"""`dpom-warp run`: a sequence of depth frames in, detections, maps, pictures and scores out."""

from __future__ import annotations

import dataclasses
import glob
import itertools
import json
import platform
import shutil
import statistics
import time
from collections import Counter
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .detect import detect
from .engine import Engine, ListOverflow, MemoryBudgetError, resolve_device
from .evaluate import load_ground_truth, score_frames
from .background import BackgroundEstimator, sample_frames
from .geometry import build_geometry
from .resolution import Resolution, auto_stride
from .ground import fit_ground_files
from .io import (TEMP_MARK, InputError, WorkerError, read_depth, write_json_atomic,
                 write_npy_atomic, write_text_atomic)
from .synthetic import generate

CSV_HEADER = "frame,x,y,z,rho,u0,v0,u1,v1"



def expand(pattern: str, key: str) -> list[Path]:
    files = sorted(Path(p) for p in glob.glob(pattern))
    files = [f for f in files if f.is_file()]
    if not files:
        raise InputError(f"{key}: no files match {pattern!r}")
    return files


def fit_camera_pose(cfg: RunConfig, files: list[Path], log=print):
    """camera.extrinsics: auto. Fit the floor on `files` and return the posed camera and a
    report for summary.json.

    Raises:
        InputError: naming the frames, when no floor plane is found in them.
    """
    t = time.perf_counter()
    fit = fit_ground_files(files, cfg.camera, cfg.inputs.depth_scale, cfg.ground)
    kind = "background frame" if cfg.inputs.background else "frame"
    log(f"ground plane from {len(files)} {kind}{'s' if len(files) > 1 else ''}: camera "
        f"{fit.camera_height:.3f} m above the floor, pitch {fit.pitch_deg:.2f} deg, roll "
        f"{fit.roll_deg:.2f} deg ({fit.inlier_count} inliers, rms {1000 * fit.rms_m:.1f} mm)")
    report = {**fit.report(), "rms_m": fit.rms_m, "frames": [str(f) for f in files],
              "fit_s": time.perf_counter() - t}
    return dataclasses.replace(cfg.camera, T_world_from_camera=fit.T_world_from_camera), report


RUN_STATE = "run.json"
OUTPUTS = ("maps", "images", "frames", "plots", "ply", "detections.csv", "summary.json", "eval.json",
           RUN_STATE)


def prepare_output(out: Path, resolved: dict, overwrite: bool, resume: bool) -> None:
    """Make `out` ready: refuse a non-empty folder unless overwriting or resuming a run of
    the same config; remove what an interrupted write left behind."""
    state = {"config": _jsonable(resolved)}
    if out.exists() and any(out.iterdir()):
        if resume:
            path = out / RUN_STATE
            try:
                before = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError):
                raise ConfigError(f"--resume: {out} holds no resumable run ({RUN_STATE} missing "
                                  f"or unreadable)") from None
            if before != json.loads(json.dumps(state)):
                diff = _first_difference(before.get("config", {}), state["config"])
                raise ConfigError(f"--resume: {out} holds a run of another config ({diff}); "
                                  f"expected the same config, or use --overwrite")
        elif overwrite:
            for name in OUTPUTS:
                target = out / name
                if target.is_dir():
                    shutil.rmtree(target)
                elif target.exists():
                    target.unlink()
        else:
            raise ConfigError(f"output.dir: {out} is not empty; expected an empty or new folder "
                              f"(use --overwrite to replace its results or --resume to continue)")
    out.mkdir(parents=True, exist_ok=True)
    for stale in list(out.glob(f".*{TEMP_MARK}*")) + list(out.glob(f"*/.*{TEMP_MARK}*")):
        stale.unlink()  # temporary files of a killed run
    write_json_atomic(out / RUN_STATE, state)


def _first_difference(a, b, path=""):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
    return f"{path}: {a!r} then, {b!r} now"


def check_frames(frames: list[Path], scale: float, shape, strict: bool) -> tuple[list[Path], list[dict]]:
    """Read every frame once before any output is written. Returns the good frames and the
    skipped ones with reasons; with `strict`, or when no frame is good, the first error."""
    good, skipped = [], []
    for f in frames:
        try:
            depth = read_depth(f, scale, shape)
            if not np.any(depth > 0):
                raise InputError(f"{f}: no depth readings (every pixel is 0)")
            good.append(f)
        except InputError as e:
            if strict:
                raise
            skipped.append({"frame": f.name, "reason": str(e)})
    if not good:
        raise InputError(skipped[0]["reason"] + (f" (none of the {len(frames)} frames is usable)"
                                                 if len(frames) > 1 else ""))
    dup = next((s for s, n in Counter(f.stem for f in good).items() if n > 1), None)
    if dup:
        raise ConfigError(f"input.frames: two frames share the name {dup!r} (outputs are named "
                          f"by it); expected distinct names")
    return good, skipped


def run(cfg: RunConfig, output_dir: str | None = None, device: str | None = None,
        progress: bool = True, log=print, strict: bool = False, overwrite: bool = False,
        resume: bool = False, workers: int = 1) -> dict:
    """Run DPOM over the configured frames; returns the summary also written to summary.json.

    A frame whose file is bad, or whose lists would exceed the memory budget, is reported
    and skipped (listed in summary.json), unless `strict`. Each frame's outputs (map,
    picture, then its record in frames/) are written atomically, so an interrupted run
    leaves whole files and `resume` continues it to the same final files. With `workers` > 1
    frames are processed by that many processes, each with its own engine (Warp runs CPU
    kernels on one thread), giving the same files.
    """
    t_start = time.perf_counter()
    out = Path(output_dir or cfg.output.dir)
    if cfg.synthetic is not None:
        t = time.perf_counter()
        cached = (Path(cfg.synthetic_cache) / "scene.json").exists()
        generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
        log(f"synthetic scene: {cfg.synthetic.frames} frames in {cfg.synthetic_cache} "
            f"({'checked' if cached else 'generated'} in {time.perf_counter() - t:.1f} s)")
    shape = (cfg.camera.height, cfg.camera.width)
    scale = cfg.inputs.depth_scale
    frames, skipped = check_frames(expand(cfg.inputs.frames, "input.frames"), scale, shape, strict)
    auto_bg = cfg.inputs.auto_background
    bg_files = (expand(cfg.inputs.background, "input.background")
                if cfg.inputs.background and not auto_bg else [])
    bg_frames = [read_frame(cfg, f) for f in bg_files]  # a bad one is fatal
    for item in skipped:
        log(f"skipping {item['reason']}")
    truth = load_ground_truth(cfg.evaluation.ground_truth) if cfg.evaluation.ground_truth else None
    if truth is not None:
        missing = [f.name for f in frames if f.name not in truth]
        if missing:
            raise InputError(f"{cfg.evaluation.ground_truth}: no ground truth for frame {missing[0]}")
    try:
        dev = resolve_device(device or cfg.device)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    sample = ([frames[i] for i in sample_frames(len(frames), cfg.inputs.background_auto.max_frames)]
              if auto_bg else [])
    camera, ground = cfg.camera, None
    if cfg.pose_auto:
        if auto_bg and len(sample) >= cfg.inputs.background_auto.min_frames:
            camera, ground = fit_pose_on_estimate(cfg, sample, dev, log)
        else:
            camera, ground = fit_camera_pose(cfg, bg_files or frames[:cfg.ground_frames], log)

    t = time.perf_counter()
    geometry = build_geometry(camera, cfg.grid, cfg.obj)  # full resolution: boxes, pictures
    if workers > 1 and cfg.model.warm_start:
        raise ConfigError("model.warm_start: each frame starts from the previous one, so frames "
                          "must run in order; expected --workers 1 with it")
    try:
        engine = make_engine(cfg, camera, dev, cfg.engine.batch)
    except MemoryBudgetError as e:
        raise ConfigError(f"engine.memory_gb: {e}; coarsen grid.x/grid.y or raise the budget") from None
    auto_report, given = None, None
    if bg_frames:
        engine.set_background_frames(engine.resolution.frames(np.stack(bg_frames)))
        background = f"{len(bg_files)} background frames"
    elif auto_bg:
        estimator, auto_report = estimate_background(cfg, sample, engine.height, engine.width, dev,
                                                     engine.resolution)
        given = estimator.result()  # (Background, fallback): also what --workers' engines take
        engine.set_background(*given)
        auto_report["fallback_pixels"] = engine.fallback_pixels
        auto_report["fallback_share"] = engine.fallback_pixels / engine.n_pixels
        background = (f"auto from {len(sample)} of the frames ({engine.fallback_pixels} of "
                      f"{engine.n_pixels} pixels left to the floor-only model)")
    else:
        background = "floor plane only"
    del bg_frames
    t_setup = time.perf_counter() - t
    prepare_output(out, cfg.resolved, overwrite, resume)
    r = engine.resolution
    log(f"device {dev}; {geometry.locations.shape[0]} locations {cfg.grid.shape}; "
        f"{len(frames)} frames; background: {background}; inference at {engine.width}x"
        f"{engine.height} pixels (stride {r.stride}{', ' + r.reduce if r.stride > 1 else ''}"
        f"{', exact path' if cfg.engine.exact else ''})")

    records = {}
    todo = []
    for f in frames:
        record = out / "frames" / f"{f.stem}.json"
        if resume and record.exists():
            records[f.name] = json.loads(record.read_text())
        else:
            todo.append(f)
    if resume:
        log(f"resuming: {len(records)} frames already done, {len(todo)} to go")
    if workers > 1 and len(todo) > 1:
        outcomes = _process_in_workers(cfg, camera, given or bg_files, engine, todo, out, truth,
                                       workers, progress)
    else:
        outcomes = _process_here(cfg, engine, geometry, todo, out, truth, progress)
    try:
        for f, record, error in outcomes:
            if error is None:
                records[f.name] = record
                continue
            if strict:
                raise InputError(error)
            skipped.append({"frame": f.name, "reason": error})
            log(f"skipping {error}")
    finally:
        outcomes.close()  # stops the worker pool at once on an error or Ctrl-C
    done = [f for f in frames if f.name in records]
    summary = summarise(cfg, out, done, records, skipped, truth, geometry, dev, background, ground,
                        engine.grown)
    if auto_report is not None:
        summary["background_auto"] = auto_report
    summary["inference"] = {"stride": r.stride, "reduce": r.reduce, "image": [engine.width, engine.height],
                            "sparse_epsilon": cfg.model.sparse_epsilon,
                            "warm_start": cfg.model.warm_start, "exact": cfg.engine.exact}
    summary["timings"]["setup_s"] = t_setup
    summary["timings"]["total_s"] = time.perf_counter() - t_start
    write_json_atomic(out / "summary.json", _jsonable(summary))
    if truth is not None and done:  # the curves of `dpom-warp eval`, from the maps just written
        from .evaluate import evaluate_runs

        results = evaluate_runs([out], cfg.evaluation.ground_truth, cfg.evaluation.hidden_visibility)
        write_json_atomic(out / "eval.json", _jsonable(results))
        if cfg.evaluation.plots:
            from .plots import write_figures

            write_figures(results, out / "plots")
    return summary


def estimate_background(cfg: RunConfig, files: list[Path], height: int, width: int, device: str,
                        resolution: Resolution | None = None, chunk: int = 16):
    """input.background: auto over `files`, streamed `chunk` frames at a time, reduced by
    `resolution` (None: full resolution). Returns the estimator and a report."""
    t = time.perf_counter()
    estimator = BackgroundEstimator(height, width, cfg.model, cfg.inputs.background_auto, device)
    for i in range(0, len(files), chunk):
        batch = np.stack([read_frame(cfg, f) for f in files[i:i + chunk]])
        estimator.add(resolution.frames(batch) if resolution else batch)
    return estimator, {"frames": len(files), "pixels": height * width,
                       "memory_bytes": estimator.memory_bytes(),
                       "estimate_s": time.perf_counter() - t}


def fit_pose_on_estimate(cfg: RunConfig, files: list[Path], device: str, log=print):
    """camera.extrinsics: auto with background: auto: the floor is fitted on the estimated
    background at full resolution (the floor people hide in a frame shows in the estimate)."""
    from .ground import GroundFitError, fit_ground_frames

    t = time.perf_counter()
    estimator, _ = estimate_background(cfg, files, cfg.camera.height, cfg.camera.width, device)
    bg, fallback = estimator.result()
    depth = np.where(fallback | (bg.outlier >= 1), 0.0, bg.mu)
    try:
        fit = fit_ground_frames([depth], cfg.camera, cfg.ground)
    except GroundFitError as e:
        raise InputError(f"{files[0]} and {len(files) - 1} more frames: in their estimated "
                         f"background: {e}") from None
    log(f"ground plane from the background estimated on {len(files)} frames: camera "
        f"{fit.camera_height:.3f} m above the floor, pitch {fit.pitch_deg:.2f} deg, roll "
        f"{fit.roll_deg:.2f} deg ({fit.inlier_count} inliers, rms {1000 * fit.rms_m:.1f} mm)")
    report = {**fit.report(), "rms_m": fit.rms_m, "frames": "estimated background of "
              f"{len(files)} frames", "fit_s": time.perf_counter() - t}
    return dataclasses.replace(cfg.camera, T_world_from_camera=fit.T_world_from_camera), report


def resolution_of(cfg: RunConfig, camera) -> Resolution:
    """input.stride (auto: resolution.auto_stride for this camera and grid) and input.reduce."""
    stride = (auto_stride(camera, cfg.grid, cfg.obj) if cfg.inputs.stride == "auto"
              else cfg.inputs.stride)
    if min(camera.width // stride, camera.height // stride) < 1:
        raise ConfigError(f"input.stride: expected a stride that leaves at least one pixel of "
                          f"the {camera.width}x{camera.height} image, found {stride}")
    return Resolution(stride, cfg.inputs.reduce, cfg.model.z_max)


def make_engine(cfg: RunConfig, camera, device: str, batch: int) -> Engine:
    """The engine of a run (engine.* options) at the run's inference resolution, for `batch`
    frames per call; it takes frames reduced by engine.resolution.frames."""
    resolution = resolution_of(cfg, camera)
    geometry = build_geometry(resolution.camera(camera), cfg.grid, cfg.obj)
    # the tile index's tiles keep about 8 x 8 full-resolution pixels' worth of the scene
    # (2 x 2 at stride 4: list building ~20 % faster than 8 x 8 there)
    tile = max(2, round(8 / resolution.stride))
    return Engine(geometry, cfg.model, device, cfg.engine.entries_per_pixel, cfg.engine.max_entries,
                  cfg.engine.memory_gb, tile=tile, batch=batch,
                  graph={"auto": None, "on": True, "off": False}[cfg.engine.graph],
                  resolution=resolution,
                  background_auto=cfg.inputs.background_auto if cfg.inputs.auto_background else None)


def _attempt(cfg, engine, geometry, f, out, truth, read=None):
    """(frame, record, None) or (frame, None, reason) for a frame that cannot be processed;
    `read` = (depth, seconds) when the frame has been read already."""
    try:
        return f, process_frame(cfg, engine, geometry, f, out, truth, read), None
    except InputError as e:
        return f, None, str(e)
    except ListOverflow as e:
        return f, None, f"{f}: {e}"


def _process_here(cfg, engine, geometry, todo, out, truth, progress):
    iterator = iter(todo)
    if progress:
        from tqdm import tqdm
        iterator = iter(tqdm(todo, unit="frame", desc="dpom", leave=False))
    while chunk := list(itertools.islice(iterator, engine.batch)):
        if len(chunk) == 1:
            yield _attempt(cfg, engine, geometry, chunk[0], out, truth)
        else:
            yield from _attempt_batch(cfg, engine, geometry, chunk, out, truth)


def _attempt_batch(cfg, engine, geometry, files, out, truth):
    """_attempt for the frames of one engine batch; frames that cannot be read are reported
    alone, and a batch whose lists overflow is retried frame by frame."""
    read = []
    for f in files:
        try:
            t = time.perf_counter()
            read.append((f, read_frame(cfg, f), time.perf_counter() - t))
        except InputError as e:
            yield f, None, str(e)
    if len(read) < 2:
        yield from (_attempt(cfg, engine, geometry, f, out, truth, (d, s)) for f, d, s in read)
        return
    t0 = time.perf_counter()
    try:
        results = engine.infer_batch(engine.resolution.frames(np.stack([depth for _, depth, _ in read])))
    except ListOverflow:
        yield from (_attempt(cfg, engine, geometry, f, out, truth, (d, s)) for f, d, s in read)
        return
    share = (time.perf_counter() - t0) / len(read)
    for (f, depth, read_s), res in zip(read, results):
        yield f, finish_frame(cfg, geometry, f, depth, res, out, truth, read_s, share), None


_worker = {}


def _worker_start(cfg, camera, background, device, cache_dir):
    """Process-pool initializer: a private copy of the kernel cache, then an engine;
    `background`: the background files, or the run's auto estimate (Background, fallback)."""
    import atexit
    import os
    import tempfile

    own = Path(tempfile.mkdtemp(prefix="dpom-warp-cache-"))
    atexit.register(shutil.rmtree, own, True)
    # Warp keeps its modules under WARP_CACHE_PATH/<version>, read when it initialises
    shutil.copytree(cache_dir, own / Path(cache_dir).name, dirs_exist_ok=True)
    os.environ["WARP_CACHE_PATH"] = str(own)
    geometry = build_geometry(camera, cfg.grid, cfg.obj)
    engine = make_engine(cfg, camera, device, batch=1)  # a worker takes frames one at a time
    if isinstance(background, tuple):
        engine.set_background(*background)
    elif background:
        engine.set_background_frames(engine.resolution.frames(np.stack([read_frame(cfg, f) for f in background])))
    import warp as wp

    _worker.update(cfg=cfg, engine=engine, geometry=geometry, cache=wp.config.kernel_cache_dir)


def _worker_frame(f, out, truth):
    w = _worker
    return _attempt(w["cfg"], w["engine"], w["geometry"], f, out, truth)


def _process_in_workers(cfg, camera, background, engine, todo, out, truth, workers, progress):
    """Frames in a pool of processes ('spawn': no Warp state is forked). The main engine
    first runs an empty frame, which compiles every kernel into the cache; each worker copies
    the cache and only loads them."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    import warp as wp

    engine.infer(np.zeros((engine.height, engine.width), np.float32))
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_start,
                               initargs=(cfg, camera, background, engine.device,
                                         wp.config.kernel_cache_dir))
    try:
        futures = [pool.submit(_worker_frame, f, out, truth) for f in todo]
        iterator = futures
        if progress:
            from tqdm import tqdm
            iterator = tqdm(futures, unit="frame", desc=f"dpom x{workers}", leave=False)
        for fut in iterator:
            try:
                yield fut.result()
            except BrokenProcessPool as e:
                raise WorkerError(f"--workers: a worker process died ({e}); finished frames are "
                                  f"kept, continue with --resume") from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def read_frame(cfg: RunConfig, f: Path) -> np.ndarray:
    return read_depth(f, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width))


def process_frame(cfg: RunConfig, engine: Engine, geometry, f: Path, out: Path, truth,
                  read: tuple[np.ndarray, float] | None = None) -> dict:
    """Infer one frame and write its map, picture and record (finish_frame); `read` =
    (depth, seconds) when the frame has been read already."""
    if read is None:
        t = time.perf_counter()
        depth = read_frame(cfg, f)
        read = depth, time.perf_counter() - t
    depth, read_s = read
    t0 = time.perf_counter()
    res = engine.infer(engine.resolution.frames(depth))
    return finish_frame(cfg, geometry, f, depth, res, out, truth, read_s, time.perf_counter() - t0)


def finish_frame(cfg: RunConfig, geometry, f: Path, depth, res, out: Path, truth, read_s: float,
                 infer_s: float) -> dict:
    """Detections of an inferred frame; writes its map, picture and record (the record last:
    a frame is done when its record exists). `infer_s` is the frame's share of a batch."""
    t1 = time.perf_counter()
    rho_map = res.rho_star.reshape(cfg.grid.shape)
    dets = detect(rho_map, geometry.locations, geometry.rect, cfg.detection.threshold,
                  cfg.detection.nms_radius)
    t2 = time.perf_counter()
    write_npy_atomic(out / "maps" / f"{f.stem}.npy", rho_map.astype(np.float32))
    if cfg.output.images:
        from .render import frame_picture
        frame_picture(out / "images" / f"{f.stem}.png", depth, rho_map, cfg.grid, dets,
                      geometry.centre[:2], truth.get(f.name) if truth else None, f.name)
    if cfg.output.ply:
        write_ply(out / "ply", f.stem, depth, geometry, dets, cfg)
    t3 = time.perf_counter()
    record = {
        "frame": f.name,
        "rows": [f"{f.name},{d.x:.4f},{d.y:.4f},{d.z:.4f},{d.rho:.6f},{d.box[0]},{d.box[1]},"
                 f"{d.box[2]},{d.box[3]}" for d in dets],
        "xy": [[d.x, d.y, d.z] if cfg.grid.mode == "voxel" else [d.x, d.y] for d in dets],
        "stats": {"frame": f.name, "detections": len(dets), "iterations": res.iterations, "live": res.live,
                  "entries": res.entries, "read_s": read_s, "infer_s": infer_s,
                  "detect_s": t2 - t1, "write_s": t3 - t2,
                  **{f"engine_{k}": v for k, v in res.timings.items()}},
    }
    write_json_atomic(out / "frames" / f"{f.stem}.json", record)
    return record


def write_ply(folder: Path, stem: str, depth, geometry, dets, cfg: RunConfig):
    """For Open3D's viewer: <stem>_points.ply (the frame's points, world metres) and
    <stem>_boxes.ply (the detected object boxes as a mesh)."""
    import open3d as o3d

    from .io import atomic_path

    ok = depth > 0
    pts = geometry.centre + depth[ok][:, None].astype(np.float64) * geometry.rays[ok]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    with atomic_path(folder / f"{stem}_points.ply") as tmp:
        o3d.io.write_point_cloud(str(tmp), cloud)
    boxes = o3d.geometry.TriangleMesh()
    size = np.array([cfg.obj.width, cfg.obj.depth or cfg.obj.width, cfg.obj.height])
    for d in dets:
        b = o3d.geometry.TriangleMesh.create_box(*size)
        lift = 0.0 if cfg.grid.mode == "ground" else size[2] / 2
        boxes += b.translate(np.array([d.x, d.y, d.z - lift]) - np.array([size[0] / 2, size[1] / 2, 0]))
    with atomic_path(folder / f"{stem}_boxes.ply") as tmp:
        o3d.io.write_triangle_mesh(str(tmp), boxes)


def summarise(cfg, out, done, records, skipped, truth, geometry, dev, background, ground, grown):
    """detections.csv and the summary, from the frame records in frame order."""
    rows = [CSV_HEADER] + [r for f in done for r in records[f.name]["rows"]]
    write_text_atomic(out / "detections.csv", "\n".join(rows) + "\n")
    per_frame = [records[f.name]["stats"] for f in done]

    def median(key):
        return statistics.median(p[key] for p in per_frame) if per_frame else float("nan")

    summary = {
        "config": cfg.resolved,
        "device": dev, "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "background": background, "ground_fit": ground, "frames": len(done),
        "skipped": skipped, "detections": sum(p["detections"] for p in per_frame),
        "list_capacity_growth": grown,
        "timings": {"median_read_s": median("read_s"), "median_infer_s": median("infer_s"),
                    "median_lists_s": median("engine_lists_s"),
                    "median_iterations_s": median("engine_iterations_s"),
                    "median_detect_s": median("detect_s"), "median_write_s": median("write_s"),
                    "median_iterations": median("iterations")},
        "per_frame": per_frame,
    }
    if truth is not None and done:
        dims = 3 if cfg.grid.mode == "voxel" else 2
        det_xy = {f.name: np.array(records[f.name]["xy"]).reshape(-1, dims) for f in done}
        summary["scores"] = score_frames(det_xy, {f.name: truth[f.name] for f in done},
                                         cfg.evaluation.match_distance,
                                         cfg.evaluation.hidden_visibility, geometry.centre[:2])
    return summary


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x

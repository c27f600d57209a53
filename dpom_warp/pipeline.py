"""`dpom-warp run`: a sequence of depth frames in, detections, maps, pictures and scores out."""

from __future__ import annotations

import dataclasses
import glob
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .detect import detect
from .engine import Engine, resolve_device
from .evaluate import load_ground_truth, score_frames
from .geometry import build_geometry
from .ground import GroundFitError, fit_ground_frames
from .io import InputError, read_depth, write_json_atomic, write_npy_atomic, write_text_atomic
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
    depths = [read_depth(f, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width))
              for f in files]
    try:
        fit = fit_ground_frames(depths, cfg.camera, cfg.ground)
    except GroundFitError as e:
        which = str(files[0]) if len(files) == 1 else f"{files[0]} and {len(files) - 1} more frames"
        raise InputError(f"{which}: {e}") from None
    kind = "background frame" if cfg.inputs.background else "frame"
    log(f"ground plane from {len(files)} {kind}{'s' if len(files) > 1 else ''}: camera "
        f"{fit.camera_height:.3f} m above the floor, pitch {fit.pitch_deg:.2f} deg, roll "
        f"{fit.roll_deg:.2f} deg ({fit.inlier_count} inliers, rms {1000 * fit.rms_m:.1f} mm)")
    report = {**fit.report(), "rms_m": fit.rms_m, "frames": [str(f) for f in files],
              "fit_s": time.perf_counter() - t}
    return dataclasses.replace(cfg.camera, T_world_from_camera=fit.T_world_from_camera), report


def run(cfg: RunConfig, output_dir: str | None = None, device: str | None = None,
        progress: bool = True, log=print) -> dict:
    """Run DPOM over the configured frames; returns the summary also written to summary.json."""
    t_start = time.perf_counter()
    out = Path(output_dir or cfg.output.dir)
    if cfg.synthetic is not None:
        t = time.perf_counter()
        cached = (Path(cfg.synthetic_cache) / "scene.json").exists()
        generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
        log(f"synthetic scene: {cfg.synthetic.frames} frames in {cfg.synthetic_cache} "
            f"({'checked' if cached else 'generated'} in {time.perf_counter() - t:.1f} s)")
    frames = expand(cfg.inputs.frames, "input.frames")
    bg_files = expand(cfg.inputs.background, "input.background") if cfg.inputs.background else []
    shape = (cfg.camera.height, cfg.camera.width)
    scale = cfg.inputs.depth_scale
    for f in frames + bg_files:  # check every frame before writing anything (kept out of memory)
        read_depth(f, scale, shape)
    truth = load_ground_truth(cfg.evaluation.ground_truth) if cfg.evaluation.ground_truth else None
    camera, ground = cfg.camera, None
    if cfg.pose_auto:
        camera, ground = fit_camera_pose(cfg, bg_files or frames[:cfg.ground_frames], log)

    try:
        dev = resolve_device(device or cfg.device)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    t = time.perf_counter()
    geometry = build_geometry(camera, cfg.grid, cfg.obj)
    engine = Engine(geometry, cfg.model, dev, cfg.engine.entries_per_pixel, cfg.engine.max_entries)
    if bg_files:
        engine.set_background_frames(np.stack([read_depth(f, scale, shape) for f in bg_files]))
        background = f"{len(bg_files)} background frames"
    else:
        background = "floor plane only"
    t_setup = time.perf_counter() - t
    log(f"device {dev}; {geometry.locations.shape[0]} locations {cfg.grid.shape}; "
        f"{len(frames)} frames; background: {background}")

    rows, per_frame, det_xy = [CSV_HEADER], [], {}
    iterator = frames
    if progress:
        from tqdm import tqdm
        iterator = tqdm(frames, unit="frame", desc="dpom", leave=False)
    for f in iterator:
        t_read = time.perf_counter()
        depth = read_depth(f, scale, shape)
        t0 = time.perf_counter()
        res = engine.infer(depth)
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
        t3 = time.perf_counter()
        rows += [f"{f.name},{d.x:.4f},{d.y:.4f},{d.z:.4f},{d.rho:.6f},{d.box[0]},{d.box[1]},"
                 f"{d.box[2]},{d.box[3]}" for d in dets]
        det_xy[f.name] = np.array([[d.x, d.y] for d in dets]).reshape(-1, 2)
        per_frame.append({"frame": f.name, "detections": len(dets), "iterations": res.iterations,
                          "entries": res.entries, "read_s": t0 - t_read, "infer_s": t1 - t0, "detect_s": t2 - t1,
                          "write_s": t3 - t2, **{f"engine_{k}": v for k, v in res.timings.items()}})
    write_text_atomic(out / "detections.csv", "\n".join(rows) + "\n")

    def median(key):
        return statistics.median(p[key] for p in per_frame)

    summary = {
        "config": cfg.resolved,
        "device": dev, "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "background": background, "ground_fit": ground, "frames": len(frames),
        "detections": sum(p["detections"] for p in per_frame),
        "list_capacity_growth": engine.grown,
        "timings": {"setup_s": t_setup, "total_s": time.perf_counter() - t_start,
                    "median_read_s": median("read_s"), "median_infer_s": median("infer_s"),
                    "median_lists_s": median("engine_lists_s"),
                    "median_iterations_s": median("engine_iterations_s"),
                    "median_detect_s": median("detect_s"), "median_write_s": median("write_s"),
                    "median_iterations": median("iterations")},
        "per_frame": per_frame,
    }
    if truth is not None:
        missing = [f.name for f in frames if f.name not in truth]
        if missing:
            raise InputError(f"{cfg.evaluation.ground_truth}: no ground truth for frame {missing[0]}")
        scores = score_frames(det_xy, {f.name: truth[f.name] for f in frames},
                              cfg.evaluation.match_distance, cfg.evaluation.hidden_visibility,
                              geometry.centre[:2])
        summary["scores"] = scores
    summary["timings"]["total_s"] = time.perf_counter() - t_start
    write_json_atomic(out / "summary.json", _jsonable(summary))
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

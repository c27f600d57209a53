"""`dpom-warp run`: a sequence of depth frames in, detections, maps, pictures and scores out."""

from __future__ import annotations

import dataclasses
import json
import platform
import shutil
import statistics
import time
from collections import Counter
from pathlib import Path

import numpy as np

from .background import BackgroundEstimator, sample_frames
from .config import ConfigError, RunConfig
from .engine import Engine, MemoryBudgetError, resolve_device
from .evaluate import load_ground_truth, score_frames
from .geometry import build_geometry
from .ground import fit_ground_files, frames_named
from .io import TEMP_MARK, InputError, depth_scale_hint, write_bytes_atomic, write_json_atomic, write_text_atomic
from .resolution import Resolution
from .sources.run import expand, render_synthetic, run_frames  # noqa: F401 - render_synthetic: the API's
from .worker import (FrameItem, FrameOutput, FrameWorker, WorkerSpec, make_engine,
                     pool_outcomes, read_frame, write_output)

CSV_HEADER = "frame,x,y,z,rho,u0,v0,u1,v1"



def _ambiguity(fit, log) -> dict:
    """A floor fit's ambiguity (camera.ground.up: auto), logged and for summary.json's ground."""
    if not fit.ambiguity:
        return {}
    log(f"warning: {fit.ambiguity}")
    return {"ambiguity": fit.ambiguity}


def floor_words(floor_xy) -> str:
    """'floor in view x .. to .. m, y .. to .. m' of a floor fit's floor_xy (where the grid goes)."""
    x0, x1, y0, y1 = floor_xy
    return f"floor in view x {x0:g} to {x1:g} m, y {y0:g} to {y1:g} m"


def posed(cfg: RunConfig, fit, fitted_on: str, frames, t0: float, log):
    """The camera posed by a floor fit and summary.json's ground_fit report, the fit logged
    ("ground plane from `fitted_on`: ..."); `frames`: what the report says it was fitted on."""
    floor = f"; {floor_words(fit.floor_xy)}" if fit.floor_xy is not None else ""
    log(f"ground plane from {fitted_on}: camera {fit.camera_height:.3f} m above the floor, pitch "
        f"{fit.pitch_deg:.2f} deg, roll {fit.roll_deg:.2f} deg ({fit.inlier_count} inliers, rms "
        f"{1000 * fit.rms_m:.1f} mm){floor}")
    report = {**fit.report(), "rms_m": fit.rms_m, "floor_xy": fit.floor_xy, "frames": frames,
              "fit_s": time.perf_counter() - t0, **_ambiguity(fit, log)}
    return dataclasses.replace(cfg.camera, T_world_from_camera=fit.T_world_from_camera), report


def fit_camera_pose(cfg: RunConfig, files: list[Path], log=print):
    """camera.extrinsics: auto. Fit the floor on `files` (input.background's, else
    input.frames') and return the posed camera and a report for summary.json.

    Raises:
        InputError: naming the frames (a recording's by the recording and frame), when no
            floor plane is found in them.
    """
    from .sources import is_recording

    t = time.perf_counter()
    kind = "background frame" if cfg.inputs.background else "frame"
    log(f"fitting the floor on {len(files)} {kind}{'s' if len(files) > 1 else ''} ...")
    source = cfg.inputs.background or cfg.inputs.frames
    names = [f"{source} (frame {f.name})" for f in files] if source and is_recording(source) else None
    fit = fit_ground_files(files, cfg.camera, cfg.inputs.depth_scale, cfg.ground, names)
    refuse_low_view_from_above(cfg, fit, frames_named(files, names))
    return posed(cfg, fit, f"{len(files)} {kind}{'s' if len(files) > 1 else ''}", [str(f) for f in files], t, log)


RUN_STATE = "run.json"
TRACK_FILES = ("tracks.csv", "track_table.csv")
OUTPUTS = ("maps", "images", "frames", "plots", "ply", "detections.csv", "summary.json", "eval.json",
           *TRACK_FILES, RUN_STATE)


def prepare_output(out: Path, resolved: dict, overwrite: bool, resume: bool) -> None:
    """Make `out` ready: refuse a non-empty folder unless overwriting or resuming a run of
    the same config; remove what an interrupted write left behind."""
    state = {"config": _jsonable(resolved)}
    if out.exists() and not out.is_dir():
        raise ConfigError(f"output.dir: {out} is a file; expected an empty or new folder")
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
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a file where a folder above it should be, no permission
        raise ConfigError(f"output.dir: {out}: cannot make the folder ({e.strerror or e}); expected a "
                          f"path where a new folder can be made") from None
    remove_temporaries(out)  # of a killed run
    write_json_atomic(out / RUN_STATE, state)


def remove_temporaries(out: Path) -> None:
    """The temporary files of atomic writes left in a run's folder: by a killed run, or by
    Ctrl-C landing between a temporary file's creation and the write's own cleanup."""
    for stale in list(out.glob(f".*{TEMP_MARK}*")) + list(out.glob(f"*/.*{TEMP_MARK}*")):
        stale.unlink(missing_ok=True)


def _first_difference(a, b, path=""):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
    return f"{path}: {a!r} then, {b!r} now"


@dataclasses.dataclass
class Setup:
    """What a run infers with, built from its config: the device, the posed camera, the
    full-resolution geometry (boxes, pictures, scores) and the engine with its background."""

    device: str
    spec: WorkerSpec  # how a worker builds the run's engine
    geometry: object  # full resolution: boxes, pictures, scores
    ground: dict | None
    background: str
    auto_report: dict | None
    inference: dict
    engine: Engine | None  # this process's engine (None when workers infer the frames)
    setup_s: float


@dataclasses.dataclass
class RunPlan(Setup):
    """A run checked and set up, before any output is written: what every way of inferring
    its frames (this process, --workers processes, Ray actors) starts from (its Setup, with
    the frames, the skipped ones, the ground truth and the output folder)."""

    cfg: RunConfig
    out: Path
    frames: list[Path]
    skipped: list[dict]
    truth: dict | None
    t_start: float
    records: dict = dataclasses.field(default_factory=dict)
    timestamps: dict = dataclasses.field(default_factory=dict)  # a recording's: frame -> seconds
    todo: list = dataclasses.field(default_factory=list)
    grown: list = dataclasses.field(default_factory=list)
    by_worker: Counter = dataclasses.field(default_factory=Counter)

    def chunks(self) -> list[list[FrameItem]]:
        """The frames to do in engine batches, in frame order (their files not read yet)."""
        items = [FrameItem(str(f), None, self.truth.get(f.name) if self.truth else None)
                 for f in self.todo]
        n = self.cfg.engine.batch
        return [items[i:i + n] for i in range(0, len(items), n)]


def run(cfg: RunConfig, output_dir: str | None = None, device: str | None = None,
        progress: bool = True, log=print, strict: bool = False, overwrite: bool = False,
        resume: bool = False, workers: int | None = None, max_frames: int | None = None) -> dict:
    """Run DPOM over the configured frames; returns the summary also written to summary.json.
    A live camera (`input.frames: realsense[:SERIAL]`) runs until Ctrl-C or `max_frames`
    (live.run_live; `workers` None: live.default_workers); other frames are the first
    `max_frames` of input.frames (all by default).

    A frame whose file is bad, or whose lists would exceed the memory budget, is reported
    and skipped (listed in summary.json), unless `strict`. Each frame's outputs (map,
    picture, then its record in frames/) are written atomically, so an interrupted run
    leaves whole files and `resume` continues it to the same final files. With `workers` > 1
    frames are inferred by that many processes, this one and workers - 1 helpers, each with
    its own engine (Warp runs CPU kernels on one thread), and written here: the same files.
    """
    from .sources.realsense import is_live

    if cfg.inputs.frames is not None and is_live(cfg.inputs.frames):
        from .live import run_live

        return run_live(cfg, output_dir, device, log, max_frames, overwrite, workers=workers)
    workers = workers or 1
    plan = plan_run(cfg, output_dir, device, log, strict, parallel=workers > 1, keep_engine=workers > 1,
                    max_frames=max_frames)
    open_output(plan, overwrite, resume, log)
    if workers > 1 and len(plan.todo) > 1:
        outcomes = pool_outcomes(plan.spec, plan.chunks(), workers, plan.engine)
        runner, desc = {"kind": "processes", "workers": workers}, f"dpom x{workers}"
    else:
        outcomes = _outcomes_here(plan)
        runner, desc = {"kind": "one process"}, "dpom"
    t = time.perf_counter()
    try:
        collect(plan, progress_bar(outcomes, len(plan.todo), desc, progress), strict, log)
    except (InputError, ConfigError):
        abandon_if_empty(plan)  # --strict: a bad frame before any good one leaves nothing
        raise
    except KeyboardInterrupt:  # every write started has ended (collect): none is in flight
        remove_temporaries(plan.out)
        raise
    finally:
        outcomes.close()  # stops the worker pool at once on an error or Ctrl-C
    wall = time.perf_counter() - t
    runner["frames_wall_s"] = wall  # from the first frame sent to the last written
    runner["frames_per_s"] = len(plan.todo) / wall if plan.todo and wall > 0 else None
    return finish_run(plan, runner)


def plan_run(cfg: RunConfig, output_dir: str | None = None, device: str | None = None,
             log=print, strict: bool = False, parallel: bool = False, keep_engine: bool = False,
             max_frames: int | None = None) -> RunPlan:
    """Check the frames, fit the pose, set up the background and the engine; nothing is
    written to the output yet. `parallel`: other processes will infer the frames, so the
    engine here compiles the kernels (into the cache they are given) and is dropped unless
    `keep_engine` (this process infers frames beside them); `max_frames`: the first that many
    frames of input.frames."""
    t_start = time.perf_counter()
    out = Path(output_dir or cfg.output.dir)
    source = run_frames(cfg, strict, log, max_frames)  # every frame read and checked once
    frames, skipped, timestamps = source.frames, source.skipped, source.timestamps
    truth = load_ground_truth(cfg.evaluation.ground_truth) if cfg.evaluation.ground_truth else None
    if truth is not None:
        missing = [f.name for f in frames if f.name not in truth]
        if missing:
            raise InputError(f"{cfg.evaluation.ground_truth}: no ground truth for frame {missing[0]}")
    s = set_up(cfg, frames, device, log, parallel, keep_engine, recorded=True)
    s.spec.pictures = cfg.output.images and not pictures_deferred(cfg, len(frames))
    return RunPlan(**{f.name: getattr(s, f.name) for f in dataclasses.fields(Setup)}, cfg=s.spec.cfg,
                   out=out, frames=frames, skipped=skipped, truth=truth, t_start=t_start,
                   timestamps=timestamps)


def warn_depth_scale(cfg: RunConfig, path, depth: np.ndarray | None, log=print) -> None:
    """A warning (`log`) when the first frame's readings are no depth camera's at the config's
    input.depth_scale (io.depth_scale_hint); `depth`: the frame at `path`, read if None."""
    if path is None:
        return
    try:
        depth = read_frame(cfg, path) if depth is None else depth
    except InputError:  # a bad frame is reported where frames are read
        return
    hint = depth_scale_hint(depth, cfg.inputs.depth_scale)
    if hint:
        log(f"warning: {path}: {hint}")


# engine.batch: auto on a GPU for a recorded run: on an H200 (docs/bench_cuda_h200.md, third
# lease) a kinect_v2 frame took 4.9 ms alone and 1.1 ms in a call of 16 (0.83 ms at 32, 0.54 at
# 128, for a latency and memory 2 to 8 times larger: a run's reading, detection and writing on
# the host take longer than that a frame)
GPU_BATCH = 16


def auto_batch(device: str, recorded: bool) -> int:
    """engine.batch auto's frames a call (before the memory budget): GPU_BATCH for a recorded
    run on a GPU; 1 on the CPU (one thread: a batch takes as long as its frames one by one),
    for a live camera (a frame waits for no other) and the Python API (`detect` takes one)."""
    return GPU_BATCH if recorded and device.startswith("cuda") else 1


def with_batch(cfg: RunConfig, batch: int) -> RunConfig:
    """cfg with engine.batch = batch."""
    return dataclasses.replace(cfg, engine=dataclasses.replace(cfg.engine, batch=batch))


def set_up(cfg: RunConfig, frames: list[Path], device: str | None = None, log=print,
           parallel: bool = False, keep_engine: bool = False, recorded: bool = False) -> Setup:
    """The pose (fitted with extrinsics: auto), the background (frames, auto from `frames`,
    or the floor) and the engine of a run: what `dpom-warp run` and the Python API's
    Detector both infer with. `frames`: the run's frames (read only for `auto` background
    and for a floor fit without background frames). engine.batch auto is GPU_BATCH for a
    `recorded` run on a GPU (halved until engine.memory_gb holds it), else 1; the Setup's
    spec.cfg has the batch chosen."""
    auto_bg = cfg.inputs.auto_background
    bg_files = (expand(cfg.inputs.background, "input.background", cfg.inputs.topic, log)
                if cfg.inputs.background and not auto_bg else [])
    bg_frames = [read_frame(cfg, f) for f in bg_files]  # a bad one is fatal
    warn_depth_scale(cfg, bg_files[0] if bg_files else frames[0] if frames else None,
                     bg_frames[0] if bg_frames else None, log)
    try:
        dev = resolve_device(device or cfg.device)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    batch_auto = cfg.engine.batch == "auto"
    if batch_auto:
        cfg = with_batch(cfg, auto_batch(dev, recorded))
    sample = ([frames[i] for i in sample_frames(len(frames), cfg.inputs.background_auto.max_frames)]
              if auto_bg else [])
    camera, ground = cfg.camera, None
    if cfg.pose_auto:
        if auto_bg and len(sample) >= cfg.inputs.background_auto.min_frames:
            camera, ground = fit_pose_on_estimate(cfg, sample, dev, log)
        else:
            fit_on = bg_files or frames[:cfg.ground_frames]
            if not fit_on:
                raise ConfigError("camera.extrinsics: auto needs frames to fit the floor on; expected "
                                  "input.frames or input.background, found neither")
            camera, ground = fit_camera_pose(cfg, fit_on, log)

    t = time.perf_counter()
    geometry = build_geometry(camera, cfg.grid, cfg.obj)  # full resolution: boxes, pictures
    if not np.any(geometry.rect_area > 0):  # a grid beside the view: every map would be empty
        c = camera.centre
        floor = (ground or {}).get("floor_xy")
        seen = f" ({floor_words(floor)})" if floor else ""
        raise ConfigError(
            f"grid: none of its {len(geometry.rect)} locations is in the camera's view (the camera "
            f"{'fitted ' if ground else ''}at x {c[0]:.2f} m, y {c[1]:.2f} m, {c[2]:.2f} m up); expected "
            f"grid.x and grid.y{' and grid.z' if cfg.grid.mode == 'voxel' else ''} over what the camera sees{seen}")
    if parallel and cfg.model.warm_start:
        raise ConfigError("model.warm_start: each frame starts from the previous one, so frames "
                          "must run in order in one process; expected no --workers or --ray with it")
    log("setting up the engine (mask index; Warp kernels compiled on first use, then cached) ...")
    while True:
        try:
            engine = make_engine(cfg, camera, dev, cfg.engine.batch)
            break
        except MemoryBudgetError as e:
            if batch_auto and cfg.engine.batch > 1:  # fewer frames a call where the budget holds fewer
                cfg = with_batch(cfg, cfg.engine.batch // 2)
                continue
            raise ConfigError(f"engine.memory_gb: {e}; coarsen grid.x/grid.y or raise the budget") from None
    auto_report, given = None, None
    if bg_frames:
        engine.set_background_frames(engine.resolution.frames(np.stack(bg_frames)))
        given = (engine.background(0), None) if parallel else None
        background = f"{len(bg_files)} background frames"
    elif auto_bg:
        if len(sample) >= cfg.inputs.background_auto.min_frames:
            log(f"estimating the background from {len(sample)} frames ...")
        estimator, auto_report = estimate_background(cfg, sample, engine.height, engine.width, dev,
                                                     engine.resolution)
        given = estimator.result()  # (Background, fallback): also what other workers take
        engine.set_background(*given)
        auto_report["fallback_pixels"] = engine.fallback_pixels
        auto_report["fallback_share"] = engine.fallback_pixels / engine.n_pixels
        background = (f"auto from {len(sample)} of the frames ({engine.fallback_pixels} of "
                      f"{engine.n_pixels} pixels left to the floor-only model)")
    else:
        background = "floor plane only"
    del bg_frames
    r = engine.resolution
    inference = {"stride": r.stride, "reduce": r.reduce, "image": [engine.width, engine.height],
                 "sparse_epsilon": cfg.model.sparse_epsilon, "bound_rounds": cfg.model.bound_rounds,
                 "warm_start": cfg.model.warm_start, "exact": cfg.engine.exact, "batch": cfg.engine.batch}
    if parallel:  # an empty frame compiles every kernel into the cache the workers are given
        engine.infer_batch(np.zeros((1, engine.height, engine.width), np.float32))
        engine = engine if keep_engine else None
    return Setup(dev, WorkerSpec(cfg, camera, dev, given), geometry, ground, background, auto_report,
                 inference, engine, time.perf_counter() - t)


def open_output(plan: RunPlan, overwrite: bool, resume: bool, log=print) -> None:
    """Make the output folder ready (prepare_output) and find the frames left to do: with
    `resume`, the frames whose record exists are done."""
    cfg, out, i = plan.cfg, plan.out, plan.inference
    prepare_output(out, cfg.resolved, overwrite, resume)
    log(f"device {plan.device}; {plan.geometry.locations.shape[0]} locations {cfg.grid.shape}; "
        f"{len(plan.frames)} frame{'' if len(plan.frames) == 1 else 's'}; background: {plan.background}; "
        f"inference at {i['image'][0]}x"
        f"{i['image'][1]} pixels (stride {i['stride']}{', ' + i['reduce'] if i['stride'] > 1 else ''}"
        f"{', exact path' if cfg.engine.exact else ''}"
        f"{f', {cfg.engine.batch} frames an engine call' if cfg.engine.batch > 1 else ''})")
    for f in plan.frames:
        record = out / "frames" / f"{f.stem}.json"
        if resume and record.exists():
            plan.records[f.name] = json.loads(record.read_text())
        else:
            plan.todo.append(f)
    if resume:
        log(f"resuming: {len(plan.records)} frames already done, {len(plan.todo)} to go")


def _outcomes_here(plan: RunPlan):
    """The frames' outcomes in this process; the next chunk's frames are read on a thread
    while this chunk infers (Warp's CPU kernels release the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    worker = FrameWorker(plan.spec, engine=plan.engine)
    chunks = plan.chunks()
    with ThreadPoolExecutor(1) as pool:
        ahead = pool.submit(worker.read, chunks[0]) if chunks else None
        for i, chunk in enumerate(chunks):
            got = ahead.result()
            ahead = pool.submit(worker.read, chunks[i + 1]) if i + 1 < len(chunks) else None
            yield from worker.process(chunk, got)


def progress_bar(outcomes, frames: int, desc: str, progress: bool):
    """`outcomes` (one per frame) through a progress bar over `frames` frames (none without
    `progress`); the bar closes when the iteration ends, whichever way."""
    from tqdm import tqdm

    return tqdm(outcomes, total=frames, unit="frame", desc=desc, leave=False, disable=not progress)


def collect(plan: RunPlan, outcomes, strict: bool, log=print) -> None:
    """Write each frame's outputs as its outcome arrives, on a thread (while the next frame
    infers), in order; a frame that could not be processed is skipped with its reason (fatal
    with `strict`). Every write started is finished before this returns or raises."""
    from concurrent.futures import ThreadPoolExecutor

    failed = []

    def write(output):  # after a failed write no later frame is written: frames stay in order
        if failed:
            raise RuntimeError("not written: an earlier frame's write failed")
        try:
            return write_output(plan.out, output)
        except BaseException as e:
            failed.append(e)
            raise

    with ThreadPoolExecutor(1) as writer:
        pending = []
        try:
            for name, output, error in outcomes:
                if error is None:
                    stamp(plan, name, output)
                    pending.append((name, output, writer.submit(write, output)))
                else:
                    accept(plan, name, output, error, strict, log)
                while pending and pending[0][2].done():
                    _written(plan, *pending.pop(0))
        finally:
            for item in pending:
                item[2].exception()  # wait for it; an error is raised below, in order
        for item in pending:
            _written(plan, *item)


def stamp(plan: RunPlan, name: str, output: FrameOutput) -> None:
    """A recording's frame record carries its timestamp."""
    if name in plan.timestamps:
        output.record["timestamp"] = output.record["stats"]["timestamp"] = plan.timestamps[name]


def _written(plan: RunPlan, name: str, output: FrameOutput, future) -> None:
    plan.records[name] = future.result()
    plan.grown += output.grown
    plan.by_worker[output.record["stats"]["worker"]] += 1


def accept(plan: RunPlan, name: str, output: FrameOutput | None, error: str | None, strict: bool,
           log=print) -> None:
    if error is None:
        stamp(plan, name, output)
        plan.records[name] = write_output(plan.out, output)
        plan.grown += output.grown
        plan.by_worker[output.record["stats"]["worker"]] += 1
        return
    if strict:
        raise InputError(error)
    plan.skipped.append({"frame": name, "reason": error})
    log(f"skipping {error}")


def abandon_if_empty(plan: RunPlan) -> None:
    """A run that wrote no frame leaves nothing behind: its run.json and the folders it made
    go (a resumed run's earlier frames, and anything else in the folder, stay)."""
    out = plan.out
    if any((out / "frames").glob("*.json")):
        return
    (out / RUN_STATE).unlink(missing_ok=True)
    for name in ("frames", "maps", "images", "ply", ""):
        try:
            (out / name).rmdir()  # only when empty
        except OSError:
            pass


def finish_run(plan: RunPlan, runner: dict) -> dict:
    """detections.csv, summary.json and (with ground truth) eval.json of a run whose frames
    are all done or skipped; `runner` says what inferred them (written in the summary with
    the frames each worker did)."""
    cfg, out, truth = plan.cfg, plan.out, plan.truth
    done = [f for f in plan.frames if f.name in plan.records]
    if not done:  # every frame skipped while inferring (lists over engine.max_entries, ...)
        abandon_if_empty(plan)
        first = plan.skipped[0]["reason"] if plan.skipped else "no frame"
        raise InputError(f"{first} (none of the {len(plan.frames)} readable frames could be inferred; "
                         f"nothing written)")
    summary = summarise(cfg, out, done, plan.records, plan.skipped, truth, plan.geometry,
                        plan.device, plan.background, plan.ground, plan.grown)
    if plan.auto_report is not None:
        summary["background_auto"] = plan.auto_report
    summary["inference"] = plan.inference
    summary["runner"] = {**runner, "frames_resumed": len(done) - sum(plan.by_worker.values()),
                         "frames_per_worker": dict(sorted(plan.by_worker.items()))}
    stamps = {f.name: plan.records[f.name].get("timestamp") for f in done}
    summary["tracking"] = track_run(cfg, out, done, plan.geometry, truth, log=lambda *_: None,
                                    fps=fps_of(list(stamps.values())), camera=plan.spec.camera,
                                    timestamps=stamps, redraw=not plan.spec.pictures)
    summary["timings"]["setup_s"] = plan.setup_s
    summary["timings"]["total_s"] = time.perf_counter() - plan.t_start
    write_json_atomic(out / "summary.json", _jsonable(summary))
    if truth is not None and done:  # the curves of `dpom-warp eval`, from the maps just written
        from .evaluate import evaluate_runs

        results = evaluate_runs([out], cfg.evaluation.ground_truth, cfg.evaluation.hidden_visibility)
        write_json_atomic(out / "eval.json", _jsonable(results))
        if cfg.evaluation.plots:
            from .plots import write_figures

            write_figures(results, out / "plots")
    return summary


def fps_of(timestamps: list) -> float | None:
    """The frame rate of frames with timestamps, None without: one over the median interval
    between consecutive frames, the intervals over frames dropped or skipped between left
    out (those over 1.5 times the intervals' 10th percentile: a short recording with a frame
    skipped has as many of those as of the others)."""
    ts = [t for t in timestamps if t is not None]
    if len(ts) < 2 or len(ts) < len(timestamps):
        return None
    gaps = np.array([b - a for a, b in zip(ts, ts[1:]) if b > a])
    if not len(gaps):
        return None
    return 1.0 / float(np.median(gaps[gaps <= 1.5 * np.percentile(gaps, 10)]))


def pictures_deferred(cfg: RunConfig, frames: int) -> bool:
    """Whether a run's pictures are drawn after tracking (they show the tracks), or after the
    frames (a picture of every output.images_every-th frame done, counted in order), rather
    than by whoever infers each frame."""
    return cfg.output.images and (cfg.output.images_every > 1 or cfg.tracking.resolved_method(frames) != "off")


VIEW: list = []  # --view: a Rerun viewer is spawned for the runs of this process


class ShownTracks:
    """What a frame's picture and Rerun log show of the tracks, frame after frame (`at`, in
    order): each track's id, box (the silhouette of the cell nearest to it), bridged flag and
    trail (its positions over the last tracking.trail frames, this one's included). Holds
    only the trails' frames."""

    def __init__(self, geometry, trail: int):
        self.geometry, self.trail = geometry, max(1, trail)
        self.history: dict[int, list] = {}

    def at(self, i: int, rows: list) -> list[dict]:
        """Frame i's tracks from rows [(id, xyz, bridged)]."""
        shown = []
        for tid, xyz, bridged in rows:
            self.history.setdefault(tid, []).append((i, xyz))
            past = [p for j, p in self.history[tid] if j > i - self.trail]
            k = int(np.argmin(np.linalg.norm(self.geometry.locations - xyz, axis=1)))
            shown.append({"id": tid, "box": self.geometry.rect[k], "bridged": bridged, "trail": past, "xyz": xyz})
        self.history = {tid: [(j, p) for j, p in h if j > i - self.trail] for tid, h in self.history.items()
                        if h[-1][0] > i - self.trail}
        return shown


def tracked_picture(cfg: RunConfig, geometry, depth, rho_map, dets, name: str, truth, shown) -> bytes:
    """A frame's picture with the tracks `shown` on it (ShownTracks; None: no tracks), as a
    finished run and a live run draw it."""
    from .render import frame_picture

    return frame_picture(depth, rho_map, cfg.grid, dets, geometry.centre[:2], truth, name,
                         in_view=geometry.rect_area > 0, tracks=shown, trail=cfg.tracking.trail)


def frames_out(cfg: RunConfig, out: Path, done: list[Path], geometry, maps, truth, tracks,
               pictures: bool, timestamps: dict | None = None, camera=None) -> None:
    """After the frames: each frame's picture (with `tracks`, their identities and trails)
    when `pictures` (of every output.images_every-th frame of `done`: the others' pictures,
    left by an earlier drawing, are removed), and its Rerun log with output.rerun or --view
    (depth, boxes, map, tracks)."""
    from .detect import detect_map
    from .tracking import per_frame

    log = None
    if cfg.output.rerun or VIEW:
        from .view import RerunLog

        log = RerunLog(cfg.output.rerun, spawn=bool(VIEW))
        log.camera(camera or cfg.camera)
    now = per_frame(tracks, len(done)) if tracks is not None else [[] for _ in done]
    trails = ShownTracks(geometry, cfg.tracking.trail)
    shown_all = [trails.at(i, now[i]) for i in range(len(done))]

    def one(i):
        """Frame i's detections, depth and (with `pictures`) picture file."""
        f = done[i]
        due = pictures and i % cfg.output.images_every == 0
        if pictures and not due:
            (out / "images" / f"{f.stem}.png").unlink(missing_ok=True)
        if not due and log is None:
            return None
        rho_map = maps[i].reshape(cfg.grid.shape)
        dets = detect_map(rho_map, geometry, cfg.detection)
        depth = read_frame(cfg, f)
        if due:
            png = tracked_picture(cfg, geometry, depth, rho_map, dets, f.name, truth.get(f.name) if truth else None,
                                  shown_all[i] if tracks is not None else None)
            write_bytes_atomic(out / "images" / f"{f.stem}.png", png)
        return (rho_map, dets, depth) if log is not None else None

    # two threads: PNG encoding and Pillow's drawing release the GIL, so on two cores one
    # picture is drawn while the other is encoded; 64 frames in flight at most
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        for start in range(0, len(done), 64):
            span = range(start, min(len(done), start + 64))
            for i, got in zip(span, pool.map(one, span)):
                if log is not None:
                    rho_map, dets, depth = got
                    log.frame(i, (timestamps or {}).get(done[i].name), depth, dets, rho_map,
                              shown_all[i] if tracks is not None else None)
    if log is not None:
        log.close()


def track_table_files(out: Path, tracks, names: list[str], fps: float, times: list | None = None) -> None:
    """tracks.csv and track_table.csv of `tracks` over the frames `names` (`times`: their
    timestamps, None where unknown)."""
    from .tracking import track_table, tracks_csv

    write_text_atomic(out / "tracks.csv", tracks_csv(tracks, names))
    write_text_atomic(out / "track_table.csv", track_table(tracks, names, fps, times))


def track_run(cfg: RunConfig, out: Path, done: list[Path], geometry, truth=None, log=print,
              fps: float | None = None, camera=None, timestamps: dict | None = None,
              redraw: bool = True) -> dict:
    """Tracks of a run whose maps are written (maps/<stem>.npy of the `done` frames, in
    order): tracks.csv and track_table.csv, then, when the run has pictures, every frame's
    picture with the tracks (deferred until now: pictures_deferred). `fps`: the frames' rate
    from their timestamps (default input.fps). Returns the `tracking` block of summary.json.
    tracking.method off (or a single frame): no track files, and the pictures are drawn here
    only when `redraw` (False: whoever inferred the frames drew them)."""
    from .tracking import Cells, FrameMaps, run_tracker

    method = cfg.tracking.resolved_method(len(done))
    maps = FrameMaps([out / "maps" / f"{f.stem}.npy" for f in done], keep=2 * cfg.tracking.window)
    if method == "off":
        for name in TRACK_FILES:
            (out / name).unlink(missing_ok=True)
        pictures = cfg.output.images and redraw  # the Rerun log is always drawn here
        if cfg.output.rerun or VIEW or pictures:
            frames_out(cfg, out, done, geometry, maps, truth, None, pictures, timestamps, camera)
        why = ("tracking.method: off" if cfg.tracking.method == "off" else
               f"tracking.method {cfg.tracking.method} tracks 2 frames or more, found {len(done)}")
        return {"method": "off", "why": why}
    cells = Cells.for_run(geometry, cfg)
    rate = fps or cfg.inputs.fps
    names = [f.name for f in done]
    times = [(timestamps or {}).get(n) for n in names]  # frames dropped or skipped between: by the clock
    tracks, report = run_tracker(maps, cells, cfg.grid.shape, cfg.tracking, rate, cfg.detection.threshold,
                                 method, times)
    report["fps_from"] = "timestamps" if fps else "input.fps"
    track_table_files(out, tracks, names, rate, times)
    log(f"{len(tracks)} tracks ({method}) in {report['time_s']:.2f} s "
        f"({report['ms_per_frame']:.1f} ms per frame)")
    if cfg.output.images or cfg.output.rerun or VIEW:
        t = time.perf_counter()
        frames_out(cfg, out, done, geometry, maps, truth, tracks, cfg.output.images, timestamps, camera)
        report["pictures_s"] = time.perf_counter() - t
    return report


RETRACK_KEYS = ("tracking.", "input.fps", "output.images", "output.rerun")


def retrack(run_dir: str | Path, overrides: list[str], log=print) -> dict:
    """`dpom-warp track RUN_DIR`: the tracks of a finished run again from its maps, with
    `overrides` (tracking.*, input.fps, output.images) applied to its config; tracks.csv,
    track_table.csv, the pictures, summary.json's `tracking` and eval.json are rewritten.
    Returns the new tracking block."""
    from .config import apply_overrides, parse_config

    run_dir = Path(run_dir)
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        raw = summary["config"]
    except (OSError, json.JSONDecodeError, KeyError):
        raise InputError(f"{run_dir}: not a finished dpom-warp run (no readable summary.json)") from None
    for o in overrides:
        key = o.split("=", 1)[0].strip()
        if not any(key.startswith(k) for k in RETRACK_KEYS):
            raise ConfigError(f"--set {key}: expected a tracking.* key, input.fps, output.images or output.rerun "
                              f"(the rest of a run changes only by inferring again)")
    cfg = parse_config(apply_overrides(raw, overrides))
    camera = cfg.camera
    if cfg.pose_auto:
        camera = dataclasses.replace(camera, T_world_from_camera=np.array(
            summary["ground_fit"]["T_world_from_camera"], float))
    names = [p["frame"] for p in summary["per_frame"]]
    from .sources.realsense import is_live

    if is_live(cfg.inputs.frames) and (cfg.output.images or cfg.output.rerun):
        raise InputError(f"{run_dir}: a live run keeps no frames (input.frames: {cfg.inputs.frames}), so its "
                         f"pictures and Rerun log cannot be drawn again; expected --set output.images=false "
                         f"--set output.rerun=null (tracks.csv, track_table.csv and the summary only)")
    if cfg.output.images:
        by_name = {f.name: f for f in expand(cfg.inputs.frames, "input.frames", cfg.inputs.topic, log)}
        missing = [n for n in names if n not in by_name]
        if missing:
            raise InputError(f"input.frames: {cfg.inputs.frames} has no frame {missing[0]} of the run "
                             f"(its frames redraw the pictures; run from the folder the run started "
                             f"in, or --set output.images=false)")
        done = [by_name[n] for n in names]
    else:
        done = [Path(n) for n in names]
    for n in names:
        if not (run_dir / "maps" / f"{Path(n).stem}.npy").is_file():
            raise InputError(f"{run_dir / 'maps' / (Path(n).stem + '.npy')}: missing occupancy map")
    truth = load_ground_truth(cfg.evaluation.ground_truth) if cfg.evaluation.ground_truth else None
    geometry = build_geometry(camera, cfg.grid, cfg.obj)
    report = track_run(cfg, run_dir, done, geometry, truth, log,
                       fps=fps_of([p.get("timestamp") for p in summary["per_frame"]]), camera=camera,
                       timestamps={p["frame"]: p.get("timestamp") for p in summary["per_frame"]})
    summary["config"], summary["tracking"] = cfg.resolved, report
    write_json_atomic(run_dir / "summary.json", _jsonable(summary))
    write_json_atomic(run_dir / RUN_STATE, {"config": _jsonable(cfg.resolved)})
    if truth is not None:
        from .evaluate import evaluate_runs

        results = evaluate_runs([run_dir], cfg.evaluation.ground_truth, cfg.evaluation.hidden_visibility)
        write_json_atomic(run_dir / "eval.json", _jsonable(results))
    return report


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


def refuse_low_view_from_above(cfg: RunConfig, fit, where: str) -> None:
    """camera.ground.up: auto (no IMU in the recording, none in the config): a plane facing the
    camera reads the same as a floor seen from straight down and as a wall faced level, and
    auto takes the floor. On a ground grid, a camera looking down (within 10 degrees of
    straight down) from lower than its objects' height sees none of them whole: the plane is
    taken for a wall, and the run stops with an InputError saying how to give the pose."""
    from .ground import AUTO_MARGIN_DEG, HINT

    if not isinstance(cfg.ground.up, str) or cfg.grid.mode != "ground":
        return
    if abs(fit.pitch_deg - 90.0) <= AUTO_MARGIN_DEG and fit.camera_height < cfg.obj.height:
        raise InputError(
            f"{where}: camera.extrinsics: auto: the floor found is a plane {fit.camera_height:.2f} m away facing "
            f"the camera; as a floor the camera would look down on it (pitch {fit.pitch_deg:.1f} deg) from lower "
            f"than the {cfg.obj.height:g} m objects it is to find, so it is more likely a wall the camera faces; "
            f"{HINT}, or give camera.extrinsics")


def fit_pose_on_estimate(cfg: RunConfig, files: list[Path], device: str, log=print):
    """camera.extrinsics: auto with background: auto: the floor is fitted on the estimated
    background at full resolution (the floor people hide in a frame shows in the estimate)."""
    from .ground import GroundFitError, fit_ground_frames

    t = time.perf_counter()
    log(f"fitting the floor on the background estimated from {len(files)} frames ...")
    estimator, _ = estimate_background(cfg, files, cfg.camera.height, cfg.camera.width, device)
    bg, fallback = estimator.result()
    depth = np.where(fallback | (bg.outlier >= 1), 0.0, bg.mu)
    try:
        fit = fit_ground_frames([depth], cfg.camera, cfg.ground)
    except GroundFitError as e:
        raise InputError(f"{files[0]} and {len(files) - 1} more frames: in their estimated "
                         f"background: {e}") from None
    refuse_low_view_from_above(cfg, fit, f"{files[0]} and {len(files) - 1} more frames (their estimated background)")
    return posed(cfg, fit, f"the background estimated on {len(files)} frames",
                 f"estimated background of {len(files)} frames", t, log)


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
        "unconverged": [p["frame"] for p in per_frame if not p.get("converged", True)],
        "list_capacity_growth": grown,
        "timings": {"median_read_s": median("read_s"), "median_infer_s": median("infer_s"),
                    "median_lists_s": median("engine_lists_s"),
                    "median_iterations_s": median("engine_iterations_s"),
                    "median_detect_s": median("detect_s"), "median_write_s": median("write_s"),
                    "median_iterations": median("iterations"),
                    "median_entries": median("entries"),
                    "median_kept_entries": median("kept_entries") if per_frame and all(
                        p.get("kept_entries") is not None for p in per_frame) else None},
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

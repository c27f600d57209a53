"""`dpom-warp run`: a sequence of depth frames in, detections, maps, pictures and scores out."""

from __future__ import annotations

import dataclasses
import json
import time
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .evaluate import load_ground_truth
from .frames import render_synthetic, run_frames  # noqa: F401 - render_synthetic: the API's
from .geometry import RigGeometry, build_geometry
from .io import InputError, write_json_atomic
from .outputs import (RUN_STATE, ShownTracks, check_output, fps_of, pictures_deferred, remove_temporaries, summarise)
from .session import Setup, set_up
from .sources import expand
from .worker import FrameItem, FrameWorker, pool_outcomes
from .loop import FrameLoop, open_loop
from .writers import FrameDone, Pictures, Rerun, RunEnd, RunView, Summary, TrackTables, Writers, ZoneTables, jsonable


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
    writers: Writers | None = None  # once the output folder is ready (open_output)
    view: RunView | None = None
    loop: FrameLoop | None = None  # what happens to each frame inferred, whoever inferred it
    strict: bool = False  # a frame that cannot be inferred is fatal

    def chunks(self) -> list[list[FrameItem]]:
        """The frames to do in engine batches, in frame order (their files not read yet)."""
        items = [FrameItem(str(f), None, self.truth.get(f.name) if self.truth else None, getattr(f, "paths", None))
                 for f in self.todo]
        n = self.cfg.engine.batch
        return [items[i:i + n] for i in range(0, len(items), n)]


def run(cfg: RunConfig, output_dir: str | None = None, device: str | None = None,
        progress: bool = True, log=print, strict: bool = False, overwrite: bool = False,
        resume: bool = False, workers: int | None = None, max_frames: int | None = None) -> dict:
    """Run DPOM over the configured frames; returns the summary also written to summary.json.
    A live camera (`input.frames: realsense[:SERIAL]`, or frames played as one: input.play)
    runs until Ctrl-C or `max_frames`
    (live.run_live; `workers` None: live.default_workers); other frames are the first
    `max_frames` of input.frames (all by default).

    A frame whose file is bad, or whose lists would exceed the memory budget, is reported
    and skipped (listed in summary.json), unless `strict`. Each frame's outputs (map,
    picture, then its record in frames/) are written atomically, so an interrupted run
    leaves whole files and `resume` continues it to the same final files. With `workers` > 1
    frames are inferred by that many processes, this one and workers - 1 helpers, each with
    its own engine (Warp runs CPU kernels on one thread), and written here: the same files.
    """
    if cfg.live:
        from .live import run_live

        check_output(Path(output_dir or cfg.output.dir), cfg.resolved, overwrite, False)
        return run_live(cfg, output_dir, device, log, max_frames, overwrite, workers=workers)
    check_output(Path(output_dir or cfg.output.dir), cfg.resolved, overwrite, resume)  # before any setup
    workers = workers or 1
    plan = plan_run(cfg, output_dir, device, log, strict, parallel=workers > 1, keep_engine=workers > 1,
                    max_frames=max_frames)
    open_output(plan, overwrite, resume, log)
    try:
        return infer_and_finish(plan, workers, progress)
    except BaseException:
        plan.writers.close()
        raise


def infer_and_finish(plan: RunPlan, workers: int, progress: bool) -> dict:
    """The frames inferred (in this process, or `workers` processes) and written as they come,
    then the run's own outputs; returns the summary."""
    if workers > 1 and len(plan.todo) > 1:
        outcomes = pool_outcomes(plan.spec, plan.chunks(), workers, plan.engine)
        runner, desc = {"kind": "processes", "workers": workers}, f"dpom x{workers}"
    else:
        outcomes = _outcomes_here(plan)
        runner, desc = {"kind": "one process"}, "dpom"
    t = time.perf_counter()
    try:
        collect(plan, progress_bar(outcomes, len(plan.todo), desc, progress))
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
    try:
        source = run_frames(cfg, strict, log, max_frames)  # every frame read and checked once
    except (InputError, ConfigError) as e:  # a frames path that matches nothing: from the file, or --set
        raise type(e)(cfg.blame(str(e))) from None
    frames, skipped, timestamps = source.frames, source.skipped, source.timestamps
    truth = load_ground_truth(cfg.evaluation.ground_truth) if cfg.evaluation.ground_truth else None
    if truth is not None:
        missing = [f.name for f in frames if f.name not in truth]
        if missing:
            raise InputError(f"{cfg.evaluation.ground_truth}: no ground truth for frame {missing[0]}")
    try:
        s = set_up(cfg, frames, device, log, parallel, keep_engine, recorded=True)
    except (InputError, ConfigError) as e:  # background frames that match nothing, ...
        raise type(e)(cfg.blame(str(e))) from None
    s.spec.pictures = cfg.output.images and not pictures_deferred(cfg, len(frames))
    return RunPlan(**{f.name: getattr(s, f.name) for f in dataclasses.fields(Setup)}, cfg=s.spec.cfg,
                   out=out, frames=frames, skipped=skipped, truth=truth, t_start=t_start,
                   timestamps=timestamps, strict=strict)


def open_output(plan: RunPlan, overwrite: bool, resume: bool, log=print) -> None:
    """Make the output folder ready (prepare_output) and find the frames left to do: with
    `resume`, the frames whose record and map exist are done."""
    cfg, out, i = plan.cfg, plan.out, plan.inference
    plan.loop = open_loop(cfg, out, plan.geometry, plan.spec.camera, overwrite=overwrite, resume=resume,
                          worker_pictures=plan.spec.pictures, log=log, records=plan.records,
                          skipped=plan.skipped, grown=plan.grown, by_worker=plan.by_worker,
                          timestamps=plan.timestamps, strict=plan.strict)
    plan.view, plan.writers = plan.loop.view, plan.loop.writers
    images = i["image"] if cfg.is_rig else [i["image"]]
    log(f"device {plan.device}; {int(np.prod(cfg.grid.shape))} locations {cfg.grid.shape}; "
        f"{len(plan.frames)} frame{'' if len(plan.frames) == 1 else 's'}; background: {plan.background}; "
        f"inference at {' and '.join(f'{w}x{h}' for w, h in images)} pixels (stride {i['stride']}{', ' + i['reduce'] if i['stride'] > 1 else ''}"
        f"{', exact path' if cfg.engine.exact else ''}"
        f"{f', {cfg.engine.batch} frames an engine call' if cfg.engine.batch > 1 else ''})")
    again = []
    for f in plan.frames:
        record = _finished_record(out, f) if resume else None
        if record is not None:
            plan.records[f.name] = record
        else:
            plan.todo.append(f)
            if resume and record_path(out, f).exists():
                again.append(f.name)
    if resume:
        log(f"resuming: {len(plan.records)} frames already done, {len(plan.todo)} to go"
            + (f" ({len(again)} of them again, their map or record missing or unreadable: "
               f"{', '.join(again[:5])}{', ...' if len(again) > 5 else ''})" if again else ""))


def record_path(out: Path, frame: Path) -> Path:
    """Where a run in `out` keeps a frame's record: frames/<stem>.json."""
    return out / "frames" / f"{frame.stem}.json"


def _finished_record(out: Path, frame: Path) -> dict | None:
    """A frame's record where the frame is finished: the record readable and its map there (a
    record is written last, so a missing map was removed since, and the frame is done again)."""
    record, map_file = record_path(out, frame), out / "maps" / f"{frame.stem}.npy"
    if not (record.is_file() and map_file.is_file()):
        return None
    try:
        return json.loads(record.read_text())
    except (OSError, json.JSONDecodeError):
        return None


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


def collect(plan: RunPlan, outcomes) -> None:
    """Each frame's outcome through the run's FrameLoop as it arrives, its outputs written on
    a thread (while the next frame infers), in order; a frame that could not be processed is
    skipped with its reason (fatal with --strict). Every write started is finished before this
    returns or raises."""
    from concurrent.futures import ThreadPoolExecutor

    loop, failed = plan.loop, []

    def write(done):  # after a failed write no later frame is written: frames stay in order
        if failed:
            raise RuntimeError("not written: an earlier frame's write failed")
        try:
            return loop.write(done)
        except BaseException as e:
            failed.append(e)
            raise

    with ThreadPoolExecutor(1) as writer:
        pending = []
        try:
            for name, output, error in outcomes:
                if error is None:
                    done = loop.done(name, output)
                    pending.append((name, output, done, writer.submit(write, done)))
                else:
                    loop.skip(name, error)
                while pending and pending[0][3].done():
                    name, output, done, future = pending.pop(0)
                    loop.keep(name, output, done, future.result())
        finally:
            for item in pending:
                item[3].exception()  # wait for it; an error is raised below, in order
        for name, output, done, future in pending:
            loop.keep(name, output, done, future.result())


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
    summary = summarise(cfg, done, plan.records, plan.skipped, truth, plan.geometry,
                        plan.device, plan.background, plan.ground, plan.grown)
    if plan.auto_report is not None:
        summary["background_auto"] = plan.auto_report
    summary["inference"] = plan.inference
    summary["runner"] = {**runner, "frames_resumed": len(done) - sum(plan.by_worker.values()),
                         "frames_per_worker": dict(sorted(plan.by_worker.items()))}
    stamps = {f.name: plan.records[f.name].get("timestamp") for f in done}
    summary["tracking"], end = track_run(plan.view, plan.writers, done, truth, log=lambda *_: None,
                                         fps=fps_of(list(stamps.values())), timestamps=stamps,
                                         records=plan.records)
    summary["timings"]["setup_s"] = plan.setup_s
    summary["timings"]["total_s"] = time.perf_counter() - plan.t_start
    end.records, end.summary = plan.records, summary
    plan.writers.finish(end)  # detections.csv, the tracks' tables, the Rerun log closed, summary.json last
    if truth is not None and done:  # the curves of `dpom-warp eval`, from the maps just written
        from .evaluate import evaluate_runs

        results = evaluate_runs([out], cfg.evaluation.ground_truth, cfg.evaluation.hidden_visibility)
        write_json_atomic(out / "eval.json", jsonable(results))
        if cfg.evaluation.plots:
            from .plots import write_figures

            write_figures(results, out / "plots")
    return summary


def track_run(view: RunView, writers: Writers, done: list[Path], truth=None, log=print,
              fps: float | None = None, timestamps: dict | None = None,
              records: dict | None = None) -> tuple[dict, RunEnd]:
    """Tracks of a run whose maps are written (maps/<stem>.npy of the `done` frames, in
    order), then every frame's tracks handed to the writers (`tracked`: the pictures with the
    tracks, deferred until now, and the Rerun log). `fps`: the frames' rate from their
    timestamps (default input.fps). `records`: each of the `done` frames' record by name, as the
    run holds them (None: read from frames/<stem>.json, as `dpom-warp track` does). Returns (the
    `tracking` block of summary.json, the RunEnd the writers finish with: the frames, their
    tracks). tracking.method off (or a single frame): no tracks (their tables removed)."""
    from .tracking import Cells, FrameMaps, run_tracker

    cfg, out = view.cfg, view.out
    method = cfg.tracking.resolved_method(len(done))
    maps = FrameMaps([out / "maps" / f"{f.stem}.npy" for f in done], keep=2 * cfg.tracking.window)
    names = [f.name for f in done]
    times = [(timestamps or {}).get(n) for n in names]  # frames dropped or skipped between: by the clock
    if method == "off":
        tracked_frames(view, writers, done, maps, truth, None, timestamps)
        why = ("tracking.method: off" if cfg.tracking.method == "off" else
               f"tracking.method {cfg.tracking.method} tracks 2 frames or more, found {len(done)}")
        return {"method": "off", "why": why}, RunEnd(names, {}, None, None, times)
    cells = Cells.for_run(view.geometry, cfg)
    rate = fps or cfg.inputs.fps
    tracks, report = run_tracker(maps, cells, cfg.grid.shape, cfg.tracking, rate, cfg.detection.threshold,
                                 method, times)
    placed = placed_on_heads(tracks, (records[f.name] if records is not None else read_record(out, f)
                                      for f in done), cfg)
    if placed is not None:
        report["positions"] = placed
    report["fps_from"] = "timestamps" if fps else "input.fps"
    log(f"{len(tracks)} tracks ({method}) in {report['time_s']:.2f} s "
        f"({report['ms_per_frame']:.1f} ms per frame)")
    t = time.perf_counter()
    tracked_frames(view, writers, done, maps, truth, tracks, timestamps)
    if cfg.output.images or cfg.output.rerun or cfg.output.view:
        report["pictures_s"] = time.perf_counter() - t
    return report, RunEnd(names, {}, tracks, rate, times)


def read_record(out: Path, frame: Path) -> dict:
    """A finished frame's record, frames/<stem>.json ({} where there is none)."""
    path = record_path(out, frame)
    return json.loads(path.read_text()) if path.is_file() else {}


def placed_on_heads(tracks: list, records: Iterable[dict], cfg) -> dict | None:
    """`tracks` moved to their detections' heads (heads.place_tracks) as the frames' records
    (in the tracks' frame order; taken only where the run places tracks) found them; returns
    the tracking block's `positions` (how many track-frames are at a head, how many at a cell
    centre), or None where the run places none (heads.can_place)."""
    from .heads import Placer, found_in

    placer = Placer.of(cfg)
    if placer is None:
        return None
    found = [found_in(record) for record in records]
    at_heads = placer.tracks(tracks, found)
    shown = sum(int((~tr.bridged).sum()) for tr in tracks)
    return {"at": "head", "head": at_heads, "cell": shown - at_heads}


def tracked_frames(view: RunView, writers: Writers, done: list[Path], maps, truth, tracks,
                   timestamps: dict | None) -> None:
    """Every frame of a tracked (or, `tracks` None, untracked) run handed to the writers with
    its tracks (ShownTracks: identities, boxes, trails), its map loaded and its depth read only
    where a writer asks."""
    from .track_files import per_frame

    now = per_frame(tracks, len(done)) if tracks is not None else [[] for _ in done]
    trails = ShownTracks(view.geometry, view.cfg.tracking.trail)
    shown = [trails.at(i, now[i]) if tracks is not None else None for i in range(len(done))]

    def frame(i):
        f = done[i]
        return FrameDone(view, i, f.name, f.stem, (timestamps or {}).get(f.name), lambda: maps[i], path=f,
                         truth=truth.get(f.name) if truth else None)

    writers.tracked_all(frame, shown)


RETRACK_KEYS = ("tracking.", "input.fps", "output.images", "output.rerun", "output.view", "zones", "lines", "counting")


def retrack(run_dir: str | Path, overrides: list[str], log=print) -> dict:
    """`dpom-warp track RUN_DIR`: the tracks of a finished run again from its maps, with
    `overrides` (tracking.*, input.fps, output.images, output.rerun, output.view) applied to its
    config; tracks.csv, track_table.csv, the pictures, summary.json's `tracking` (with the
    settings used: `settings`) and eval.json are rewritten; run.json and summary.json's config
    stay as the run made them. Returns the new tracking block."""
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
            raise ConfigError(f"--set {key}: expected a tracking.* key, input.fps, output.images, output.rerun, output.view, "
                              f"zones, lines or counting.* (the rest of a run changes only by inferring again)")
    cfg = parse_config(apply_overrides(raw, overrides))
    fits = summary.get("ground_fit") if cfg.is_rig else [summary.get("ground_fit")]
    cameras = []
    for c, (_, m) in enumerate(cfg.members()):  # each camera as the run posed it
        camera = m.camera
        if m.pose_auto:
            camera = dataclasses.replace(camera, T_world_from_camera=np.array(fits[c]["T_world_from_camera"], float))
        cameras.append(camera)
    names = [p["frame"] for p in summary["per_frame"]]
    if cfg.live and (cfg.output.images or cfg.output.rerun or cfg.output.view):
        raise InputError(f"{run_dir}: a live run keeps no frames (input.frames: {cfg.inputs.frames}"
                         f"{', played' if cfg.inputs.play else ''}), so its "
                         f"pictures and Rerun log cannot be drawn again; expected --set output.images=false "
                         f"--set output.rerun=null (tracks.csv, track_table.csv and the summary only)")
    if cfg.output.images:
        if cfg.is_rig:  # each camera's frames paired again
            from .frames import rig_frames

            by_name = {f.name: f for f in rig_frames(cfg, log=lambda *_: None, check=False).frames}
        else:
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
    geometries = [build_geometry(c, cfg.grid, cfg.obj) for c in cameras]
    view = RunView(cfg, run_dir, RigGeometry(geometries) if cfg.is_rig else geometries[0],
                   cameras if cfg.is_rig else cameras[0])
    # the writers of what tracking changes: the pictures (all drawn again), the Rerun log, the
    # tracks' tables and summary.json
    writers = Writers([ZoneTables(view)] + ([Pictures(view)] if cfg.output.images else []) +
                      ([Rerun(view)] if cfg.output.rerun or cfg.output.view else []) +
                      [TrackTables(view), Summary(view)])
    # a live run's maps are the frames it took of its camera's: their rate is the camera's, as the
    # live tracker had it (their timestamps' intervals span the frames dropped between)
    camera_fps = (summary.get("live") or {}).get("camera_fps")
    try:
        report, end = track_run(view, writers, done, truth, log,
                                fps=camera_fps or fps_of([p.get("timestamp") for p in summary["per_frame"]]),
                                timestamps={p["frame"]: p.get("timestamp") for p in summary["per_frame"]})
    except BaseException:
        writers.close()
        raise
    if camera_fps:
        report["fps_from"] = "camera"
    # the run's config stays as made (summary.json's config, run.json): a later plain `track`
    # tracks as the run did; what this one used is in its tracking block
    report["settings"] = {"set": list(overrides), "tracking": cfg.resolved["tracking"], "input_fps": cfg.inputs.fps,
                          "output": {k: cfg.resolved["output"][k] for k in ("images", "images_every", "rerun", "view")}}
    summary["tracking"] = report
    end.summary = summary
    writers.finish(end)
    if truth is not None:
        from .evaluate import evaluate_runs

        results = evaluate_runs([run_dir], cfg.evaluation.ground_truth, cfg.evaluation.hidden_visibility)
        write_json_atomic(run_dir / "eval.json", jsonable(results))
    return report



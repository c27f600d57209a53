"""A run set up from its config, before any frame is inferred: the device, each camera posed and
its background made (camera_setup.py), the engine (one camera, or a rig's cameras over one grid)
and the batch. Every way of running frames starts from `set_up`: the recorded run and its
executors (one process, --workers, Ray), the live run and the Python API."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from .camera_setup import camera_background, planes_words, prepare_camera, static_structure
from .config import ConfigError, RunConfig
from .io import InputError
from .engine import Engine, MemoryBudgetError, resolve_device
from .frames import render_synthetic, run_frames  # noqa: F401 - render_synthetic: the API's
from .geometry import RigGeometry
from .worker import WorkerSpec, compile_kernels, make_engine


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
    return dataclasses.replace(cfg, engine=cfg.engine.model_copy(update={"batch": batch}))


def run_device(cfg: RunConfig, device: str | None, recorded: bool) -> tuple[str, RunConfig]:
    """The Warp device (a one-line error for one that is not there) and cfg with engine.batch
    auto chosen for it (auto_batch)."""
    try:
        dev = resolve_device(device or cfg.device)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if cfg.engine.batch == "auto":
        cfg = with_batch(cfg, auto_batch(dev, recorded))
    return dev, cfg


def budget_engine(cfg: RunConfig, camera, dev: str, batch_auto: bool) -> tuple[Engine, RunConfig]:
    """make_engine, with engine.batch auto halved until engine.memory_gb holds the engine;
    returns the engine and cfg with the batch it holds."""
    while True:
        try:
            return make_engine(cfg, camera, dev, cfg.engine.batch), cfg
        except MemoryBudgetError as e:
            if batch_auto and cfg.engine.batch > 1:  # fewer frames a call where the budget holds fewer
                cfg = with_batch(cfg, cfg.engine.batch // 2)
                continue
            raise ConfigError(f"engine.memory_gb: {e}; coarsen grid.x/grid.y or raise the budget") from None


def set_up(cfg: RunConfig, frames: list[Path], device: str | None = None, log=print,
           parallel: bool = False, keep_engine: bool = False, recorded: bool = False) -> Setup:
    """The pose (fitted with extrinsics: auto), the background (frames, auto from `frames`,
    or the floor) and the engine of a run: what `dpom-warp run` and the Python API's
    Detector both infer with. `frames`: the run's frames (read only for `auto` background
    and for a floor fit without background frames). engine.batch auto is GPU_BATCH for a
    `recorded` run on a GPU (halved until engine.memory_gb holds it), else 1; the Setup's
    spec.cfg has the batch chosen. A rig's: set_up_rig."""
    if cfg.is_rig:
        return set_up_rig(cfg, frames, device, log, parallel, keep_engine, recorded)
    batch_auto = cfg.engine.batch == "auto"
    dev, cfg = run_device(cfg, device, recorded)
    prep = prepare_camera(cfg, frames, dev, log)
    t = time.perf_counter()
    refuse_warm_start(cfg, parallel)
    log("setting up the engine (mask index; Warp kernels compiled on first use, then cached) ...")
    engine, cfg = budget_engine(cfg, prep.camera, dev, batch_auto)
    view = engine.views[0]  # the run's camera
    background, given, auto_report, structure = camera_background(cfg, view, prep, frames, dev, parallel, log)
    inference = inference_report(cfg, engine)
    if structure is not None:
        inference["structure"] = structure
    if parallel:  # every kernel compiled into the cache the workers are given
        compile_kernels(engine)
        engine = engine if keep_engine else None
    return Setup(dev, WorkerSpec(cfg, prep.camera, dev, given), prep.geometry, prep.ground, background, auto_report,
                 inference, engine, time.perf_counter() - t)


def set_up_on_first_frames(cfg: RunConfig, first: list, label: str, frames: list[Path] = (), device: str | None = None,
                           log=print) -> tuple[RunConfig, Setup]:
    """set_up for a live camera given its first frames (metres; the live run's, the API's
    first_frames), none inferred: with its pose left out (extrinsics: auto, no background
    frames) the floor is fitted on the first camera.ground.frames of them (`label`: how
    messages name them, "{n}" their number), and the setup keeps the fit's report and warnings
    as set_up's own fit does. Returns the posed config and the setup; `frames`: set_up's."""
    from .camera_setup import fit_pose_on_frames, warn_fitted_pose

    ground = None
    if first and cfg.pose_auto and not cfg.inputs.background:
        n = min(cfg.ground_frames, len(first))
        camera, ground = fit_pose_on_frames(cfg, first[:n], label.replace("{n}", str(n)), log)
        cfg = dataclasses.replace(cfg, camera=camera, pose_auto=False)
    setup = set_up(cfg, list(frames), device, log)
    if ground is not None:
        setup.ground = ground
        warn_fitted_pose(ground, setup.geometry, log)
    return cfg, setup


def planes_from_frames(cfg: RunConfig) -> bool:
    """Whether a camera's static planes (input.structure) come from its first frames: no
    background frames, and input.structure.planes."""
    return not cfg.inputs.background and cfg.inputs.structure.planes


def add_static_planes(setup: Setup, frames: list, log=print) -> dict:
    """The static planes (input.structure) found in `frames` (metres, full resolution: a live
    camera's first, given after setting up) made background in the setup's engine, its spec
    (what helper processes take), inference report and background words, as set_up makes them
    from the run's first files; returns the planes' report. A rig's frames have one depth a
    camera (None: none there): each floor-only camera's planes in its own frames, the report by
    camera name."""
    cfg, engine = setup.spec.cfg, setup.engine
    if not cfg.is_rig:
        view = engine.views[0]
        report = static_structure(cfg, view, setup.spec.camera, frames, log)
        setup.inference["structure"] = report
        if report["pixels"]:
            setup.background += planes_words(report)
            setup.spec.background = view.background_state()
        return report
    reports = {}
    for c, ((name, m), view) in enumerate(zip(cfg.cameras, engine.views)):
        own = [f[c] for f in frames if f[c] is not None]
        if own and planes_from_frames(m):
            reports[name] = static_structure(m, view, setup.spec.camera[c], own, _named(log, name))
            if reports[name]["pixels"]:
                setup.background += f"; camera {name}{planes_words(reports[name])}"
    setup.inference["structure"] = reports
    states = [engine.background_state(c) for c in range(len(engine.views))]
    setup.spec.background = states if any(s is not None for s in states) else None
    return reports


def refuse_warm_start(cfg: RunConfig, parallel: bool) -> None:
    """model.warm_start chains each frame to the one before: not with frames inferred by other
    processes (a one-line ConfigError)."""
    if parallel and cfg.model.warm_start:
        raise ConfigError("model.warm_start: each frame starts from the previous one, so frames "
                          "must run in order in one process; expected no --workers or --ray with it")


def inference_report(cfg: RunConfig, engine: Engine) -> dict:
    """summary.json's inference: the stride, the image, the sparse and batch settings."""
    r, view = engine.resolution, engine.views[0]
    return {"stride": r.stride, "reduce": r.reduce, "image": [view.width, view.height],
            "sparse_epsilon": cfg.model.sparse_epsilon, "bound_rounds": cfg.model.bound_rounds,
            "warm_start": cfg.model.warm_start, "exact": cfg.engine.exact, "batch": cfg.engine.batch}


def camera_frames(frames: list, c: int) -> list[Path]:
    """Camera c's files among a rig's frames (frames.RigFrame), in order."""
    return [f.paths[c] for f in frames if f.paths[c] is not None]


def set_up_rig(cfg: RunConfig, frames: list, device: str | None = None, log=print, parallel: bool = False,
               keep_engine: bool = False, recorded: bool = False) -> Setup:
    """session.set_up for a rig: its Setup's geometry, ground and auto report are lists (one a
    camera), its spec's camera and background too; its background words name each camera's."""
    batch_auto = cfg.engine.batch == "auto"
    dev, cfg = run_device(cfg, device, recorded)
    preps = []
    for c, (name, m) in enumerate(cfg.cameras):
        try:
            preps.append(prepare_camera(m, camera_frames(frames, c), dev, _named(log, name)))
        except (ConfigError, InputError) as e:  # said of the camera (its floor fit, its view of the grid)
            raise type(e)(f"cameras[{c}] ({name}): {e}") from None
    for line in lone_cameras(cfg, [p.geometry for p in preps]):
        log(f"warning: {line}")
    t = time.perf_counter()
    refuse_warm_start(cfg, parallel)
    log(f"setting up the engine for {len(preps)} cameras (mask index; Warp kernels compiled on first use, then "
        f"cached) ...")
    engine, cfg = budget_engine(cfg, [p.camera for p in preps], dev, batch_auto)
    words, given, autos, structures = [], [], [], {}
    for c, ((name, m), prep, view) in enumerate(zip(cfg.cameras, preps, engine.views)):
        said, state, auto, structure = camera_background(m, view, prep, camera_frames(frames, c), dev, parallel,
                                                         _named(log, name))
        words.append(f"{name}: {said}")
        given.append(state)
        autos.append(auto)
        if structure is not None:
            structures[name] = structure
    inference = inference_report(cfg, engine)
    inference["image"] = [[v.width, v.height] for v in engine.views]
    if structures:
        inference["structure"] = structures
    if parallel:  # every kernel compiled into the cache the workers are given
        compile_kernels(engine)
        engine = engine if keep_engine else None
    grounds = [p.ground for p in preps]
    return Setup(dev, WorkerSpec(cfg, [p.camera for p in preps], dev, given if any(g is not None for g in given)
                                 else None), RigGeometry([p.geometry for p in preps]),
                 grounds if any(g is not None for g in grounds) else None, "; ".join(words),
                 autos if any(a is not None for a in autos) else None, inference, engine, time.perf_counter() - t)


def lone_cameras(cfg: RunConfig, geometries: list) -> list[str]:
    """A warning for each camera of a rig that sees none of the grid's cells another camera
    sees: its evidence fuses with no other camera's (and calibrate cannot place it)."""
    seen = [g.rect_area > 0 for g in geometries]
    out = []
    for c, (name, _) in enumerate(cfg.cameras):
        others = np.any([s for i, s in enumerate(seen) if i != c], axis=0) if len(seen) > 1 else seen[c]
        if len(seen) > 1 and not np.any(seen[c] & others):
            out.append(f"cameras[{c}].camera.extrinsics: camera {name} sees none of the grid's cells another camera "
                       f"sees ({int(seen[c].sum())} cells of its own); expected views that overlap, for one map")
    return out


def _named(log, name: str):
    """`log` whose lines name the camera."""
    return lambda line: log(f"camera {name}: {line}")

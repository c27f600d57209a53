"""The engine side of a run: the same in every process that infers frames.

A FrameWorker holds one engine (geometry, mask index, compiled kernels), built once, and turns
depth frames into FrameOutputs: the occupancy map, the picture and point-cloud files as bytes,
and the frame's record. It runs in the run's own process, in `--workers` processes and in Ray
actors (cluster.py); only the run's own process writes outputs (writers.py), so the files
are the same whoever inferred them, and a cluster's nodes need no shared disk. A live run's
helper processes (Helpers) each hold a FrameWorker's engine too.
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import io
import os
import pickle
import shutil
import tarfile
import tempfile
import time
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .detect import joint_detections
from .engine import Engine, ListOverflow
from .geometry import Camera, RigGeometry, build_geometry
from .heads import HeadFinder, can_place
from .io import InputError, read_depth
from .resolution import Resolution, auto_stride


@dataclasses.dataclass
class WorkerSpec:
    """All a worker needs to build the engine of a run: the config, the posed camera (a
    fitted pose included), the Warp device and the background: None for the floor-only
    model, else (Background, fallback) at the engine's resolution, where fallback (H, W)
    marks the pixels left to the floor-only model (or is None)."""

    cfg: RunConfig
    camera: Camera
    device: str
    background: tuple | None = None
    pictures: bool = True  # False: the run draws them after tracking


@dataclasses.dataclass
class FrameItem:
    """One frame to infer: its file, the file's bytes when they travel to the worker (None:
    the worker reads the file), and its ground truth (for the picture)."""

    path: str
    data: bytes | None = None
    truth: list | None = None
    paths: tuple | None = None  # a rig's frame: each camera's file (None: no frame of that camera)


@dataclasses.dataclass
class FrameOutput:
    """What a frame gives: its map (float32), its other files (output-relative path ->
    bytes), its record (frames/<stem>.json) and the list-capacity growths it caused."""

    name: str
    stem: str
    map: np.ndarray
    files: dict
    record: dict
    grown: list


def resolution_of(cfg: RunConfig, camera: Camera | list[Camera]) -> Resolution:
    """input.stride (auto: resolution.auto_stride for this camera and grid; a rig's cameras:
    the finest any of them chooses) and input.reduce."""
    cameras = camera if isinstance(camera, list) else [camera]
    stride = (min(auto_stride(c, cfg.grid, cfg.obj) for c in cameras) if cfg.inputs.stride == "auto"
              else cfg.inputs.stride)
    for c in cameras:
        if min(c.width // stride, c.height // stride) < 1:
            raise ConfigError(f"input.stride: expected a stride that leaves at least one pixel of "
                              f"the {c.width}x{c.height} image, found {stride}")
    return Resolution(stride, cfg.inputs.reduce, cfg.model.z_max)


def read_frame(cfg: RunConfig, path, data: bytes | None = None) -> np.ndarray:
    """A frame of the run's camera in metres (io.read_depth); `data`: the file's bytes."""
    return read_depth(path, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width), data)


def read_rig_frame(cfg: RunConfig, paths, data: tuple | None = None, seconds: dict | None = None
                   ) -> list[np.ndarray | None]:
    """A rig's frame in metres, one a camera (read with its own input section; `data`: the
    files' bytes); None for a camera with no frame there. `seconds`: filled with each camera's
    read time, by name."""
    data = data or (None,) * len(paths)
    out = []
    for (name, m), p, b in zip(cfg.cameras, paths, data):
        t = time.perf_counter()
        out.append(read_frame(m, p, b) if p is not None else None)
        if seconds is not None and p is not None:
            seconds[name] = time.perf_counter() - t
    return out


def make_engine(cfg: RunConfig, camera: Camera, device: str, batch: int,
                resolution: Resolution | None = None) -> Engine:
    """The engine of a run (engine.* options) at the run's inference resolution (`resolution`:
    another's), for `batch` frames per call; it takes frames at the camera's full resolution
    (reduced by the engine: on a GPU by a kernel) or already reduced by engine.resolution.frames."""
    resolution = resolution or resolution_of(cfg, camera)
    if isinstance(camera, list):  # a rig: one geometry a camera
        geometry = [build_geometry(resolution.camera(c), cfg.grid, cfg.obj) for c in camera]
    else:
        geometry = build_geometry(resolution.camera(camera), cfg.grid, cfg.obj)
    # the tile index's tiles (where the pixel table is not used) keep about 8 x 8 full-resolution
    # pixels' worth of the scene (2 x 2 at stride 4: list building ~20 % faster than 8 x 8 there)
    tile = max(2, round(8 / resolution.stride))
    engine = Engine(geometry, cfg.model, device, cfg.engine.entries_per_pixel, cfg.engine.max_entries,
                    cfg.engine.memory_gb, tile=tile, batch=batch,
                    graph={"auto": None, "on": True, "off": False}[cfg.engine.graph],
                    table={"auto": None, "table": True, "tiles": False}[cfg.engine.mask_index],
                    resolution=resolution,
                    background_auto=cfg.inputs.background_auto if cfg.inputs.auto_background else None,
                    drift=cfg.inputs.drift)
    if cfg.detection.min_log_odds > 0:  # results carry the joint test's lists (joint.JointLists)
        engine.joint_threshold = cfg.detection.threshold
    return engine


def detections_of(res, geometry, cfg: RunConfig) -> tuple[np.ndarray, list]:
    """FrameWorker.detections for a result of an engine made by make_engine (its results carry
    the joint test's lists where the test is on), `geometry` at full resolution."""
    rho_map = res.rho_star.reshape(cfg.grid.shape)
    return joint_detections(rho_map, geometry, cfg.detection, None if res.joint is None else res.joint.log_odds)


class FrameWorker:
    """One run's engine and what turns its results into outputs. `engine`: one built
    already (with its background set), else it is built from `spec`; `name` is written in
    the records of the frames it infers."""

    def __init__(self, spec: WorkerSpec, name: str = "main", engine: Engine | None = None):
        self.cfg, self.name = spec.cfg, name
        self.pictures = spec.cfg.output.images and spec.pictures
        self.rig, self.spec = isinstance(spec.camera, list), spec
        self.partial: dict[tuple, Engine] = {}  # a rig's cameras that have a frame -> their engine
        self.read_cameras: dict[str, dict] = {}  # a rig's frame (path) -> each camera's read time
        self.geometry = (RigGeometry([build_geometry(c, spec.cfg.grid, spec.cfg.obj) for c in spec.camera]) if self.rig
                         else build_geometry(spec.camera, spec.cfg.grid, spec.cfg.obj))  # full resolution
        if engine is None:
            engine = make_engine(spec.cfg, spec.camera, spec.device, spec.cfg.engine.batch)
            if self.rig:
                for c, state in enumerate(spec.background or []):
                    if state is not None:
                        engine.set_background(*state, camera=c)
            elif spec.background is not None:
                engine.set_background(*spec.background)
        self.engine = engine
        self.head_finder = HeadFinder(spec.cfg, engine, spec.camera, self.geometry) if can_place(spec.cfg) else None

    def read(self, items: list[FrameItem]) -> tuple[list, list]:
        """The frames of `items` read: (outcomes of those that cannot be, [(item, depth, read_s)])."""
        outcomes, read = [], []
        for item in items:
            t = time.perf_counter()
            try:
                depth = (read_rig_frame(self.cfg, item.paths, item.data, self.read_cameras.setdefault(item.path, {}))
                         if item.paths is not None else read_frame(self.cfg, item.path, item.data))
            except InputError as e:
                outcomes.append((Path(item.path).name, None, str(e)))
                continue
            read.append((item, depth, time.perf_counter() - t))
        return outcomes, read

    def process(self, items: list[FrameItem], read: tuple | None = None
                ) -> list[tuple[str, FrameOutput | None, str | None]]:
        """(frame name, output, None), or (frame name, None, reason) for a frame that cannot be
        read or whose lists overflow, for up to engine.batch frames; a batch whose lists
        overflow is retried frame by frame. `read`: what `read(items)` gave, done already
        (the one-process run reads the next frames while these infer)."""
        outcomes, read = self.read(items) if read is None else (list(read[0]), read[1])
        engine = self.engine
        whole = not self.rig or all(d is not None for _, frame, _ in read for d in frame)
        if len(read) > 1 and whole:
            grown, t0 = len(engine.grown), time.perf_counter()
            try:
                results = engine.infer_batch(stacked([d for _, d, _ in read], self.rig))  # reduced by the engine
            except ListOverflow:
                pass  # each frame alone below
            else:
                share = (time.perf_counter() - t0) / len(read)
                for i, ((item, depth, read_s), res) in enumerate(zip(read, results)):
                    res = every_camera(res, [True] * len(depth)) if self.rig else res
                    growth = engine.grown[grown:] if i == 0 else []
                    outcomes.append(self._finish(item, depth, res, read_s, share, growth))
                return outcomes
        for item, depth, read_s in read:
            grown, t0 = len(engine.grown), time.perf_counter()
            try:
                res = self.infer(depth)
            except ListOverflow as e:
                outcomes.append((Path(item.path).name, None, f"{item.path}: {e}"))
                continue
            outcomes.append(self._finish(item, depth, res, read_s, time.perf_counter() - t0,
                                         engine.grown[grown:]))
        return outcomes

    def infer(self, depth):
        """One frame's engine result; a rig's frame where some cameras have none (None) is
        inferred by an engine of the cameras that have one (built once for those cameras, at
        the rig's resolution, with their backgrounds): the rig without them."""
        if not self.rig:
            return self.engine.infer(depth)
        if all(d is not None for d in depth):
            return every_camera(self.engine.infer(depth if len(depth) > 1 else depth[0]), [True] * len(depth))
        present = tuple(d is not None for d in depth)
        if not any(present):
            raise InputError("no camera of the rig has a frame here")
        if present not in self.partial:
            which = [c for c, p in enumerate(present) if p]
            cameras = [self.spec.camera[c] for c in which]
            part = make_engine(self.cfg, cameras if len(which) > 1 else cameras[0], self.spec.device,
                               1, self.engine.resolution)
            for i, c in enumerate(which):
                state = self.engine.background_state(c)
                if state is not None:
                    part.set_background(*state, camera=i)
            self.partial[present] = part
        frames = [d for d in depth if d is not None]
        return every_camera(self.partial[present].infer(frames if len(frames) > 1 else frames[0]), present)

    def detections(self, res) -> tuple[np.ndarray, list]:
        """The rho* map (grid-shaped) of an engine result and its detections, located and
        boxed on the full-resolution geometry, after the joint test (detect.joint_detections:
        a cell it rejects is 0 in the map returned, which is the run's map)."""
        return detections_of(res, self.geometry, self.cfg)

    def heads(self, dets: list, depth, res) -> list | None:
        """Each detection's head position in the frame `depth` (a rig's: one a camera) of result
        `res` (heads.HeadFinder), or None where the run places none (heads.can_place)."""
        return self.head_finder(dets, depth, res) if self.head_finder is not None else None

    def _finish(self, item: FrameItem, depth, res, read_s: float, infer_s: float, grown: list):
        """Detections, map, picture and record of an inferred frame; `infer_s` is the
        frame's share of a batch."""
        cfg, geometry, f = self.cfg, self.geometry, Path(item.path)
        t1 = time.perf_counter()
        rho_map, dets = self.detections(res)
        rho_map = rho_map.astype(np.float32)  # the map written, which later pictures are drawn from
        found = self.heads(dets, depth, res)
        t2 = time.perf_counter()
        files = {}
        if self.pictures and self.rig:
            from .render_rig import rig_picture

            files[f"images/{f.stem}.png"] = rig_picture(depth, rho_map, cfg, geometry, dets, item.truth, f.name)
        elif self.pictures:
            from .render import frame_picture

            files[f"images/{f.stem}.png"] = frame_picture(depth, rho_map, cfg.grid, dets,
                                                          geometry.centre[:2], item.truth, f.name,
                                                          in_view=geometry.rect_area > 0)
        if cfg.output.ply:
            from .render import ply_files

            files.update(ply_files(f.stem, depth, geometry, dets, cfg))
        t3 = time.perf_counter()
        timings = dict(res.timings)
        per_camera = {k: timings.pop(k, None) for k in ("lists_s_cameras", "iterations_s_cameras")}
        record = {
            "frame": f.name,
            "rows": [f"{f.name},{d.x:.4f},{d.y:.4f},{d.z:.4f},{d.rho:.6f},{d.box[0]},{d.box[1]},"
                     f"{d.box[2]},{d.box[3]}" for d in dets],
            "xy": [[d.x, d.y, d.z] if cfg.grid.mode == "voxel" else [d.x, d.y] for d in dets],
            **({} if found is None else {"heads": [None if h is None else [round(h[0], 4), round(h[1], 4)]
                                                   for h in found]}),
            "stats": {"frame": f.name, "detections": len(dets), "iterations": res.iterations,
                      "converged": res.converged,
                      "live": res.live, "entries": res.entries, "kept_entries": res.kept_entries,
                      "read_s": read_s,
                      "infer_s": infer_s, "detect_s": t2 - t1, "render_s": t3 - t2,
                      "worker": self.name, **{f"engine_{k}": v for k, v in timings.items()}},
        }
        if self.rig:  # each camera's file (None: inferred from the others) and drift
            names = cfg.camera_names
            record["cameras"] = {n: (Path(p).name if p is not None else None) for n, p in zip(names, item.paths)}
            record["stats"]["read_s_cameras"] = self.read_cameras.pop(item.path, {})
            present = [n for n, p in zip(names, item.paths) if p is not None]  # the engine's cameras
            for key, times in per_camera.items():  # each camera's engine time by name (engine.infer_batch)
                record["stats"][key] = dict(zip(present, times)) if times is not None else {}
            if res.drift is not None:
                record["stats"]["drift"] = {n: (d.record() if d is not None else None) for n, d in zip(names, res.drift)}
        elif res.drift is not None:  # the frame's depth scale against the background (drift.py)
            record["stats"]["drift"] = res.drift.record()
        return f.name, FrameOutput(f.name, f.stem, rho_map, files, record,
                                   list(grown)), None


def compile_kernels(engine: Engine) -> None:
    """An empty frame (a rig's: one a camera) through `engine`: every kernel compiled, into the
    cache other processes are given."""
    empty = [np.zeros((1, v.height, v.width), np.float32) for v in engine.views]
    engine.infer_batch(empty if len(empty) > 1 else empty[0])


def every_camera(res, present):
    """A rig's result with its drift a list over every camera of the rig (None where a camera
    had no frame, or no estimate), whichever engine inferred it."""
    if res.drift is None:
        return res
    got = iter(res.drift if isinstance(res.drift, list) else [res.drift])
    return dataclasses.replace(res, drift=[next(got) if p else None for p in present])


def stacked(depths: list, rig: bool):
    """A batch's frames as the engine takes them: (n, H, W), a rig's one such a camera."""
    if not rig:
        return np.stack(depths)
    per_camera = [np.stack([d[c] for d in depths]) for c in range(len(depths[0]))]
    return per_camera if len(per_camera) > 1 else per_camera[0]  # (the engine of a rig of one takes an array)


# -- compiled kernels for other processes ---------------------------------------------------
CACHE_PREFIX = "dpom-warp-cache-"


def kernel_cache() -> dict:
    """This package's compiled Warp modules from this process's kernel cache, as a tar
    archive (about 1 MB): a worker that installs it (install_kernel_cache) loads the kernels
    instead of compiling them, on this machine or another of the same platform."""
    import warp as wp

    root = Path(wp.config.kernel_cache_dir)
    archive = io.BytesIO()
    with tarfile.open(fileobj=archive, mode="w") as tar:
        for entry in sorted(root.glob("wp_dpom_warp*")):
            tar.add(entry, arcname=entry.name)
    return {"version": root.name, "tar": archive.getvalue()}


def install_kernel_cache(cache: dict | None) -> None:
    """Before Warp starts in this process: give it a private kernel cache (one per
    concurrent process), holding `cache` (kernel_cache's archive) when given. Caches left by
    killed processes are removed."""
    from warp._src import context

    if context.runtime is not None:
        return  # Warp has started here: it keeps its cache
    _remove_orphan_caches()
    own = Path(tempfile.mkdtemp(prefix=f"{CACHE_PREFIX}{os.getpid()}-"))
    atexit.register(shutil.rmtree, own, True)
    if cache:
        target = own / cache["version"]
        target.mkdir()
        with tarfile.open(fileobj=io.BytesIO(cache["tar"])) as tar:
            if hasattr(tarfile, "data_filter"):
                tar.extractall(target, filter="data")
            else:  # Python < 3.10.12: our own archive, made by kernel_cache
                tar.extractall(target)
    # Warp keeps its modules under WARP_CACHE_PATH/<version>, read when it initialises
    os.environ["WARP_CACHE_PATH"] = str(own)


def _remove_orphan_caches():
    if not os.path.isdir("/proc/self"):
        return  # no /proc: no way to tell a dead process's cache from a live one's
    for old in Path(tempfile.gettempdir()).glob(f"{CACHE_PREFIX}*"):
        pid = old.name[len(CACHE_PREFIX):].split("-")[0]
        if pid.isdigit() and not Path(f"/proc/{pid}").exists():
            shutil.rmtree(old, ignore_errors=True)


_start_files: dict = {}  # helper_start_file's files -> their removal at exit


def helper_start_file(spec: WorkerSpec) -> Path:
    """A file of this process's holding `spec` and kernel_cache()'s archive, which a spawned
    helper's initializer reads (_pool_start); removed by remove_start_file, else when this
    process exits, else (killed) by the next process that starts a worker.

    They travel by file, not as the initializer's arguments: spawning a process writes its
    arguments into a pipe, and CPython keeps the pipe's read end open in the parent while it
    writes, so a helper that dies before reading more than a pipe holds (64 KB; the kernels
    are ~1 MB) would block the spawning thread for ever, holding the pool's lock."""
    folder = Path(tempfile.mkdtemp(prefix=f"{CACHE_PREFIX}{os.getpid()}-"))
    path = folder / "helper.pickle"
    _start_files[path] = functools.partial(shutil.rmtree, folder, True)
    atexit.register(_start_files[path])
    path.write_bytes(pickle.dumps((spec, kernel_cache()), protocol=pickle.HIGHEST_PROTOCOL))
    return path


def helper_pool(spec: WorkerSpec, n: int, initializer):
    """(pool, start file): n helper processes ('spawn': no Warp state is forked), each running
    `initializer` on the path of helper_start_file(spec) as it starts."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    start_file = helper_start_file(spec)
    pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn"), initializer=initializer,
                               initargs=(str(start_file),))
    return pool, start_file


def remove_start_file(path: Path) -> None:
    """Remove helper_start_file's file (every helper has read it or will never start)."""
    remove = _start_files.pop(path, None)
    if remove is not None:
        atexit.unregister(remove)  # (a long-lived process makes many runs)
        remove()


# -- `--workers N`: processes on this machine -----------------------------------------------
_pool_worker: list[FrameWorker] = []


def _pool_start(start_file: str) -> None:
    spec, cache = pickle.loads(Path(start_file).read_bytes())
    install_kernel_cache(cache)
    _pool_worker.append(FrameWorker(spec, name=f"process {os.getpid()}"))


def _pool_process(items: list[FrameItem]):
    return _pool_worker[0].process(items)


def pool_outcomes(spec: WorkerSpec, chunks: list[list[FrameItem]], workers: int, engine: Engine):
    """The outcomes of FrameWorker.process over `chunks`, in chunk order, inferred by this
    process (with `engine`, set up from `spec`) and workers - 1 helper processes ('spawn': no
    Warp state is forked) that each build the engine once from `spec` and load the kernels
    this process compiled (helper_start_file); frames travel as paths (the processes share
    this disk). The helpers are spawned on a thread (a spawn blocked until the child had read
    its arguments, ~0.7 s, when they held the spec and the kernels; a few ms now) and get
    chunks, two queued each, once started (an empty task done), so that no chunk waits for a
    helper still starting (~2 s to build its engine); this process takes the next chunk
    whenever they have theirs, and the last two itself (a helper's first chunk can take
    longer than those)."""
    import threading
    from concurrent.futures.process import BrokenProcessPool

    from .io import WorkerError

    helpers = workers - 1
    here = FrameWorker(spec, engine=engine)
    pool, start_file = helper_pool(spec, helpers, _pool_start)
    started: list = []

    def start():
        try:
            for _ in range(helpers):
                started.append(pool.submit(_pool_started))
        except BrokenProcessPool as e:  # a helper died starting: the run learns it below
            started.append(failed_future(e))
        except RuntimeError:  # the run ended first (the pool shut down)
            pass

    starting = threading.Thread(target=start, daemon=True)
    starting.start()
    inferred: dict[int, list] = {}  # chunk -> its outcomes (here) or the future of them (helpers)
    nxt = 0
    try:
        for i in range(len(chunks)):
            while i not in inferred or not _ready(inferred[i]):
                for f in started:  # a helper that died starting ends the run as one dying later
                    if f.done() and f.exception() is not None:
                        raise f.exception()
                ahead = 2 * sum(f.done() for f in started)
                while nxt < len(chunks) - 2 and sum(not _ready(v) for v in inferred.values()) < ahead:
                    inferred[nxt] = pool.submit(_pool_process, chunks[nxt])
                    nxt += 1
                if nxt >= len(chunks):
                    break  # nothing left to infer here: wait for the helpers' chunk i
                inferred[nxt] = list(here.process(chunks[nxt]))  # the next one, here
                nxt += 1
            got = inferred.pop(i)
            yield from (got if isinstance(got, list) else got.result())
        # every chunk done: a helper still starting is not waited for, one being spawned
        # (the thread still in submit) is left to end once it has started
        spawning = starting.is_alive()
        if not spawning:
            _stop_helpers(pool)
        pool.shutdown(wait=not spawning, cancel_futures=True)
    except BrokenProcessPool as e:
        raise WorkerError(f"--workers: a worker process died ({e}); finished frames are "
                          f"kept, continue with --resume") from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)  # (returns at once after the above)
        if not starting.is_alive():  # else a helper may not have read it yet: removed at exit
            remove_start_file(start_file)


def failed_future(error: BaseException) -> Future:
    """A future that holds `error` (a frame handed to helper processes that have died)."""
    fut = Future()
    fut.set_exception(error)
    return fut


def _stop_helpers(pool) -> None:
    """End a process pool's workers now (their work all done; one may still be starting:
    building its engine takes a second or two, which a short run should not wait for). Their
    private kernel caches are removed by the next process that starts one."""
    terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()


def _pool_started() -> bool:
    """An empty task: done once a helper has built its engine (pool_outcomes)."""
    return True


def _ready(value) -> bool:
    """A chunk's outcomes are in: inferred here, or its helper's future done."""
    return isinstance(value, list) or value.done()


def _helper_start(start_file: str) -> None:
    """A helper process of a live run: Ctrl-C is the main process's to handle; the engine is
    built from the run's spec with the kernels the main process compiled."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _pool_start(start_file)


def _helper_infer(small: np.ndarray):
    """(result, inference seconds, the process's name) of one frame at the engine's resolution."""
    worker = _pool_worker[0]
    t = time.perf_counter()
    res = worker.infer(small)  # a rig's frame missing a camera: the others' engine
    return res, time.perf_counter() - t, worker.name


class Helpers:
    """`n` processes, each with its own engine, inferring the frames the main process's
    feeder thread hands them while its loop infers others (Warp runs a CPU launch on one
    thread: this is how a live run uses more cores). If one dies, its frames are inferred by
    the main process and the run goes on without helpers."""

    def __init__(self, spec, engine, n: int):
        rig = isinstance(spec.camera, list)
        states = [engine.background_state(c) for c in range(len(engine.views))]
        spec = dataclasses.replace(spec, background=states if rig else states[0])
        empty = [np.zeros((v.height, v.width), np.float32) for v in engine.views]  # a frame of each camera
        compile_kernels(engine)
        self.n, self.running = n, []
        self.pool, self.start_file = helper_pool(spec, n, _helper_start)
        try:
            warm = [self.pool.submit(_helper_infer, empty if rig else empty[0]) for _ in range(n)]
            for w in warm:  # started, engines built: the first frames do not wait for them
                w.result()
        except BaseException:
            self.close()
            raise

    def busy(self) -> list:
        """The futures of the frames the helpers are inferring now."""
        self.running = [f for f in self.running if not f.done()]
        return list(self.running)

    def submit(self, small: np.ndarray):
        """A future of the frame's result; a pool already broken by a helper's death (which
        the main process may learn of here first) gives a future holding that error, so the
        frame is inferred where every other death is handled (run_live's adopt)."""
        try:
            fut = self.pool.submit(_helper_infer, small)
        except BrokenProcessPool as e:
            fut = failed_future(e)
        self.running.append(fut)
        return fut

    def close(self):
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None
            remove_start_file(self.start_file)

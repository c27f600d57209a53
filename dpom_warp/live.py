"""A run on a live camera (`input.frames: realsense[:SERIAL]`), or on frames played as one
(`input.play`: sources.played, ending with them): it goes on until Ctrl-C or
`--max-frames N`, always infers the newest frame and drops those it cannot keep up with
(counted), tracks online, writes the usual outputs (a picture of every
`output.images_every`-th frame: with tracks, drawn with them once the online tracker commits
its frame, as the live view's identities) and prints a live line with the rate, the drops and
the latency (a frame's arrival to its record written).

The camera's frames arrive on the driver's thread into a one-frame slot; the loop here takes
the newest, infers it with the run's engine and FrameWorker (the plain run's code), writes its
map and record, and feeds its map to the online tracker. The writing and tracking run on a
finisher thread, in the order the frames were taken, as soon as each result is in; with
helper processes (`--workers`; on the CPU three processes by default, default_workers) a
feeder thread hands each helper the newest frame the moment it is free, while the loop infers
its own. Stopping writes detections.csv, tracks.csv, track_table.csv and summary.json (with a
`live` block) as a plain run does.

Its pose left out (extrinsics: auto, one camera without background frames), the floor is
fitted on the camera's first frames before any is inferred (LiveRun.take_first).

A camera that stops sending (unplugged, or its stream stalled: no frame for STALL_S seconds)
ends the run with every output of the frames inferred so far written, then one line and exit
code 1; its SDK failing to stop (as an unplugged camera does) loses nothing either.
"""

from __future__ import annotations

import os
import statistics
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED
from concurrent.futures import wait as wait_futures
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .io import WorkerError, units_to_metres
from .sources import NewestFrame

STALL_S = 5.0  # seconds without a frame after which a streaming camera has stopped sending
# processes of a live run on the CPU without --workers: one infers the demo's frame in ~40 to
# 60 ms on a 2-core VM, so a 30 fps stream needs both cores, and a third process gives each
# frame two intervals more, so that one the machine slows does not make the next wait
# (README, live block: 29.6 against 28.5 frames/s with two, 2 % dropped against 5 %)
LIVE_WORKERS = 3


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def steady_rate(done: int, first_arrival: float | None, latencies: list, finished: list) -> float | None:
    """Frames written a second once running: done - 1 over the time from the first frame's
    arrival plus the median latency to the last frame's record; None under two frames."""
    if done < 2 or first_arrival is None:
        return None
    span = finished[-1] - (first_arrival + statistics.median(latencies))
    return (done - 1) / span if span > 0 else None


def default_workers(cfg: RunConfig, device: str) -> int:
    """A live run's processes without --workers: on the CPU LIVE_WORKERS where there are two
    CPUs or more, one where there is one; one with warm starts (each frame starts from the one
    before: frames in order in one process) and on a GPU (a frame takes milliseconds there)."""
    if not str(device).startswith("cpu") or cfg.model.warm_start or usable_cpus() < 2:
        return 1
    return LIVE_WORKERS


def stop_threads(thread: threading.Thread | None, stop: threading.Event) -> None:
    """Set `stop` and wait for `thread` (the live run's feeder), if it was started."""
    stop.set()
    if thread is not None and thread.is_alive():
        thread.join()


def run_live(cfg: RunConfig, output_dir: str | None = None, device: str | None = None, log=print,
             max_frames: int | None = None, overwrite: bool = False, first_frame_timeout: float = 10.0,
             workers: int | None = None) -> dict:
    """Infer a live camera's frames until Ctrl-C or `max_frames`; returns the summary. With
    `workers` > 1, workers - 1 helper processes infer beside this one (Helpers); frames are
    written and tracked in the order they were taken. None: default_workers."""
    check_live(cfg, workers)
    return LiveRun(cfg, output_dir, device, log, max_frames, overwrite, first_frame_timeout, workers).run()


def check_live(cfg: RunConfig, workers: int | None) -> None:
    """What a live run cannot do, said before the camera starts (played frames are known
    before: auto background and pose are fitted on them as in a plain run); a rig's, of each
    camera."""
    for c, (_, m) in enumerate(cfg.members()):
        at = f"cameras[{c}]." if cfg.is_rig else ""
        if m.inputs.auto_background and not m.inputs.play:
            raise ConfigError(f"{at}input.background: auto estimates the background from the run's frames; a live "
                              f"run has none in advance; expected background frames or null")
        if m.pose_auto and not m.inputs.play and cfg.is_rig:  # one camera's floor: its first frames (LiveRun)
            raise ConfigError(f"{at}camera.extrinsics: auto: a live rig's cameras are placed in one world by "
                              f"`dpom-warp calibrate` on recordings of them; expected each camera's pose "
                              f"({{T_world_from_camera: ...}}, as calibrate writes it)")
    if workers is not None and workers > 1 and cfg.model.warm_start:
        raise ConfigError("model.warm_start: each frame starts from the previous one, so frames "
                          "must run in order in one process; expected no --workers with it")


class Pending:
    """A frame taken from the camera, until it is written: its depth (metres) and what the
    engines take (`small`), then its result, the future of a helper inferring it (None: here
    or done), the inference's seconds and the process that inferred it."""

    __slots__ = ("frame", "depth", "small", "result", "future", "infer_s", "process")

    def __init__(self, frame, depth, small, future=None, process=None):
        self.frame, self.depth, self.small, self.future, self.process = frame, depth, small, future, process
        self.result, self.infer_s = None, None


class LiveRun:
    """One live run: the camera's newest frame inferred by this process (the main loop, `run`)
    or by a helper (the feeder thread, `feed`), the frames written and tracked in the order
    they were taken by the finisher thread (`finish`), the outputs of a plain run written at
    the end (`summary`)."""

    def __init__(self, cfg: RunConfig, output_dir, device, log, max_frames, overwrite, first_frame_timeout,
                 workers):
        from .loop import open_loop
        from .session import set_up_on_first_frames
        from .sources import open_source
        from .frames import played_source
        from .worker import FrameWorker
        from .writers import Rerun

        self.cfg, self.log, self.max_frames, self.first_frame_timeout = cfg, log, max_frames, first_frame_timeout
        self.t_start = time.perf_counter()
        self.rig = cfg.is_rig
        if cfg.inputs.play:  # the plain run's frames, sent at their own rate
            self.source, played = played_source(cfg, log, max_frames)
        elif self.rig:  # every camera's frames paired with the first's as they arrive
            from .sources.rig import RigStream

            self.source = RigStream([open_source(m.inputs.frames, key=f"cameras[{c}].input.frames")
                                     for c, (_, m) in enumerate(cfg.cameras)], cfg.camera_names,
                                    cfg.rig.tolerance)
            played = []
        else:
            self.source, played = open_source(cfg.inputs.frames), []  # a live kind of names.READERS
        self.info = info = self.source.stream_info()  # the accelerometer was read with the config
        self.out = Path(output_dir or cfg.output.dir)
        self.slot, self.started, self.first = NewestFrame(), False, []
        # the plain run's: device, engine, background (played frames: auto and the floor fit as a
        # plain run's; a live camera's pose left out: the floor in its first frames)
        try:
            if cfg.pose_auto and not (cfg.inputs.play or cfg.inputs.background):
                self.take_first(cfg)
            cfg, self.setup = set_up_on_first_frames(cfg, self.first, f"{cfg.inputs.frames}'s first {{n}} frames",
                                                     played, device, log)
        except BaseException:
            self.stop_early()
            raise
        self.cfg, setup = cfg, self.setup
        self.engine, self.geometry = setup.engine, setup.geometry
        self.workers = workers or default_workers(cfg, setup.device)
        self.worker = FrameWorker(setup.spec, engine=self.engine)
        self.tracking_on = cfg.tracking.method != "off"
        if cfg.tracking.method == "ksp":
            log("tracking.method ksp needs the whole run; a live run tracks online")
        self.fps = info.rate_hz or cfg.inputs.fps
        # the plain run's writers; with tracks, a frame's picture and its tracks on the view wait for
        # the online tracker to commit it (tracking.delay frames later)
        self.frame_loop = open_loop(cfg, self.out, self.geometry, setup.spec.camera, overwrite=overwrite,
                                    resume=False, worker_pictures=not self.tracking_on,
                                    online_fps=self.fps if self.tracking_on else None, log=log)
        self.run_view, self.writers, self.online = self.frame_loop.view, self.frame_loop.writers, self.frame_loop.online
        self.rerun = self.writers.has(Rerun)
        self.structure_frames = 0  # a live camera's first frames, taken for the static planes
        self.latencies, self.infer_s = [], []
        self.finished = []  # when each frame was written
        self.done, self.taken, self.t_first, self.last_line = 0, 0, None, time.perf_counter()
        self.pending: deque = deque()  # Pending frames, in the order they were taken
        self.helpers = None  # started by run(), once the background is whole (start_helpers)
        # the frames are taken one taker at a time (the main loop, and the feeder thread that
        # hands the helpers theirs), each put in `pending` before the next is taken: stream order
        self.taking, self.state = threading.Lock(), threading.Condition()
        self.stop_feeding = threading.Event()
        # the finisher thread writes and tracks the frames in order, beside the inference; a
        # helper's death it finds is left to the main loop (`adopt`), the one thread that runs
        # this engine
        self.closing, self.broken, self.abandon = threading.Event(), threading.Event(), threading.Event()
        self.died: list = []  # the error a helper's death gave
        self.failure: list = []  # an error writing or tracking a frame: raised by the main loop
        self.feeder = self.finisher = None

    # -- taking frames ---------------------------------------------------------------------
    def reserve(self) -> bool:
        """A place for one more frame under --max-frames (released by `unreserve`)."""
        with self.state:
            if self.max_frames is not None and self.taken >= self.max_frames:
                return False
            self.taken += 1
            return True

    def unreserve(self) -> None:
        with self.state:
            self.taken -= 1

    def take(self, timeout: float, then):
        """The newest frame (None after `timeout`), with `then(frame, depth, small)` (its item
        in `pending`) done before any other frame is taken."""
        with self.taking:
            fr = self.slot.take(timeout)
            if fr is None:
                return None
            depth = self.metres(fr)
            # what the engines take: on a GPU the frame itself (the engine reduces it there)
            reduce = self.engine.resolution.frames
            small = (depth if self.engine.reduce_on_device else
                     [reduce(d) if d is not None else None for d in depth] if self.rig else reduce(depth))
            return then(fr, depth, small)

    def take_first(self, cfg: RunConfig) -> None:
        """extrinsics: auto on a live camera without background frames: the camera started and
        its first frames taken for the floor fit (camera.ground.frames) and the static planes
        (input.structure.frames), none of them inferred."""
        from .session import planes_from_frames

        self.source.start(self.slot.put)
        self.started = True
        self.first = self.first_frames(max(cfg.ground_frames, cfg.inputs.structure.frames * planes_from_frames(cfg)))

    def stop_early(self) -> None:
        """The camera stopped when the run fails before its loop (started for the floor fit)."""
        if self.started:
            self.started = False
            self.source.stop()

    def first_frames(self, n: int) -> list:
        """The camera's next `n` frames in metres (fewer if the stream ends or stalls), not inferred."""
        frames = self.slot.take_next(n, self.first_frame_timeout, STALL_S)
        if not frames:
            raise self.no_first_frame()
        return [self.metres(fr) for fr in frames]

    def metres(self, fr):
        """A frame's depth in metres (a rig's: one a camera, None where it has none)."""
        if not self.rig:
            return units_to_metres(fr.depth, self.cfg.inputs.depth_scale)
        return [units_to_metres(d, m.inputs.depth_scale) if d is not None else None
                for d, (_, m) in zip(fr.depth, self.cfg.cameras)]

    def mine(self, fr, depth, small) -> Pending:
        item = Pending(fr, depth, small, process=self.worker.name)
        with self.state:
            self.pending.append(item)
        return item

    # -- the helpers -------------------------------------------------------------------------
    def feed(self) -> None:
        """While the main loop infers, hand each helper that is free the newest frame."""
        while not (self.stop_feeding.is_set() or self.broken.is_set()):
            with self.state:
                h = self.helpers
            if h is None:
                return
            busy = h.busy()
            if len(busy) >= h.n:
                wait_futures(busy, timeout=0.05, return_when=FIRST_COMPLETED)
                continue
            if not self.reserve():
                return
            got = self.take(0.05, self.submit)
            if got is None:
                self.unreserve()
            elif got.future.done() and got.future.exception() is not None:
                return  # the helpers are gone: this frame is the main loop's to infer (adopt)

    def submit(self, fr, depth, small) -> Pending:
        from .worker import failed_future

        with self.state:  # a helper that died meanwhile: a future holding the pool's error
            fut = (self.helpers.submit(small) if self.helpers is not None
                   else failed_future(BrokenProcessPool("the helper processes are gone")))
            item = Pending(fr, depth, small, future=fut)
            self.pending.append(item)
        fut.add_done_callback(lambda _: self.notify())
        return item

    def notify(self) -> None:
        with self.state:
            self.state.notify_all()

    def infer_here(self, item: Pending) -> None:
        """Infer a pending frame with this process's engine (main loop only: the engine is not
        shared between threads) and hand its result to the finisher."""
        t0 = time.perf_counter()
        res = self.worker.infer(item.small)  # a rig's frame missing a camera: the others' engine
        with self.state:
            item.result, item.future, item.infer_s, item.process = res, None, time.perf_counter() - t0, self.worker.name
            self.state.notify_all()

    def adopt(self) -> None:
        """After a helper's death: every frame the helpers held is inferred here, and the run
        goes on without them (main loop only: this engine is not shared between threads)."""
        self.broken.clear()
        with self.state:
            h, self.helpers = self.helpers, None
            held = [other for other in self.pending if other.future is not None]
        if h is not None:
            e = self.died[0] if self.died else None
            self.log(f"live: a helper process died ({e or 'no reason given'}); its frames are inferred here, "
                     f"the run goes on in one process")
            h.close()
        for other in held:
            self.infer_here(other)

    # -- writing and tracking, in order (the finisher thread) ---------------------------------
    def next_ready(self) -> Pending | None:
        """The first pending frame once its result is in (None: closing and nothing left)."""
        with self.state:
            while not self.abandon.is_set():
                item = self.pending[0] if self.pending else None
                if item is None:
                    if self.closing.is_set():
                        return None
                elif item.future is None and item.result is not None:
                    return self.pending.popleft()
                elif item.future is not None and item.future.done():
                    try:
                        item.result, item.infer_s, item.process = item.future.result()
                        item.future = None
                        continue
                    except BrokenProcessPool as e:
                        self.died.append(e)
                        self.broken.set()  # the main loop adopts its frames
                self.state.wait(0.05)
            return None  # the run failed: the frames after stay unwritten

    def finishing(self) -> None:
        try:
            while (item := self.next_ready()) is not None:
                self.finish(item)
        except BaseException as e:  # raised by the main loop; the frames after it stay unwritten
            self.failure.append(e)

    def finish(self, item: Pending) -> None:
        """A frame's map, record and picture written, shown and tracked (FrameLoop: as a plain
        run's)."""
        from .worker import FrameItem

        cfg, fr, res = self.cfg, item.frame, item.result
        due = cfg.output.images and self.done % cfg.output.images_every == 0
        self.worker.pictures = due and not self.tracking_on  # with tracks: drawn once committed (OnlineTracks)
        paths = tuple(p.output_name if p is not None else None for p in fr.parts) if self.rig else None
        _, output, _ = self.worker._finish(FrameItem(fr.output_name, paths=paths), item.depth, res,
                                           0.0, item.infer_s, [])
        output.record["stats"]["worker"] = item.process
        if self.rig:  # when each camera's frame arrived, against the first camera's (the pairing)
            output.record["stats"]["arrived_ms"] = {n: 1000 * (p.arrived - fr.arrived) if p is not None else None
                                                    for (n, _), p in zip(cfg.cameras, fr.parts)}
        self.frame_loop.accept(output.name, output, None, fr.timestamp, depth=item.depth if due or self.rerun else None,
                         result_dets=self.worker.detections(res)[1] if self.rerun else None)
        self.finished.append(time.perf_counter())
        self.latencies.append(self.finished[-1] - fr.arrived)
        self.infer_s.append(item.infer_s)
        self.done += 1

    def close_finisher(self) -> None:
        """Every frame taken written and tracked (the helpers' dead ones inferred here first),
        then the finisher gone; its error, if it had one, raised here."""
        self.closing.set()
        self.notify()
        while self.finisher.is_alive():
            if self.broken.is_set():
                self.adopt()
            self.finisher.join(0.05)
        if self.failure:
            raise self.failure[0]

    # -- the main loop -----------------------------------------------------------------------
    def run(self) -> dict:
        """Until Ctrl-C, --max-frames or the camera stopping; then the run's outputs."""
        from .session import planes_from_frames

        # floor-only on a live camera (of a rig: any): the static planes come from its first frames
        planes_first = not self.cfg.inputs.play and any(planes_from_frames(m) for _, m in self.cfg.members())
        if not planes_first:
            self.start_helpers()  # before the camera: no frame is dropped while they start
        if not self.started:
            self.source.start(self.slot.put)
        self.finisher = threading.Thread(target=self.finishing, daemon=True)
        self.finisher.start()
        stopped_by, stop_error, clean = "max_frames", None, False
        try:
            if planes_first:  # the helpers take the background with the planes
                self.find_structure()
                self.start_helpers()
            self.feeder = threading.Thread(target=self.feed, daemon=True) if self.helpers is not None else None
            self.announce()
            stopped_by = self.loop()
            stop_threads(self.feeder, self.stop_feeding)
            self.close_finisher()
            clean = True
        except KeyboardInterrupt:
            stopped_by = "Ctrl-C"
            stop_threads(self.feeder, self.stop_feeding)
            for item in list(self.pending):  # one being inferred here when Ctrl-C came: again
                if item.result is None and item.future is None:
                    self.infer_here(item)
            self.close_finisher()  # the frames taken are inferred and written: nothing is lost
            clean = True
        finally:
            stop_error = self.stop(clean)
        return self.summary(stopped_by, stop_error)

    def find_structure(self) -> None:
        """A live camera's floor-only run: the static planes (input.structure) found in the
        camera's first input.structure.frames frames, as a recorded run finds them in its first
        files (a played run's set_up did); those frames are not inferred (summary.json's
        live.structure_frames)."""
        from .session import add_static_planes

        n = self.cfg.inputs.structure.frames
        frames = self.first[:n] if self.first else self.first_frames(n)  # the floor fit's, else the next
        self.structure_frames = len(frames)
        add_static_planes(self.setup, frames, self.log)

    def no_first_frame(self) -> ConfigError:
        return ConfigError(f"input.frames: {self.cfg.inputs.frames}: no frame within "
                           f"{self.first_frame_timeout:g} s of starting the camera")

    def start_helpers(self) -> None:
        """workers - 1 helper processes, each with an engine of this one's background."""
        from .worker import Helpers

        if self.workers > 1:
            try:
                self.helpers = Helpers(self.setup.spec, self.engine, self.workers - 1)
            except BrokenProcessPool as e:  # as one dying later: the run goes on in this process
                self.log(f"live: a helper process died starting ({e}); the run goes on in one process")

    def announce(self) -> None:
        info, cfg = self.info, self.cfg
        size = "" if self.rig else f", {info.width}x{info.height}"
        self.log(f"live: {info.kind}{size} at {self.fps:g} frames/s; device "
                 f"{self.setup.device}, {self.workers} process{'es' * (self.workers > 1)}; background: "
                 f"{self.setup.background}; until {'the frames end, ' if cfg.inputs.play else ''}Ctrl-C"
                 f"{f' or {self.max_frames} frames' if self.max_frames else ''}")

    def loop(self) -> str:
        """Take and infer the newest frame until --max-frames or the camera stops sending;
        returns what stopped it."""
        while self.reserve() or self.feeder_gives_back():
            first = self.t_first is None
            item = self.take(self.first_frame_timeout if first else STALL_S, self.mine)
            if item is None:
                self.unreserve()
                if self.slot.ended:
                    return "end of the frames"
                if first:
                    raise self.no_first_frame()
                return "camera stopped sending"
            self.t_first = self.t_first or item.frame.arrived
            if self.feeder is not None and first:
                self.feeder.start()  # the helpers' frames from now on, beside this loop's
            self.infer_here(item)
            if self.broken.is_set():
                self.adopt()
            if self.failure:
                raise self.failure[0]
            if self.latencies and time.perf_counter() - self.last_line >= 1.0:
                self.last_line = time.perf_counter()
                rate = self.done / max(1e-9, self.last_line - self.t_first)
                self.log(f"live: {self.done} frames, {rate:.1f} frames/s, {self.slot.dropped} dropped, latency "
                         f"{1000 * statistics.median(self.latencies[-30:]):.0f} ms")
        return "max_frames"

    def feeder_gives_back(self) -> bool:
        """At --max-frames: whether the feeder thread, stopped, gave back a place it held while
        waiting for a frame for the helpers (a slow camera's next frame is then this loop's; it
        ended runs a frame short), and this loop took it."""
        if self.feeder is None or not self.feeder.is_alive():
            return False
        stop_threads(self.feeder, self.stop_feeding)
        return self.reserve()

    def stop(self, clean: bool) -> str | None:
        """The threads, the camera and the helpers stopped, whichever way the run ends; the
        camera's error where it failed to stop (the frames are kept)."""
        stop_error = None
        stop_threads(self.feeder, self.stop_feeding)
        self.abandon.set()  # (the finisher is done here unless the run failed)
        self.notify()
        try:
            self.source.stop()
        except RuntimeError as e:  # an unplugged camera's SDK may fail to stop it: keep the frames
            stop_error = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            self.log(f"live: the camera did not stop cleanly ({stop_error})")
        if self.helpers is not None:
            self.helpers.close()
        if not clean:  # else the Rerun log is closed once the last frames' tracks are on it (summary)
            self.writers.close()
        return stop_error

    # -- the run's outputs -------------------------------------------------------------------
    def summary(self, stopped_by: str, stop_error: str | None) -> dict:
        """detections.csv, tracks.csv, track_table.csv and summary.json (with its `live` block),
        as a plain run writes them; a camera that stopped sending is then an error."""
        from .outputs import summarise
        from .writers import RunEnd

        cfg, setup, done = self.cfg, self.setup, self.done
        wall = time.perf_counter() - (self.t_first or time.perf_counter())
        names, records = self.frame_loop.names, self.frame_loop.records
        summary = summarise(cfg, [Path(n) for n in names], records, [], None, self.geometry,
                            setup.device, setup.background, setup.ground, [])
        summary["inference"] = setup.inference
        summary["tracking"], tracks = self.tracks()
        summary["live"] = self.live_block(stopped_by, stop_error, wall)
        summary["timings"]["total_s"] = time.perf_counter() - self.t_start
        times = [records[n].get("timestamp") for n in names]
        # detections.csv, the tracks' tables, the Rerun log closed, summary.json last
        self.writers.finish(RunEnd(names, records, tracks, self.fps, times, summary))
        if stopped_by == "camera stopped sending":
            raise WorkerError(f"input.frames: {cfg.inputs.frames}: the camera stopped sending (no frame for "
                              f"{STALL_S:g} s after {done} frames: unplugged?); expected frames until Ctrl-C"
                              f"{' or --max-frames' if self.max_frames else ''}; the {done} frames inferred are "
                              f"written to {self.out}")
        return summary

    def tracks(self) -> tuple[dict, list | None]:
        """The online tracker's last frames committed (to the writers); the summary's
        `tracking` block and the tracks (None: not tracked)."""
        from .tracking import frames_without_map

        names = self.frame_loop.names
        if not (self.tracking_on and names):
            return {"method": "off", "why": "tracking.method: off"}, None
        tracks, report = self.online.finish()  # the last tracking.delay frames to the writers
        times = [self.frame_loop.records[n].get("timestamp") for n in names]
        seconds = self.online.seconds
        report = {"method": "online", "tracks": len(tracks), "time_s": seconds,
                  "ms_per_frame": 1000 * seconds / len(names), "fps": self.fps, "fps_from": "camera", **report,
                  "frames_without_map": frames_without_map(times, 1.0 / self.fps)}
        return report, tracks

    def live_block(self, stopped_by: str, stop_error: str | None, wall: float) -> dict:
        """summary.json's `live` block: frames, drops, rates and latencies."""
        done, slot, latencies, infer_s = self.done, self.slot, self.latencies, self.infer_s
        return {"source": self.info.kind, "frames": done, "received": slot.received,
                "dropped": slot.dropped, "dropped_share": slot.dropped / max(1, slot.received),
                "frames_per_s": done / wall if wall > 0 else None,
                # the output rate once running: frames written from when the first's record
                # would be at the run's pace (its arrival plus the median latency: its own
                # record, late with the first solve's costs, would count the frames queued
                # behind it as a burst) to the last's record (the pipeline's start and the
                # run's shutdown left out) (t_first: the first frame taken, so the first
                # written: frames are written in the order taken)
                "frames_per_s_steady": steady_rate(done, self.t_first, latencies, self.finished),
                "processes": self.workers, "structure_frames": self.structure_frames, "floor_frames": len(self.first),
                "camera_fps": self.fps, "stopped_by": stopped_by, "stop_error": stop_error,
                "latency_ms_median": 1000 * statistics.median(latencies) if latencies else None,
                "latency_ms_p95": 1000 * float(np.percentile(latencies, 95)) if latencies else None,
                "infer_ms_median": 1000 * statistics.median(infer_s) if infer_s else None,
                **({"cameras": {n: {"received": r} for (n, _), r in zip(self.cfg.cameras, self.source.received)},
                    "tolerance_s": self.source.tolerance} if self.rig else {})}

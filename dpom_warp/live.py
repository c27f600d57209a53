"""A run on a live camera (`input.frames: realsense[:SERIAL]`): it goes on until Ctrl-C or
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

A camera that stops sending (unplugged, or its stream stalled: no frame for STALL_S seconds)
ends the run with every output of the frames inferred so far written, then one line and exit
code 1; its SDK failing to stop (as an unplugged camera does) loses nothing either.
"""

from __future__ import annotations

import dataclasses
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
from .io import WorkerError, units_to_metres, write_json_atomic

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


class NewestFrame:
    """A one-frame slot: `put` replaces what is there (counting the frame dropped), `take`
    waits for a frame and empties the slot."""

    def __init__(self):
        self.cond = threading.Condition()
        self.frame, self.received, self.dropped = None, 0, 0

    def put(self, frame) -> None:
        with self.cond:
            if self.frame is not None:
                self.dropped += 1
            self.frame = frame
            self.received += 1
            self.cond.notify()

    def take(self, timeout: float):
        with self.cond:
            if self.frame is None:
                self.cond.wait(timeout)
            frame, self.frame = self.frame, None
            return frame


def _helper_start(start_file: str) -> None:
    """A helper process of a live run: Ctrl-C is the main process's to handle; the engine is
    built from the run's spec with the kernels the main process compiled."""
    import signal

    from .worker import _pool_start

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _pool_start(start_file)


def _helper_infer(small: np.ndarray):
    """(result, inference seconds, the process's name) of one frame at the engine's resolution."""
    from .worker import _pool_worker

    worker = _pool_worker[0]
    t = time.perf_counter()
    res = worker.engine.infer(small)
    return res, time.perf_counter() - t, worker.name


class Helpers:
    """`n` processes, each with its own engine, inferring the frames the main process's
    feeder thread hands them while its loop infers others (Warp runs a CPU launch on one
    thread: this is how a live run uses more cores). If one dies, its frames are inferred by
    the main process and the run goes on without helpers."""

    def __init__(self, spec, engine, n: int):
        from .worker import helper_pool

        spec = dataclasses.replace(spec, background=engine.background_state())
        engine.infer_batch(np.zeros((1, engine.height, engine.width), np.float32))  # every kernel compiled
        self.n, self.running = n, []
        self.pool, self.start_file = helper_pool(spec, n, _helper_start)
        try:
            warm = [self.pool.submit(_helper_infer, np.zeros((engine.height, engine.width), np.float32))
                    for _ in range(n)]
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
        from .worker import failed_future

        try:
            fut = self.pool.submit(_helper_infer, small)
        except BrokenProcessPool as e:
            fut = failed_future(e)
        self.running.append(fut)
        return fut

    def close(self):
        from .worker import remove_start_file

        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None
            remove_start_file(self.start_file)


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
    from .detect import detect_map
    from .io import write_bytes_atomic
    from .outputs import ShownTracks, _jsonable, prepare_output, summarise, track_table_files, tracked_picture
    from .session import set_up
    from .sources.realsense import RealSenseLive
    from .tracking import Cells, OnlineTracker, frames_without_map
    from .worker import FrameItem, FrameWorker, failed_future, write_output

    if cfg.inputs.auto_background:
        raise ConfigError("input.background: auto estimates the background from the run's frames; a live "
                          "run has none in advance; expected background frames or null")
    if cfg.pose_auto:
        raise ConfigError("camera.extrinsics: auto fits the floor on frames read before the run; expected "
                          "the live camera's pose ({height, pitch_deg, ...}; `dpom-warp fit-ground` on a "
                          "few saved frames gives it)")
    if workers is not None and workers > 1 and cfg.model.warm_start:
        raise ConfigError("model.warm_start: each frame starts from the previous one, so frames "
                          "must run in order in one process; expected no --workers with it")
    t_start = time.perf_counter()
    source = RealSenseLive(cfg.inputs.frames)
    info = source.info()
    out = Path(output_dir or cfg.output.dir)
    setup = set_up(cfg, [], device, log)  # the plain run's setup: device, engine, background frames
    dev, camera, engine, background = setup.device, setup.spec.camera, setup.engine, setup.background
    workers = workers or default_workers(cfg, dev)
    worker = FrameWorker(setup.spec, engine=engine)
    geometry = setup.geometry
    cells = Cells.for_run(geometry, cfg)
    method = cfg.tracking.method
    tracking_on = method != "off"
    if method == "ksp":
        log("tracking.method ksp needs the whole run; a live run tracks online")
    fps = info.rate_hz or cfg.inputs.fps
    tracker = OnlineTracker(cells, cfg.grid.shape, cfg.tracking, 1.0 / fps, cfg.detection.threshold)
    prepare_output(out, cfg.resolved, overwrite, resume=False)
    log(f"live: {info.kind}, {info.width}x{info.height} at {fps:g} frames/s; device {dev}, "
        f"{workers} process{'es' * (workers > 1)}; background: "
        f"{background}; until Ctrl-C{f' or {max_frames} frames' if max_frames else ''}")
    from .outputs import VIEW

    view = None
    if cfg.output.rerun or VIEW:
        from .view import RerunLog

        view = RerunLog(cfg.output.rerun, spawn=bool(VIEW))
        view.camera(camera)
    slot = NewestFrame()
    records, names, latencies, infer_s, finished = {}, [], [], [], []  # finished: when each was written
    # with tracks, a frame's picture and its tracks on the view wait for the online tracker to
    # commit it (tracking.delay frames later): frame index -> (name, timestamp, map as saved,
    # depth where a picture is due)
    trails, awaiting = ShownTracks(geometry, cfg.tracking.trail), {}
    done, taken, t_first, last_line, track_s = 0, 0, None, time.perf_counter(), 0.0
    # [frame, depth, small, FrameResult, future or None (being inferred here), inference s,
    # process], in the order the frames were taken
    pending: deque = deque()
    helpers = None
    if workers > 1:
        try:
            helpers = Helpers(setup.spec, engine, workers - 1)
        except BrokenProcessPool as e:  # as one dying later: the run goes on in this process
            log(f"live: a helper process died starting ({e}); the run goes on in one process")
    # the frames are taken one taker at a time (this loop, and the feeder thread that hands
    # the helpers theirs), each put in `pending` before the next is taken: stream order
    taking, state = threading.Lock(), threading.Condition()
    stop_feeding = threading.Event()
    # a finisher thread writes and tracks the frames in order, beside the inference; a helper's
    # death it finds is left to the main loop (`adopt`), the one thread that runs this engine
    closing, broken, abandon = threading.Event(), threading.Event(), threading.Event()
    died: list = []  # the error a helper's death gave
    failure: list = []  # an error writing or tracking a frame: raised by the main loop

    def reserve() -> bool:
        """A place for one more frame under --max-frames (released by `unreserve`)."""
        nonlocal taken
        with state:
            if max_frames is not None and taken >= max_frames:
                return False
            taken += 1
            return True

    def unreserve():
        nonlocal taken
        with state:
            taken -= 1

    def take(timeout: float, then):
        """The newest frame (None after `timeout`), with `then(frame, depth, small)` (its item
        in `pending`) done before any other frame is taken."""
        with taking:
            fr = slot.take(timeout)
            if fr is None:
                return None
            depth = units_to_metres(fr.depth, cfg.inputs.depth_scale)
            # what the engines take: on a GPU the frame itself (the engine reduces it there)
            small = depth if engine.reduce_on_device else engine.resolution.frames(depth)
            return then(fr, depth, small)

    def feed():
        """While the main loop infers, hand each helper that is free the newest frame."""
        while not (stop_feeding.is_set() or broken.is_set()):
            with state:
                h = helpers
            if h is None:
                return
            busy = h.busy()
            if len(busy) >= h.n:
                wait_futures(busy, timeout=0.05, return_when=FIRST_COMPLETED)
                continue
            if not reserve():
                return
            got = take(0.05, lambda fr, depth, small: submit(fr, depth, small))
            if got is None:
                unreserve()
            elif got[4].done() and got[4].exception() is not None:
                return  # the helpers are gone: this frame is the main loop's to infer (adopt)

    def submit(fr, depth, small):
        with state:  # a helper that died meanwhile: a future holding the pool's error
            fut = (helpers.submit(small) if helpers is not None
                   else failed_future(BrokenProcessPool("the helper processes are gone")))
            item = [fr, depth, small, None, fut, None, None]
            pending.append(item)
        fut.add_done_callback(lambda _: notify())
        return item

    def notify():
        with state:
            state.notify_all()

    def infer_here(item):
        """Infer a pending item with this process's engine (main loop only: the engine is not
        shared between threads) and hand its result to the finisher."""
        t0 = time.perf_counter()
        res = engine.infer(item[2])
        with state:
            item[3], item[4], item[5], item[6] = res, None, time.perf_counter() - t0, worker.name
            state.notify_all()

    def adopt():
        """After a helper's death: every frame the helpers held is inferred here, and the run
        goes on without them (main loop only: this engine is not shared between threads)."""
        nonlocal helpers
        broken.clear()
        with state:
            h, helpers = helpers, None
            held = [other for other in pending if other[4] is not None]
        if h is not None:
            e = died[0] if died else None
            log(f"live: a helper process died ({e or 'no reason given'}); its frames are inferred here, "
                f"the run goes on in one process")
            h.close()
        for other in held:
            infer_here(other)

    def next_ready():
        """The first pending item once its result is in (None: closing and nothing left)."""
        with state:
            while not abandon.is_set():
                item = pending[0] if pending else None
                if item is None:
                    if closing.is_set():
                        return None
                elif item[4] is None and item[3] is not None:
                    return pending.popleft()
                elif item[4] is not None and item[4].done():
                    try:
                        item[3], item[5], item[6] = item[4].result()
                        item[4] = None
                        continue
                    except BrokenProcessPool as e:
                        died.append(e)
                        broken.set()  # the main loop adopts its frames
                state.wait(0.05)
            return None  # the run failed: the frames after stay unwritten

    def finishing():
        try:
            while (item := next_ready()) is not None:
                finish(item)
        except BaseException as e:  # raised by the main loop; the frames after it stay unwritten
            failure.append(e)

    def finish(item):
        nonlocal done, track_s
        fr, depth, _, res, _, infer, process = item
        due = cfg.output.images and done % cfg.output.images_every == 0
        worker.pictures = due and not tracking_on  # with tracks: drawn once committed (publish)
        name = f"{fr.index:06d}"
        _, output, _ = worker._finish(FrameItem(name), depth, res, 0.0, infer, [])
        output.record["timestamp"] = output.record["stats"]["timestamp"] = fr.timestamp
        output.record["stats"]["worker"] = process
        records[name] = write_output(out, output)
        names.append(name)
        if view is not None:
            rho_map, dets = worker.detections(res)
            view.frame(done, fr.timestamp, depth, dets, rho_map)
        if tracking_on and (view is not None or due):
            awaiting[done] = (name, fr.timestamp, output.map, depth if due else None)
        if tracking_on:
            t1 = time.perf_counter()
            tracker.push(output.map, fr.timestamp)  # frames dropped between: reach by the time apart
            track_s += time.perf_counter() - t1
            publish(tracker.take_committed())
        finished.append(time.perf_counter())
        latencies.append(finished[-1] - fr.arrived)
        infer_s.append(infer)
        done += 1

    def publish(committed):
        """Frames the online tracker has committed: their tracks (identities as in tracks.csv)
        on the view and, where a picture is due, the picture with the tracks and trails."""
        for f, rows in committed:
            shown = trails.at(f, rows)
            got = awaiting.pop(f, None)
            if got is None:
                continue
            name, stamp, saved, depth = got
            # as a finished run draws them (frames_out): from the map as maps/ holds it
            rho_map = saved.reshape(cfg.grid.shape)
            dets = detect_map(rho_map, geometry, cfg.detection)
            if view is not None:
                view.tracks(f, stamp, dets, shown)
            if depth is not None:
                write_bytes_atomic(out / "images" / f"{name}.png",
                                   tracked_picture(cfg, geometry, depth, rho_map, dets, name, None, shown))

    def mine(fr, depth, small):
        item = [fr, depth, small, None, None, None, worker.name]
        with state:
            pending.append(item)
        return item

    def close_finisher():
        """Every frame taken written and tracked (the helpers' dead ones inferred here first),
        then the finisher gone; its error, if it had one, raised here."""
        closing.set()
        notify()
        while finisher.is_alive():
            if broken.is_set():
                adopt()
            finisher.join(0.05)
        if failure:
            raise failure[0]

    source.start(slot.put)
    feeder = threading.Thread(target=feed, daemon=True) if helpers is not None else None
    finisher = threading.Thread(target=finishing, daemon=True)
    finisher.start()
    stopped_by, stop_error, clean = "max_frames", None, False
    try:
        while reserve():
            first = t_first is None
            item = take(first_frame_timeout if first else STALL_S, mine)
            if item is None:
                unreserve()
                if first:
                    raise ConfigError(f"input.frames: {cfg.inputs.frames}: no frame within "
                                      f"{first_frame_timeout:g} s of starting the camera")
                stopped_by = "camera stopped sending"
                break
            t_first = t_first or item[0].arrived
            if feeder is not None and first:
                feeder.start()  # the helpers' frames from now on, beside this loop's
            infer_here(item)
            if broken.is_set():
                adopt()
            if failure:
                raise failure[0]
            if latencies and time.perf_counter() - last_line >= 1.0:
                last_line = time.perf_counter()
                rate = done / max(1e-9, last_line - t_first)
                log(f"live: {done} frames, {rate:.1f} frames/s, {slot.dropped} dropped, latency "
                    f"{1000 * statistics.median(latencies[-30:]):.0f} ms")
        stop_threads(feeder, stop_feeding)
        close_finisher()
        clean = True
    except KeyboardInterrupt:
        stopped_by = "Ctrl-C"
        stop_threads(feeder, stop_feeding)
        for item in list(pending):  # one being inferred here when Ctrl-C came: again
            if item[3] is None and item[4] is None:
                infer_here(item)
        close_finisher()  # the frames taken are inferred and written: nothing is lost
        clean = True
    finally:
        stop_threads(feeder, stop_feeding)
        abandon.set()  # (the finisher is done here unless the run failed)
        notify()
        try:
            source.stop()
        except RuntimeError as e:  # an unplugged camera's SDK may fail to stop it: keep the frames
            stop_error = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            log(f"live: the camera did not stop cleanly ({stop_error})")
        if helpers is not None:
            helpers.close()
        if view is not None and not clean:  # else closed once the last frames' tracks are on it
            view.close()
    wall = time.perf_counter() - (t_first or time.perf_counter())
    done_paths = [Path(n) for n in names]
    summary = summarise(cfg, out, done_paths, records, [], None, geometry, dev, background, None, [])
    if tracking_on and names:
        t1 = time.perf_counter()
        tracks, report = tracker.finish()
        track_s += time.perf_counter() - t1
        publish(tracker.take_committed())  # the last tracking.delay frames
        times = [records[n].get("timestamp") for n in names]
        report = {"method": "online", "tracks": len(tracks), "time_s": track_s,
                  "ms_per_frame": 1000 * track_s / len(names), "fps": fps, "fps_from": "camera", **report,
                  "frames_without_map": frames_without_map(times, 1.0 / fps)}
        track_table_files(out, tracks, names, fps, times)
    else:
        report = {"method": "off", "why": "tracking.method: off"}
    if view is not None:
        view.close()
    summary["tracking"] = report
    summary["live"] = {"source": info.kind, "frames": done, "received": slot.received,
                       "dropped": slot.dropped, "dropped_share": slot.dropped / max(1, slot.received),
                       "frames_per_s": done / wall if wall > 0 else None,
                       # the output rate once running: frames written from when the first's
                       # record would be at the run's pace (its arrival plus the median latency:
                       # its own record, late with the first solve's costs, would count the
                       # frames queued behind it as a burst) to the last's record (the
                       # pipeline's start and the run's shutdown left out)
                       # (t_first: the first frame taken, so the first written: frames are
                       # written in the order taken)
                       "frames_per_s_steady": steady_rate(done, t_first, latencies, finished),
                       "processes": workers,
                       "camera_fps": fps, "stopped_by": stopped_by, "stop_error": stop_error,
                       "latency_ms_median": 1000 * statistics.median(latencies) if latencies else None,
                       "latency_ms_p95": 1000 * float(np.percentile(latencies, 95)) if latencies else None,
                       "infer_ms_median": 1000 * statistics.median(infer_s) if infer_s else None}
    summary["timings"]["total_s"] = time.perf_counter() - t_start
    write_json_atomic(out / "summary.json", _jsonable(summary))
    if stopped_by == "camera stopped sending":
        raise WorkerError(f"input.frames: {cfg.inputs.frames}: the camera stopped sending (no frame for "
                          f"{STALL_S:g} s after {done} frames: unplugged?); expected frames until Ctrl-C"
                          f"{' or --max-frames' if max_frames else ''}; the {done} frames inferred are "
                          f"written to {out}")
    return summary

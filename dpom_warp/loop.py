"""The body of every run's frame loop: what happens to a frame once inferred, whichever executor
inferred it (this process, `--workers` processes, Ray actors, a live run's main loop or
helpers). Executors hand frames in frame order as (name, FrameOutput, None), or (name, None,
reason) for a frame that could not be inferred; FrameLoop stamps each with its timestamp, has
the run's writers write it, keeps its record, and in a live run tracks it online and hands the
frames the tracker commits to the writers with their tracks."""

from __future__ import annotations

import time
from collections import Counter

from pathlib import Path

from .config import RunConfig
from .geometry import Camera, Geometry
from .io import InputError
from .outputs import ShownTracks, prepare_output
from .worker import FrameOutput
from .writers import FrameDone, RunView, Writers, writers_for


class OnlineTracks:
    """A live run's tracks as frames come: each frame's map pushed to the online tracker, and
    each frame it commits (tracking.delay frames later, with its final identities) handed to
    the writers with its tracks and trails (ShownTracks)."""

    def __init__(self, view: RunView, writers: Writers, tracker):
        from .heads import Placer

        self.writers, self.tracker = writers, tracker
        self.trails = ShownTracks(view.geometry, view.cfg.tracking.trail)
        self.awaiting: dict[int, FrameDone] = {}  # frames pushed, not yet committed
        self.seconds = 0.0  # the tracker's time
        self.placer = Placer.of(view.cfg)  # each frame's detections and heads (None: tracks at the cells)

    @classmethod
    def for_run(cls, view: RunView, writers: Writers, fps: float) -> OnlineTracks:
        """The run's online tracker (its cells, grid and tracking section) at `fps` frames a second."""
        from .tracking import Cells, OnlineTracker

        cfg = view.cfg
        return cls(view, writers, OnlineTracker(Cells.for_run(view.geometry, cfg), cfg.grid.shape, cfg.tracking,
                                                1.0 / fps, cfg.detection.threshold))

    def push(self, done: FrameDone) -> None:
        from .heads import found_in

        self.awaiting[done.index] = done
        if self.placer is not None:
            self.placer.add(found_in(done.record))
        t = time.perf_counter()
        self.tracker.push(done.map, done.timestamp)  # frames dropped between: reach by the time apart
        self.seconds += time.perf_counter() - t
        self.publish(self.tracker.take_committed())

    def publish(self, committed) -> None:
        for f, rows in committed:
            if self.placer is not None:
                rows = self.placer.rows(f, rows)
            shown = self.trails.at(f, rows)
            done = self.awaiting.pop(f, None)
            if done is not None:
                self.writers.tracked(done, shown)

    def finish(self) -> tuple[list, dict]:
        """Every frame committed (the last tracking.delay ones handed to the writers); returns
        (tracks, the tracker's report)."""
        t = time.perf_counter()
        tracks, report = self.tracker.finish()
        self.seconds += time.perf_counter() - t
        self.publish(self.tracker.take_committed())
        if self.placer is not None:
            self.placer.tracks(tracks)
        return tracks, report


class FrameLoop:
    """A run's frames as they come, in frame order: written (`write`, on any one thread at a
    time, in order) and kept (`keep`, in order: the record, list growths, who inferred it,
    the online tracks), or skipped with their reason (fatal with `strict`). `accept` does all
    of a frame's steps at once. `timestamps`: a recording's, by frame name; `online`: a live
    run's OnlineTracks. The records, skipped frames, growths and counts per worker are kept
    in the mappings given (a run's plan holds them)."""

    def __init__(self, view: RunView, writers: Writers, records: dict | None = None, skipped: list | None = None,
                 grown: list | None = None, by_worker: Counter | None = None, timestamps: dict | None = None,
                 online: OnlineTracks | None = None, strict: bool = False, log=print):
        self.view, self.writers, self.timestamps, self.online = view, writers, timestamps or {}, online
        self.records = records if records is not None else {}
        self.skipped = skipped if skipped is not None else []
        self.grown = grown if grown is not None else []
        self.by_worker = by_worker if by_worker is not None else Counter()
        self.names: list[str] = []  # the frames kept by this loop, in order
        self.strict, self.log = strict, log

    def done(self, name: str, output: FrameOutput, timestamp: float | None = None, depth=None,
             result_dets=None) -> FrameDone:
        """A frame's FrameDone, its record stamped with its timestamp (a recording's, or the
        camera's `timestamp`); `depth` and `result_dets` where the executor has them."""
        stamp = self.timestamps.get(name, timestamp)
        if stamp is not None or name in self.timestamps:
            output.record["timestamp"] = output.record["stats"]["timestamp"] = stamp
        return FrameDone(self.view, len(self.names), name, output.stem, output.record.get("timestamp"),
                         output.map, output.record, output.files, result_dets=result_dets, depth=depth)

    def write(self, done: FrameDone) -> dict:
        return self.writers.frame(done)

    def keep(self, name: str, output: FrameOutput, done: FrameDone, record: dict) -> None:
        self.records[name] = record
        self.names.append(name)
        self.grown += output.grown
        self.by_worker[output.record["stats"]["worker"]] += 1
        if self.online is not None:
            self.online.push(done)

    def skip(self, name: str, error: str) -> None:
        if self.strict:
            raise InputError(error)
        self.skipped.append({"frame": name, "reason": error})
        self.log(f"skipping {error}")

    def accept(self, name: str, output: FrameOutput | None, error: str | None, timestamp: float | None = None,
               depth=None, result_dets=None) -> FrameDone | None:
        """A frame's every step, here and now; returns its FrameDone (None: skipped)."""
        if error is not None:
            self.skip(name, error)
            return None
        done = self.done(name, output, timestamp, depth, result_dets)
        self.keep(name, output, done, self.write(done))
        return done


def open_loop(cfg: RunConfig, out: Path, geometry: Geometry, camera: Camera, *, overwrite: bool, resume: bool,
              worker_pictures: bool, online_fps: float | None = None, log=print, **kept) -> FrameLoop:
    """Every run's frame loop opened, whichever executor feeds it (a recorded run's, a live
    run's): the output folder made ready (prepare_output), the writers the config asks for
    (writers_for) and, with `online_fps`, the online tracker of a live run at that rate;
    `kept`: FrameLoop's mappings and `strict`, `timestamps`."""
    prepare_output(out, cfg.resolved, overwrite, resume)
    view = RunView(cfg, out, geometry, camera, worker_pictures=worker_pictures)
    writers = writers_for(view)
    online = OnlineTracks.for_run(view, writers, online_fps) if online_fps else None
    return FrameLoop(view, writers, online=online, log=log, **kept)

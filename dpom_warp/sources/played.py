"""Frames played as a live camera sends them (`input.play: true`, `dpom-warp run CONFIG --play`):
the frames a plain run of input.frames reads (files, or a recording read into the cache), sent
at their own rate from a thread, so that the live run (newest frame inferred, the others
dropped, tracks online, the live line) is tried without a camera, on frames whose results
a plain run gives too."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Callable

from ..io import read_depth
from .base import Frame, Source, SourceInfo


class PlayedFrames(Source):
    """`files` (depth frame files, in order) sent at `timestamps` (seconds, one per file: a
    recording's clock) or, without, at `fps`. A frame is read ahead and sent when due, as
    Frame(index, timestamp, depth in the files' units) named by its file's stem; after the
    last, on_frame(None): the stream has ended. `start_at`: the time (on the timestamps' clock)
    `start` stands for (default the first frame's: it is sent at once); a rig's cameras share
    one, so that their frames are sent together as they were recorded (sources.rig)."""

    def __init__(self, files: list[Path], width: int, height: int, fps: float,
                 timestamps: list[float] | None = None, path: str = "", start_at: float | None = None):
        self.files, self.width, self.height, self.path = list(files), width, height, path
        if timestamps is not None and len(timestamps) != len(self.files):
            raise ValueError(f"timestamps: expected one per frame ({len(self.files)}), found {len(timestamps)}")
        self.times = (list(timestamps) if timestamps is not None else [i / fps for i in range(len(self.files))])
        span = self.times[-1] - self.times[0] if self.times else 0.0
        self.fps = (len(self.times) - 1) / span if timestamps is not None and span > 0 else fps
        self.start_at = start_at if start_at is not None else self.times[0] if self.times else 0.0
        self.stopped, self.thread, self.sent = threading.Event(), None, 0

    def info(self) -> SourceInfo:
        return SourceInfo(kind=f"{self.path} played ({len(self.files)} frames)", path=self.path,
                          frames=len(self.files), width=self.width, height=self.height, rate_hz=self.fps,
                          duration_s=self.times[-1] - self.times[0] if self.times else None)

    def start(self, on_frame: Callable[[Frame | None], None]) -> None:
        self.stopped.clear()
        self.thread = threading.Thread(target=self._play, args=(on_frame,), daemon=True)
        self.thread.start()

    def _play(self, on_frame) -> None:
        t0 = time.perf_counter() - self.start_at
        for i, (f, stamp) in enumerate(zip(self.files, self.times)):
            depth = read_depth(f, 1.0)  # the file's own units, as a camera sends them
            wait = t0 + stamp - time.perf_counter()
            if self.stopped.wait(max(0.0, wait)):
                return
            on_frame(Frame(i, stamp, depth, name=f.stem, arrived=time.perf_counter()))
            self.sent = i + 1
        on_frame(None)  # the end of the stream

    def stop(self) -> None:
        self.stopped.set()
        if self.thread is not None:
            self.thread.join(5)

    def frames(self):
        for i, (f, stamp) in enumerate(zip(self.files, self.times)):
            yield Frame(i, stamp, read_depth(f, 1.0))

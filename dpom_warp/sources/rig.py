"""A rig of live cameras as one live source: every camera started with its own callback, each
frame of the first camera paired with each other camera's frame that arrived nearest to it on
this machine's clock (`Frame.arrived`: the cameras' own clocks need not agree), within
`tolerance` seconds; the rig's frame is sent once no nearer frame can come from any other
camera (it has sent one after, or its next, a frame period after its last, would be farther)
or the tolerance has passed, so a camera that lags by less than the tolerance is waited for
and one that sends nothing costs the tolerance, no more. A camera with no frame near in time is
None in the rig's frame (inferred from the others, as a recorded rig's frame missing a camera
is). The rig's stream ends when the first camera's does, once its last frame is paired."""

from __future__ import annotations

import dataclasses
import threading
from collections import deque
from typing import Callable

from .base import Frame, Source, SourceInfo

KEEP = 8  # each other camera's last frames kept to pair from


class RigStream(Source):
    """`sources` (live, each with start/stop), named `names`, as one source whose frames are the
    rig's: Frame.depth a list (one depth a camera, None where none was near) and Frame.parts
    each camera's own Frame. `tolerance`: seconds (None: half the first camera's frame period)."""

    def __init__(self, sources: list[Source], names: list[str], tolerance: float | None = None):
        self.sources, self.names = list(sources), list(names)
        self._infos = [s.stream_info() for s in self.sources]
        self.periods = [1.0 / i.rate_hz if i.rate_hz else None for i in self._infos]
        rate = self._infos[0].rate_hz
        self.tolerance = tolerance if tolerance is not None else 0.5 / rate if rate else 0.05
        self.lock = threading.Lock()
        self.recent = [deque(maxlen=KEEP) for _ in self.sources[1:]]
        self.received = [0] * len(self.sources)
        self.waiting: Frame | None = None  # the first camera's newest frame, until it is sent
        self.timer: threading.Timer | None = None
        self.on_frame: Callable | None = None
        self.stopped = self.ended = False

    def info(self) -> SourceInfo:
        first = self._infos[0]
        kinds = ", ".join(f"{n}: {i.kind}" for n, i in zip(self.names, self._infos))
        return dataclasses.replace(first, kind=f"a rig of {len(self.sources)} cameras ({kinds})")

    def start(self, on_frame: Callable[[Frame | None], None]) -> None:
        self.on_frame, self.stopped, self.ended = on_frame, False, False
        for c in reversed(range(len(self.sources))):  # the first camera last: the others' frames are coming
            self.sources[c].start(lambda frame, c=c: self.arrived(c, frame))

    def arrived(self, c: int, frame: Frame | None) -> None:
        """Camera c's frame (None: its stream ended), from its own thread."""
        with self.lock:
            if self.stopped:
                return
            if c > 0:
                if frame is not None:
                    self.received[c] += 1
                    self.recent[c - 1].append(frame)
                    if self.waiting is not None and self.complete(self.waiting):
                        self.send()
                return
            if frame is None:  # the end follows the frame waiting, once it is sent (or at once)
                self.ended = True
                if self.waiting is None or self.complete(self.waiting):
                    self.send()
                return
            if self.waiting is not None:  # a newer frame: the one before goes with what came
                self.send()
            self.received[0] += 1
            self.waiting = frame
            if self.complete(frame):
                self.send()
            else:
                self.timer = threading.Timer(self.tolerance, self.due, args=(frame,))
                self.timer.daemon = True
                self.timer.start()

    def complete(self, frame: Frame) -> bool:
        """Whether no other camera can send a frame nearer in time to `frame` than it has: each
        has sent one at or after it, or one before it whose next, a frame period later (its
        rate), would be farther."""
        t = frame.arrived
        for r, period in zip(self.recent, self.periods[1:]):
            if not r:
                return False
            last = r[-1].arrived
            if last < t and (period is None or last + period - t < t - last):
                return False
        return True

    def due(self, frame: Frame) -> None:
        """The tolerance has passed since `frame` arrived: sent with what came."""
        with self.lock:
            if self.waiting is frame and not self.stopped:
                self.send()

    def send(self) -> None:
        """The waiting frame paired (the lock held) and handed on, in the order taken; after
        it, the end of the stream where the first camera's has ended."""
        frame, self.waiting = self.waiting, None
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None
        if frame is not None:
            parts = [frame] + [self.nearest(r, frame.arrived) for r in self.recent]
            self.on_frame(dataclasses.replace(frame, depth=[p.depth if p is not None else None for p in parts],
                                              parts=parts))
        if self.ended:
            self.on_frame(None)

    def nearest(self, recent: deque, t: float) -> Frame | None:
        best = min(recent, key=lambda f: abs(f.arrived - t), default=None)
        return best if best is not None and abs(best.arrived - t) <= self.tolerance else None

    def stop(self) -> None:
        """Every camera stopped (the first error a camera's SDK raised, after all are)."""
        with self.lock:
            self.stopped = True
            if self.timer is not None:
                self.timer.cancel()
        errors = []
        for s in self.sources:
            try:
                s.stop()
            except RuntimeError as e:
                errors.append(e)
        if errors:
            raise errors[0]

    def frames(self):
        raise NotImplementedError("a live rig's frames come through start(on_frame)")

"""What every source is: its description (`SourceInfo`), its frames (`Frame`), the `Source`
interface the readers implement, and the helpers they share (an optional package imported or
named in one line; gravity from accelerometer readings)."""

from __future__ import annotations

import dataclasses
import threading
from typing import Iterator

import numpy as np

from ..io import InputError

INSTALL = 'pip install "dpom-warp[sensors]"'


@dataclasses.dataclass
class SourceInfo:
    """What a source holds. `depth_scale`: metres per unit of its depth values (None: float
    metres); `intrinsics`: fx, fy, cx, cy in pixels (None when the source has no camera
    information); `distortion`: OpenCV's k1, k2, p1, p2, k3 (and k4, k5, k6 for the rational
    model), or None; `gravity_up`: the accelerometer's mean reading at rest (it measures +g
    upwards) turned into the depth camera's frame (OpenCV: x right, y down, z forward), when
    the source has one and says how it sits relative to the depth camera. `frames` counts the
    frames a run reads; for files, `unreadable` names each other one and why."""

    kind: str
    path: str
    frames: int
    width: int | None = None
    height: int | None = None
    intrinsics: dict | None = None
    distortion: list | None = None
    depth_scale: float | None = None
    encoding: str | None = None
    topic: str | None = None
    streams: list = dataclasses.field(default_factory=list)
    duration_s: float | None = None
    rate_hz: float | None = None
    imu: bool = False
    gravity_up: list | None = None  # unit "up" in the depth camera's frame, from the accelerometer
    unreadable: list = dataclasses.field(default_factory=list)  # files a run would skip: {file, reason}

    def as_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Frame:
    """One frame of a source: its index in the depth stream, its timestamp (seconds, None when
    the source has none), and the depth (2-D, in the source's units: integers, or float32
    metres with 0 / NaN / inf for no reading) or why it cannot be read; a live rig's frame has
    one depth a camera (sources.rig)."""

    index: int
    timestamp: float | None
    depth: np.ndarray | None
    reason: str | None = None
    name: str | None = None  # a live frame's name in the run's outputs (default: its index, 6 digits)
    arrived: float | None = None  # a live frame's time.perf_counter() on arrival
    parts: list | None = None  # a live rig's frame (sources.rig): each camera's Frame (None: none near in time)

    @property
    def output_name(self) -> str:
        """The frame's name in a live run's outputs: its name, else its index in 6 digits."""
        return self.name or f"{self.index:06d}"


class Source:
    """A recording, a folder of frames or a live camera. A live camera also has
    `start(on_frame)`, which calls on_frame(Frame) from its own thread for each frame as it
    arrives (`Frame.arrived`: time.perf_counter() then) and on_frame(None) if its stream ends
    (played frames: PlayedFrames), and `stop()`."""

    def info(self) -> SourceInfo:
        raise NotImplementedError

    def stream_info(self) -> SourceInfo:
        """What a run streaming the source needs of it (its kind, size and rate): `info()`, but
        for what costs time to read and the config has taken already (a live camera's
        accelerometer)."""
        return self.info()

    def frames(self) -> Iterator[Frame]:
        raise NotImplementedError


class NewestFrame:
    """A live source's frames as a run takes them, a one-frame slot: `put` replaces what is
    there (counting the frame dropped), `take` waits for a frame and empties the slot;
    `put(None)`: the stream has ended (`ended`), and `take` then gives the last frame if it is
    still there, else None at once."""

    def __init__(self):
        self.cond = threading.Condition()
        self.frame, self.received, self.dropped, self.ended = None, 0, 0, False

    def put(self, frame) -> None:
        with self.cond:
            if frame is None:
                self.ended = True
                self.cond.notify_all()
                return
            if self.frame is not None:
                self.dropped += 1
            self.frame = frame
            self.received += 1
            self.cond.notify()

    def take(self, timeout: float):
        with self.cond:
            if self.frame is None and not self.ended:
                self.cond.wait(timeout)
            frame, self.frame = self.frame, None
            return frame

    def take_next(self, n: int, timeout: float, stall: float) -> list:
        """The next `n` frames taken (the first within `timeout` seconds, each next within
        `stall`); fewer when the stream ends or stalls, none when no first frame came."""
        frames = []
        while len(frames) < n:
            frame = self.take(stall if frames else timeout)
            if frame is None:
                break
            frames.append(frame)
        return frames


def gravity_direction(readings) -> list | None:
    """Unit "up" from accelerometer readings at rest (m/s^2; an accelerometer measures +g
    upwards): their mean, normalised; None when there are none or they do not add up to a
    reading of gravity (a mean under 1 m/s^2)."""
    if not len(readings):
        return None
    up = np.mean(np.asarray(readings, float), axis=0)
    n = np.linalg.norm(up)
    return (up / n).tolist() if n > 1.0 else None


def need(module: str, what: str, package: str | None = None, install: str = INSTALL):
    """Import an optional package (a reader: the sensors extra) or say in one line how to
    install it; `package`: its name on PyPI, when not the module's."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"{what} needs the optional package {package or module.split('.')[0]}; install it "
                         f"with {install}") from None

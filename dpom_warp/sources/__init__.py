"""Where a run's frames come from: a glob of depth images, or a recording (ROS 1 bag, RealSense
SDK bag, ROS 2 bag in sqlite or MCAP, Azure Kinect Matroska).

Every kind is a `Source` in a file of its own; `open_source` picks it from the name. A source
says what it holds (`info`: size, intrinsics, distortion, depth scale, frame count, rate,
topics, IMU) and yields its depth frames in order, one at a time (`frames`), each with its
index, timestamp and either the depth array or the reason it cannot be read.

A run reads a recording once, streamed, into a cache folder of 16-bit frames (.npy arrays, named
without a suffix: read_depth tells them by their content) named by their index in the stream (`000000`, `000001`, ...: the names detections.csv carries) in the
recording's own depth units (32FC1 metres become millimetres), with the recording's camera,
timestamps and unreadable messages in `source.json`; every later step (the checks, the
background, the floor fit, --workers and Ray, --resume, `dpom-warp track`) reads those files
as it reads a folder of frames. The cache is keyed by the recording's path, size, modification
time and topic, so a changed recording is read again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Iterator

import numpy as np

from ..io import InputError, atomic_path, write_json_atomic

RECORDING_SUFFIXES = {".bag": "ROS 1 bag", ".db3": "ROS 2 bag (sqlite)", ".mcap": "ROS 2 bag (MCAP)",
                      ".mkv": "Azure Kinect recording"}
CACHE_VERSION = 2  # 2: .npy frames
INSTALL = 'pip install "dpom-warp[sensors]"'


@dataclasses.dataclass
class SourceInfo:
    """What a source holds. `depth_scale`: metres per unit of its depth values (None: float
    metres); `intrinsics`: fx, fy, cx, cy in pixels (None when the source has no camera
    information); `distortion`: OpenCV's k1, k2, p1, p2, k3 (and k4, k5, k6 for the rational
    model), or None; `gravity_up`: the accelerometer's mean reading at rest (it measures +g
    upwards) turned into the depth camera's frame (OpenCV: x right, y down, z forward), when
    the source has one and says how it sits relative to the depth camera."""

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

    def as_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Frame:
    """One frame of a source: its index in the depth stream, its timestamp (seconds, None when
    the source has none), and the depth (2-D, in the source's units: integers, or float32
    metres with 0 / NaN / inf for no reading) or why it cannot be read."""

    index: int
    timestamp: float | None
    depth: np.ndarray | None
    reason: str | None = None


class Source:
    """A recording or a folder of frames."""

    def info(self) -> SourceInfo:
        raise NotImplementedError

    def frames(self) -> Iterator[Frame]:
        raise NotImplementedError


def is_recording(spec: str | os.PathLike) -> bool:
    """Whether input.frames names a recording (by its suffix, or a ROS 2 bag's folder)."""
    p = Path(os.path.expanduser(str(spec)))
    return p.suffix.lower() in RECORDING_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def open_source(spec: str | os.PathLike, topic: str | None = None, key: str = "input.frames") -> Source:
    """The source input.frames names: a live camera (`realsense[:SERIAL]`), a recording (their
    readers need the [sensors] extra) or a glob of frame files."""
    from .realsense import RealSenseLive, is_live

    if is_live(spec):
        return RealSenseLive(str(spec), key)
    p = Path(os.path.expanduser(str(spec)))
    if not is_recording(p):
        from .files import FileFrames

        return FileFrames(str(spec), key)
    if not p.exists():
        raise InputError(f"{key}: {p}: no such recording")
    if p.suffix.lower() == ".mkv":
        from .azure import AzureKinect

        return AzureKinect(p, key)
    from .bags import Bag

    return Bag(p, topic, key)


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


# -- the cache a run reads a recording from ---------------------------------------------------
def cache_root() -> Path:
    """$DPOM_WARP_CACHE, else $XDG_CACHE_HOME/dpom-warp, else ~/.cache/dpom-warp."""
    if os.environ.get("DPOM_WARP_CACHE"):
        return Path(os.environ["DPOM_WARP_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dpom-warp"


def cache_dir(path: Path, topic: str | None) -> Path:
    st = path.stat() if path.is_file() else max((f.stat() for f in path.iterdir()), key=lambda s: s.st_mtime_ns)
    key = json.dumps([str(path.resolve()), st.st_size, st.st_mtime_ns, topic, CACHE_VERSION])
    return cache_root() / "recordings" / f"{path.stem}-{hashlib.sha1(key.encode()).hexdigest()[:12]}"


def materialise(spec: str, topic: str | None = None, key: str = "input.frames", log=print) -> dict:
    """Read the recording `spec` once into its cache folder (unless there already); returns
    its source.json: info, frames (name, timestamp), skipped (name, reason), depth_scale of
    the cached units, folder."""
    path = Path(os.path.expanduser(spec))
    source = open_source(path, topic, key)
    info = source.info()
    folder = cache_dir(path, info.topic)
    meta_path = folder / "source.json"
    if meta_path.is_file():
        try:
            return json.loads(meta_path.read_text())
        except json.JSONDecodeError:
            pass
    log(f"reading {info.frames} depth frames of {path} ({info.kind}{', ' + info.topic if info.topic else ''}) "
        f"into {folder} ...")
    folder.mkdir(parents=True, exist_ok=True)
    scale = float(f"{info.depth_scale:.7g}") if info.depth_scale else 0.001  # float metres -> mm
    frames, skipped = [], []
    for fr in source.frames():
        name = f"{fr.index:06d}"
        if fr.depth is None:
            skipped.append({"frame": name, "reason": f"{path}: depth frame {name}: {fr.reason}"})
            continue
        units = fr.depth
        if np.issubdtype(units.dtype, np.floating):
            metres = np.where(np.isfinite(units) & (units > 0), units, 0.0)
            units = np.clip(np.round(metres / scale), 0, 65535)
        with atomic_path(folder / name, suffix=".npy") as tmp:
            with open(tmp, "wb") as f:
                np.save(f, np.asarray(units, np.uint16))
        frames.append({"frame": name, "timestamp": fr.timestamp})
    meta = {"info": info.as_json(), "frames": frames, "skipped": skipped, "depth_scale": scale,
            "folder": str(folder), "recording": str(path)}
    write_json_atomic(meta_path, meta)  # last: a folder without it is read again
    return meta

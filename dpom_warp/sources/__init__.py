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

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ..geometry import Camera
from ..io import InputError, array_to_metres, atomic_path, write_json_atomic
from ..names import READERS, is_recording, live_kind
from .base import INSTALL, Frame, NewestFrame, Source, SourceInfo, gravity_direction, need  # noqa: F401 - the package's names

CACHE_VERSION = 2  # 2: .npy frames


def open_source(spec: str | os.PathLike, topic: str | None = None, key: str = "input.frames") -> Source:
    """The source input.frames names: a live camera (`realsense[:SERIAL]`), a recording (their
    readers need the [sensors] extra) or a glob of frame files."""
    if live_kind(spec) is not None:
        return _reader(live_kind(spec))(str(spec), key)
    p = Path(os.path.expanduser(str(spec)))
    if not is_recording(p):
        return _reader("files")(str(spec), key)
    if not p.exists():
        raise InputError(f"{key}: {p}: no such recording")
    kind = p.suffix.lower() if p.suffix.lower() in READERS else ".db3"  # a ROS 2 bag's folder: the bags'
    return _reader(kind)(p, topic, key)


def _reader(kind: str) -> type:
    import importlib

    _, module, name = READERS[kind]
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)


# -- the cache a run reads a recording from ---------------------------------------------------
def cache_root() -> Path:
    """The folder recordings are read into: $DPOM_WARP_CACHE itself, else
    $XDG_CACHE_HOME/dpom-warp/recordings, else ~/.cache/dpom-warp/recordings."""
    if os.environ.get("DPOM_WARP_CACHE"):
        return Path(os.environ["DPOM_WARP_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dpom-warp" / "recordings"


def cache_dir(path: Path, topic: str | None) -> Path:
    st = path.stat() if path.is_file() else max((f.stat() for f in path.iterdir()), key=lambda s: s.st_mtime_ns)
    key = json.dumps([str(path.resolve()), st.st_size, st.st_mtime_ns, topic, CACHE_VERSION])
    return cache_root() / f"{path.stem}-{hashlib.sha1(key.encode()).hexdigest()[:12]}"


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


# -- the frame files a run reads --------------------------------------------------------------
def expand(pattern: str, key: str, topic: str | None = None, log=print) -> list[Path]:
    """The frame files input.frames (or input.background) names: a glob's files in sorted
    order, or a recording's frames read into its cache (sources.materialise)."""
    return source_frames(pattern, key, topic, log)[0]


def source_frames(pattern: str, key: str, topic: str | None = None, log=print) -> tuple[list[Path], dict | None]:
    """(frame files, the recording's source.json or None for a glob)."""
    if is_recording(pattern):
        meta = materialise(pattern, topic, key, log)
        files = [Path(meta["folder"]) / f["frame"] for f in meta["frames"]]
        if not files:
            reason = meta["skipped"][0]["reason"] if meta["skipped"] else "no depth frames"
            raise InputError(f"{key}: {pattern}: no readable depth frame ({reason})")
        return files, meta
    return _reader("files")(pattern, key).files, None


# -- the first frames of a source, for a floor fit ---------------------------------------------
def recording_frames(path: str, topic: str | None, count: int, camera: Camera | None = None):
    """The first `count` readable depth frames of a recording (a live camera's next), for a
    floor fit: (camera, frames in metres, their names for messages, the accelerometer's up or
    None). The camera is the recording's (size, intrinsics, distortion) unless `camera` is given.

    Raises:
        InputError: no camera information and none given, or no readable depth frame.
    """
    source = open_source(path, topic, "DEPTH")
    info = source.info()
    if camera is None:
        i = info.intrinsics
        if i is None:
            raise InputError(f"{path}: no camera information for {info.topic} (no sensor_msgs/CameraInfo); "
                             f"expected --camera CAMERA.yaml")
        camera = Camera(info.width, info.height, i["fx"], i["fy"], i["cx"], i["cy"],
                        distortion=tuple(info.distortion) if info.distortion else None)
    frames, names = [], []
    for frame in (live_frames(source, count, path) if live_kind(path) else source.frames()):
        if frame.depth is None:  # a damaged message: the next one
            continue
        frames.append(array_to_metres(frame.depth, info.depth_scale or 0.001))
        names.append(f"{path} (frame {frame.index:06d})")
        if len(frames) == count:
            break
    if not frames:
        raise InputError(f"{path}: no readable depth frame")
    return camera, frames, names, info.gravity_up


def live_frames(source, count: int, path: str, timeout: float = 10.0, stall: float = 5.0) -> list:
    """A live camera's next `count` frames (the camera started, then stopped): fewer when it
    stalls, an InputError when none comes within `timeout` seconds."""
    slot = NewestFrame()
    source.start(slot.put)
    try:
        frames = slot.take_next(count, timeout, stall)
    finally:
        source.stop()
    if not frames:
        raise InputError(f"{path}: no frame within {timeout:g} s of starting the camera")
    return frames

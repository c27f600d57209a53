"""ROS bags through `rosbags` (pure Python, maintained): ROS 1 `.bag` (RealSense SDK recordings
included), ROS 2 bags (their folder, `.db3` or `.mcap`).

The depth stream is a sensor_msgs/Image topic in 16UC1 / mono16 (millimetres, REP 118, or the
RealSense recording's "Depth Units") or 32FC1 (metres; NaN, 0 and inf are no reading), or a
sensor_msgs/CompressedImage topic in ROS's compressedDepth format ("16UC1; compressedDepth
png": a 12-byte header, then a 16-bit PNG). `input.topic` picks it when there are several.
The camera comes from the sensor_msgs/CameraInfo topic nearest to it (the longest shared
namespace): K, D (plumb_bob: 5 coefficients, rational_polynomial: 8), width, height. A
sensor_msgs/Imu topic gives the floor's up (`_gravity`; its frame reached through /tf_static:
transforms.py).
"""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Iterator

import numpy as np

from ..io import InputError
from .base import Frame, Source, SourceInfo, gravity_direction, need

IMAGE, COMPRESSED, INFO = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo"
DEPTH_ENCODINGS = {"16UC1": np.uint16, "mono16": np.uint16, "32FC1": np.float32}
# a RealSense SDK recording's accelerometer (ROS 1 .bag and ROS 2 .db3 alike)
REALSENSE_SDK_ACCEL = re.compile(r"^/device_\d+/sensor_\d+/(Accel|Motion)_\d+/imu/data$")


def _stamp(msg, fallback_ns: int) -> float:
    st = getattr(getattr(msg, "header", None), "stamp", None)
    if st is not None:
        t = getattr(st, "sec", 0) + 1e-9 * getattr(st, "nanosec", 0)
        if t > 0:
            return float(t)
    return fallback_ns * 1e-9


def decode_image(msg) -> np.ndarray:
    """A depth sensor_msgs/Image as an array in its units (uint16) or metres (float32)."""
    enc = msg.encoding
    if enc not in DEPTH_ENCODINGS:
        raise ValueError(f"encoding {enc!r} is not a depth encoding (16UC1, mono16, 32FC1)")
    dtype = np.dtype(DEPTH_ENCODINGS[enc]).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, np.uint8)
    if step < w * dtype.itemsize or len(data) < h * step:
        raise ValueError(f"truncated image: {len(data)} bytes for {w}x{h} with row step {step}")
    rows = data[:h * step].reshape(h, step)[:, :w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(dtype.newbyteorder("="))


def decode_compressed(msg) -> np.ndarray:
    """ROS compressedDepth ('16UC1; compressedDepth png'): a 12-byte header, then a PNG."""
    from PIL import Image

    fmt = str(msg.format)
    if "compressedDepth" not in fmt:
        raise ValueError(f"format {fmt!r} is not compressedDepth")
    if not fmt.strip().startswith("16UC1") and "16UC1" not in fmt:
        raise ValueError(f"format {fmt!r}: only 16UC1 compressed depth is read")
    data = bytes(np.asarray(msg.data, np.uint8))
    png = data.find(b"\x89PNG")
    if png < 0:
        raise ValueError("no PNG in the compressed depth message")
    with Image.open(io.BytesIO(data[png:])) as im:
        im.load()
        a = np.asarray(im)
    if a.ndim != 2:
        raise ValueError(f"compressed depth PNG has {a.ndim} dimensions")
    return a.astype(np.uint16)


class Bag(Source):
    def __init__(self, path: Path, topic: str | None, key: str = "input.frames"):
        need("rosbags", f"{key}: {path} (a ROS bag)")
        self.path, self.key, self.wanted = Path(path), key, topic
        self._info = None

    def _reader(self):
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        # messages whose definitions the bag does not carry (RealSense SDK .db3 files) are
        # read with the standard definitions of the bag's ROS version
        store = Stores.ROS1_NOETIC if self.path.suffix.lower() == ".bag" else Stores.ROS2_HUMBLE
        try:
            return AnyReader([self.path], default_typestore=get_typestore(store))
        except Exception as e:  # noqa: BLE001 - rosbags raises its own kinds
            raise InputError(f"{self.key}: {self.path}: not a readable ROS bag ({type(e).__name__}: {e})") from None

    def info(self) -> SourceInfo:
        if self._info is not None:
            return self._info
        try:
            with self._reader() as r:
                self._info = self._inspect(r)
        except InputError:
            raise
        except Exception as e:  # noqa: BLE001
            raise InputError(f"{self.key}: {self.path}: not a readable ROS bag ({type(e).__name__}: {e})") from None
        return self._info

    def _first(self, r, conn):
        for c, t, raw in r.messages(connections=[conn]):
            try:
                return r.deserialize(raw, c.msgtype)
            except Exception:  # noqa: BLE001 - a damaged first message: try the next
                continue
        return None

    def _inspect(self, r) -> SourceInfo:
        suffix = self.path.suffix.lower()
        kind = {".bag": "ROS 1 bag", ".mcap": "ROS 2 bag (MCAP)"}.get(suffix, "ROS 2 bag")
        streams = [{"topic": c.topic, "type": c.msgtype, "messages": c.msgcount} for c in r.connections]
        depth = []
        for c in r.connections:
            if c.msgtype == IMAGE:
                m = self._first(r, c)
                if m is not None and m.encoding in DEPTH_ENCODINGS:
                    depth.append((c, m))
            elif c.msgtype == COMPRESSED:
                m = self._first(r, c)
                if m is not None and "compressedDepth" in str(m.format):
                    depth.append((c, m))
        names = sorted({c.topic for c, _ in depth})
        if self.wanted is not None:
            chosen = [(c, m) for c, m in depth if c.topic == self.wanted]
            if not chosen:
                raise InputError(f"input.topic: {self.path} has no depth stream {self.wanted!r}; expected one "
                                 f"of {', '.join(names) or 'none (no depth image topic)'}")
        elif len(names) > 1:
            raise InputError(f"input.topic: {self.path} has {len(names)} depth streams; expected one chosen, "
                             f"found {', '.join(names)}")
        else:
            chosen = depth
        if not chosen:
            images = sorted({c.topic for c in r.connections if c.msgtype in (IMAGE, COMPRESSED)})
            raise InputError(f"{self.key}: {self.path} has no depth image stream (sensor_msgs/Image in 16UC1, "
                             f"mono16 or 32FC1, or compressedDepth); found "
                             f"{', '.join(images) or 'no image topic'}")
        conns = [c for c, _ in chosen if c.topic == chosen[0][0].topic]
        self.conns = conns
        first = chosen[0][1]
        if first.__class__.__name__.endswith("CompressedImage"):
            sample = decode_compressed(first)
            encoding, h, w = "16UC1; compressedDepth png", *sample.shape
        else:
            encoding, h, w = first.encoding, int(first.height), int(first.width)
        count = sum(c.msgcount for c in conns)
        topic = conns[0].topic
        intrinsics, distortion, iw, ih = self._camera_info(r, topic)
        scale = None if encoding == "32FC1" else self._depth_units(r, topic)
        imu_conns = [c for c in r.connections if c.msgtype == "sensor_msgs/msg/Imu"]
        imu = bool(imu_conns)
        up = self._gravity(r, imu_conns, getattr(getattr(first, "header", None), "frame_id", None))
        dur = (r.end_time - r.start_time) * 1e-9 if r.end_time > r.start_time else None
        return SourceInfo(kind=kind, path=str(self.path), frames=count, width=iw or w, height=ih or h,
                          intrinsics=intrinsics, distortion=distortion, depth_scale=scale, encoding=encoding,
                          topic=topic, streams=streams, duration_s=dur,
                          rate_hz=(count - 1) / dur if dur and count > 1 else None, imu=imu, gravity_up=up)

    def _gravity(self, r, conns, frame_id, limit: int = 100):
        """The mean linear acceleration of a sensor_msgs/Imu topic turned into the depth image's
        frame: as it reads where the IMU is in that frame, or a RealSense SDK recording's
        accelerometer (the SDK gives it in the depth sensor's axes, its extrinsic rotation the
        identity); else by the bag's static transforms (/tf_static) from the IMU's frame to the
        depth image's. None where no Imu topic reads gravity in a frame so reached."""
        from .transforms import rotation_between, static_rotations

        rotations = None
        for c in conns:
            acc, imu_frame = [], None
            for _, _, raw in r.messages(connections=[c]):
                try:
                    m = r.deserialize(raw, c.msgtype)
                except Exception:  # noqa: BLE001
                    continue
                imu_frame = imu_frame if imu_frame is not None else m.header.frame_id
                if m.header.frame_id != imu_frame:
                    break
                a = m.linear_acceleration
                acc.append((a.x, a.y, a.z))
                if len(acc) >= limit:
                    break
            if not acc or frame_id is None:
                continue
            turn = np.eye(3) if imu_frame == frame_id or REALSENSE_SDK_ACCEL.match(c.topic) else None
            if turn is None:
                rotations = static_rotations(r) if rotations is None else rotations
                turn = rotation_between(rotations, imu_frame, frame_id)
            up = gravity_direction([turn @ np.asarray(a) for a in acc]) if turn is not None else None
            if up is not None:
                return up
        return None

    def _camera_info(self, r, topic: str):
        infos = [c for c in r.connections if c.msgtype == INFO]
        if not infos:
            return None, None, None, None
        parts = topic.strip("/").split("/")

        def shared(c):
            other = c.topic.strip("/").split("/")
            n = 0
            while n < min(len(parts), len(other)) and parts[n] == other[n]:
                n += 1
            return n

        best = max(infos, key=shared)
        if shared(best) == 0 and len(infos) > 1:
            return None, None, None, None
        m = self._first(r, best)
        if m is None:
            return None, None, None, None
        k = np.asarray(getattr(m, "k", getattr(m, "K", None)), float).ravel()
        if k.size != 9 or k[0] <= 0:
            return None, None, None, None
        d = [float(x) for x in np.asarray(getattr(m, "d", getattr(m, "D", [])), float).ravel()]
        model = getattr(m, "distortion_model", "")
        distortion = None
        if any(abs(x) > 0 for x in d):
            if model in ("plumb_bob", "rational_polynomial") and len(d) in (5, 8):
                distortion = d
            else:
                raise InputError(f"{self.key}: {self.path}: camera info {best.topic} has distortion model "
                                 f"{model!r} with {len(d)} coefficients; expected plumb_bob (5) or "
                                 f"rational_polynomial (8)")
        return ({"fx": float(k[0]), "fy": float(k[4]), "cx": float(k[2]), "cy": float(k[5])}, distortion,
                int(m.width) or None, int(m.height) or None)

    def _depth_units(self, r, topic: str) -> float:
        """Metres per unit of 16-bit depth: the RealSense recording's Depth Units option, else
        REP 118's millimetres."""
        sensor = "/".join(topic.strip("/").split("/")[:2])
        for c in r.connections:
            if c.topic.strip("/").startswith(sensor) and c.topic.replace("_", " ").endswith("Depth Units/value"):
                m = self._first(r, c)
                try:
                    units = float(m.data) if m is not None else 0.0  # Float32, or a String in .db3
                except ValueError:
                    units = 0.0
                if units > 0:
                    return float(np.float32(units))
        return 0.001

    def frames(self) -> Iterator[Frame]:
        self.info()
        with self._reader() as r:
            conns = [c for c in r.connections if c.topic == self._info.topic]
            for i, (c, t, raw) in enumerate(r.messages(connections=conns)):
                try:
                    msg = r.deserialize(raw, c.msgtype)
                except Exception as e:  # noqa: BLE001 - a damaged message is skipped, not fatal
                    yield Frame(i, t * 1e-9, None, f"unreadable message ({type(e).__name__}: {e})")
                    continue
                try:
                    depth = decode_compressed(msg) if c.msgtype == COMPRESSED else decode_image(msg)
                except (ValueError, OSError) as e:
                    yield Frame(i, _stamp(msg, t), None, str(e))
                    continue
                yield Frame(i, _stamp(msg, t), depth)

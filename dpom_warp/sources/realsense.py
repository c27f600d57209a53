"""Live RealSense cameras through pyrealsense2: `input.frames: realsense` (the first camera) or
`realsense:SERIAL`. The depth sensor streams its default z16 profile; the camera (size,
intrinsics, distortion) and the depth units come from it. Frames arrive on pyrealsense2's
thread and are handed to a callback (the live run keeps the newest).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ..io import InputError
from . import Frame, Source, SourceInfo, need

LIVE_PREFIX = "realsense"


def is_live(spec) -> bool:
    s = str(spec)
    return s == LIVE_PREFIX or s.startswith(LIVE_PREFIX + ":")


SOFTWARE: list = []  # SoftwareCamera devices in this process, seen as cameras after the real ones


def devices() -> list:
    """The RealSense devices pyrealsense2 sees, then this process's software cameras."""
    rs = need("pyrealsense2", f"input.frames: {LIVE_PREFIX} (a live RealSense camera)")
    return list(rs.context().query_devices()) + [c.device for c in SOFTWARE]


class SoftwareCamera:
    """A camera without hardware: pyrealsense2's software_device with one z16 depth stream,
    playing `frames` ((H, W) uint16 in millimetres, over and over) at `fps` on a thread once
    `start`ed; `register` makes `input.frames: realsense:SERIAL` find it. For tests, benchmarks
    and trying the live mode without a camera."""

    def __init__(self, frames, fx, fy, cx, cy, fps: float = 30.0, serial: str = "000111222"):
        import threading

        rs = self.rs_module()
        h, w = frames[0].shape
        self.frames, self.fps, self.serial = [np.asarray(f, np.uint16) for f in frames], fps, serial
        self.device = rs.software_device()
        self.device.register_info(rs.camera_info.serial_number, serial)
        self.device.register_info(rs.camera_info.name, "software depth camera")
        self.sensor = self.device.add_sensor("Depth")
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height, vs.fps, vs.bpp = rs.stream.depth, 0, 0, w, h, int(fps), 2
        vs.fmt = rs.format.z16
        intr = rs.intrinsics()
        intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = w, h, fx, fy, cx, cy
        intr.model, intr.coeffs = rs.distortion.none, [0, 0, 0, 0, 0]
        vs.intrinsics = intr
        self.profile = self.sensor.add_video_stream(vs).as_video_stream_profile()
        self.sensor.add_read_only_option(rs.option.depth_units, 0.001)
        self.stopped, self.sent, self.thread = threading.Event(), 0, None

    @classmethod
    def of_config(cls, cfg, fps: float = 30.0) -> "SoftwareCamera":
        """A software camera playing a run config's frames (rendered first when the config has
        a `synthetic` section), in their depth units, with the config's intrinsics."""
        from PIL import Image

        from .run import expand, render_synthetic

        render_synthetic(cfg, lambda *_: None)
        frames = [np.load(f) if f.suffix.lower() == ".npy" else np.asarray(Image.open(f))
                  for f in expand(cfg.inputs.frames, "input.frames", cfg.inputs.topic, lambda *_: None)]
        c = cfg.camera
        return cls([np.asarray(f, np.uint16) for f in frames], c.fx, c.fy, c.cx, c.cy, fps)

    def register(self) -> "SoftwareCamera":
        SOFTWARE.append(self)
        return self

    def unregister(self) -> None:
        if self in SOFTWARE:
            SOFTWARE.remove(self)

    def start(self) -> None:
        """Play from the first frame on a thread of its own."""
        import threading

        self.stopped.clear()
        self.sent = 0
        self.thread = threading.Thread(target=self._feed, daemon=True)
        self.thread.start()

    def stop(self) -> None:
        self.stopped.set()
        if self.thread is not None:
            self.thread.join(5)

    def record(self, path) -> int:
        """Write the frames once, in order, as a RealSense SDK recording at `path` (the SDK's
        own recorder: a ROS 2 .db3 with compressedDepth images); returns the frames written."""
        import gc

        rs = self.rs_module()
        recorder = rs.recorder(str(path), self.device)
        sensor = recorder.query_sensors()[0]
        got = []
        sensor.open(sensor.get_stream_profiles()[0])
        sensor.start(lambda f: got.append(f.get_frame_number()))
        for i, img in enumerate(self.frames):
            self._send(rs, img, i)
            deadline = time.perf_counter() + 5.0
            while len(got) <= i and time.perf_counter() < deadline:
                time.sleep(0.002)
        sensor.stop()
        sensor.close()
        del sensor, recorder
        gc.collect()  # the recorder writes the file out when it goes
        return len(got)

    def _send(self, rs, img, number: int) -> None:
        f = rs.software_video_frame()
        f.pixels, f.stride, f.bpp = img.tobytes(), img.shape[1] * 2, 2
        f.timestamp, f.domain = 1000.0 * number / self.fps, rs.timestamp_domain.hardware_clock
        f.frame_number, f.profile = number, self.profile
        self.sensor.on_video_frame(f)

    def _feed(self):
        rs = self.rs_module()
        t0 = time.perf_counter()
        while not self.stopped.is_set():
            self._send(rs, self.frames[self.sent % len(self.frames)], self.sent)
            self.sent += 1
            time.sleep(max(0.0, t0 + self.sent / self.fps - time.perf_counter()))

    @staticmethod
    def rs_module():
        return need("pyrealsense2", "a software camera")


class RealSenseLive(Source):
    def __init__(self, spec: str, key: str = "input.frames"):
        self.rs = need("pyrealsense2", f"{key}: {spec} (a live RealSense camera)")
        self.spec, self.key = spec, key
        serial = spec.split(":", 1)[1] if ":" in spec else None
        found = devices()
        serials = [d.get_info(self.rs.camera_info.serial_number) for d in found]
        if not found:
            raise InputError(f"{key}: {spec}: no RealSense camera connected (pyrealsense2 sees none); "
                             f"expected a camera on USB, or frames or a recording")
        if serial is not None and serial not in serials:
            raise InputError(f"{key}: {spec}: no RealSense camera with serial {serial}; found {', '.join(serials)}")
        self.device = found[serials.index(serial) if serial is not None else 0]
        self.serial = serials[serials.index(serial) if serial is not None else 0]
        sensors = [s for s in self.device.query_sensors() if self._depth_profiles(s)]
        if not sensors:
            raise InputError(f"{key}: {spec}: camera {self.serial} has no z16 depth stream")
        self.sensor = sensors[0]
        profiles = self._depth_profiles(self.sensor)
        defaults = [p for p in profiles if p.is_default()]
        self.profile = (defaults or profiles)[0].as_video_stream_profile()
        self.started = False

    def _depth_profiles(self, sensor):
        rs = self.rs
        return [p for p in sensor.get_stream_profiles()
                if p.stream_type() == rs.stream.depth and p.format() == rs.format.z16]

    def info(self) -> SourceInfo:
        rs = self.rs
        i = self.profile.get_intrinsics()
        coeffs = [float(c) for c in i.coeffs]
        distortion = coeffs[:5] if any(coeffs) and i.model == rs.distortion.brown_conrady else None
        scale = float(self.sensor.as_depth_sensor().get_depth_scale()) if self.sensor.is_depth_sensor() else 0.001
        name = self.device.get_info(rs.camera_info.name) if self.device.supports(rs.camera_info.name) else "RealSense"
        return SourceInfo(kind=f"live RealSense camera ({name}, serial {self.serial})", path=self.spec,
                          frames=0, width=i.width, height=i.height,
                          intrinsics={"fx": i.fx, "fy": i.fy, "cx": i.ppx, "cy": i.ppy}, distortion=distortion,
                          depth_scale=scale, encoding="z16", topic="depth",
                          rate_hz=float(self.profile.fps()), imu=any(
                              s.is_motion_sensor() for s in self.device.query_sensors()))

    def start(self, on_frame: Callable[[Frame], None]) -> None:
        """Stream: `on_frame` gets each frame (index, timestamp in seconds, uint16 depth) on
        pyrealsense2's thread, with its arrival time as `arrived` (time.perf_counter)."""
        count = [0]

        def callback(f):
            arrived = time.perf_counter()
            depth = np.asanyarray(f.get_data()).astype(np.uint16, copy=True)
            fr = Frame(count[0], float(f.get_timestamp()) / 1000.0, depth)
            fr.arrived = arrived
            count[0] += 1
            on_frame(fr)

        self.sensor.open(self.profile)
        self.sensor.start(callback)
        self.started = True

    def stop(self) -> None:
        if self.started:
            self.sensor.stop()
            self.sensor.close()
            self.started = False

    def frames(self):
        raise InputError(f"{self.key}: {self.spec}: a live camera streams; it is not read as a recording")

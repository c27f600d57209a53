"""Live RealSense cameras through pyrealsense2: `input.frames: realsense` (the first camera) or
`realsense:SERIAL`. The depth sensor streams its default z16 profile; the camera (size,
intrinsics, distortion) and the depth units come from it, and where the camera has an
accelerometer (D435i, D455), the floor's up from its readings at rest. Frames arrive on
pyrealsense2's thread and are handed to a callback (the live run keeps the newest).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from ..io import InputError
from .base import Frame, Source, SourceInfo, gravity_direction, need

LIVE_PREFIX = "realsense"  # input.frames: realsense[:SERIAL] (names.READERS)
ACCEL_SAMPLES, ACCEL_WAIT_S = 50, 2.0  # the accelerometer readings averaged for up, and the longest wait for them


def devices() -> list:
    """The RealSense devices pyrealsense2 sees, then this process's software cameras."""
    from .software import SOFTWARE

    rs = need("pyrealsense2", f"input.frames: {LIVE_PREFIX} (a live RealSense camera)")
    return list(rs.context().query_devices()) + [c.device for c in SOFTWARE]


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
        self._up = None  # the accelerometer's up once read (gravity_up)

    def _depth_profiles(self, sensor):
        rs = self.rs
        return [p for p in sensor.get_stream_profiles()
                if p.stream_type() == rs.stream.depth and p.format() == rs.format.z16]

    def info(self) -> SourceInfo:
        """The camera as `stream_info` gives it, with its accelerometer's up (gravity_up: read once)."""
        return dataclasses.replace(self.stream_info(), gravity_up=self.gravity_up())

    def stream_info(self) -> SourceInfo:
        """The camera, without reading its accelerometer (the up was read when the config was
        loaded; the live run only needs the stream's kind, size and rate): `imu` says whether it has one."""
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
                          rate_hz=float(self.profile.fps()), imu=self._accelerometer() is not None)

    def _accelerometer(self):
        """(sensor, profile) of the camera's accelerometer stream (accel, motion_xyz32f; its
        default rate where it has several), or None."""
        rs = self.rs
        for sensor in self.device.query_sensors():
            found = [p for p in sensor.get_stream_profiles()
                     if p.stream_type() == rs.stream.accel and p.format() == rs.format.motion_xyz32f]
            if found:
                return sensor, ([p for p in found if p.is_default()] or found)[0]
        return None

    def gravity_up(self) -> list | None:
        """Up in the depth camera's frame: the mean of ACCEL_SAMPLES accelerometer readings
        (the camera at rest; librealsense gives them in the depth sensor's axes, x right, y down,
        z forward, +g upwards), read once; None without an accelerometer, or when it gives no
        reading of gravity within ACCEL_WAIT_S (another process holding it, say)."""
        import threading

        accelerometer = None if self._up is not None else self._accelerometer()
        if accelerometer is None:
            return self._up
        sensor, profile = accelerometer
        readings, enough = [], threading.Event()

        def on_reading(f):
            m = f.as_motion_frame().get_motion_data()
            if len(readings) < ACCEL_SAMPLES:
                readings.append((m.x, m.y, m.z))
            if len(readings) >= ACCEL_SAMPLES:
                enough.set()

        try:
            sensor.open(profile)
        except RuntimeError:  # busy: the floor fit goes without it
            return None
        try:
            sensor.start(on_reading)
            enough.wait(ACCEL_WAIT_S)
            sensor.stop()
        finally:
            sensor.close()
        self._up = gravity_direction(list(readings))
        return self._up

    def start(self, on_frame: Callable[[Frame], None]) -> None:
        """Stream: `on_frame` gets each frame (index, timestamp in seconds, uint16 depth) on
        pyrealsense2's thread, with its arrival time as `arrived` (time.perf_counter)."""
        count = [0]

        def callback(f):
            arrived = time.perf_counter()
            depth = np.asanyarray(f.get_data()).astype(np.uint16, copy=True)
            fr = Frame(count[0], float(f.get_timestamp()) / 1000.0, depth, arrived=arrived)
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

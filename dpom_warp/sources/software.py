"""A RealSense camera without hardware: pyrealsense2's software_device playing depth frames at
a rate, which `input.frames: realsense:SERIAL` finds once it is registered (the live mode tried
without a camera, and its tests and benchmark)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .base import need

SOFTWARE: list = []  # SoftwareCamera devices in this process, seen as cameras after the real ones
ACCEL_HZ = 200  # a software camera's accelerometer rate (a D435i's is 63 or 250 Hz)


class SoftwareCamera:
    """A camera without hardware: pyrealsense2's software_device with one z16 depth stream,
    playing `frames` ((H, W) uint16 in millimetres, over and over) at `fps` on a thread once
    `start`ed; `register` makes `input.frames: realsense:SERIAL` find it. With `accel` (m/s^2,
    the depth camera's axes, +g upwards as a D435i's accelerometer reads at rest) it also has a
    motion module whose accelerometer reads that at ACCEL_HZ while registered. For tests,
    benchmarks and trying the live mode without a camera."""

    def __init__(self, frames, fx, fy, cx, cy, fps: float = 30.0, serial: str = "000111222", accel=None):
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
        self.accel, self.motion = None if accel is None else tuple(float(a) for a in accel), None
        self.motion_thread = None  # feeding the accelerometer while registered
        if self.accel is not None:
            self.motion = self._add_accelerometer(rs)
            self.motion_stopped = threading.Event()

    def _add_accelerometer(self, rs):
        """The motion module's accelerometer stream (motion_xyz32f at ACCEL_HZ): its profile."""
        sensor = self.device.add_sensor("Motion Module")
        stream = rs.motion_stream()
        stream.type, stream.index, stream.uid, stream.fps = rs.stream.accel, 0, 1, ACCEL_HZ
        stream.fmt, stream.intrinsics = rs.format.motion_xyz32f, rs.motion_device_intrinsic()
        self.motion_sensor = sensor
        return sensor.add_motion_stream(stream).as_motion_stream_profile()

    @classmethod
    def of_files(cls, files, camera, fps: float = 30.0, accel=None) -> "SoftwareCamera":
        """A software camera playing depth frame files (16-bit PNGs or .npy arrays, in their
        own depth units) with `camera`'s intrinsics (a geometry.Camera)."""
        from PIL import Image

        frames = [np.load(f) if Path(f).suffix.lower() == ".npy" else np.asarray(Image.open(f)) for f in files]
        return cls([np.asarray(f, np.uint16) for f in frames], camera.fx, camera.fy, camera.cx, camera.cy, fps,
                   accel=accel)

    def register(self) -> "SoftwareCamera":
        """Seen as a camera (and its accelerometer reading) until unregistered."""
        import threading

        SOFTWARE.append(self)
        if self.motion is not None:
            self.motion_stopped.clear()
            self.motion_thread = threading.Thread(target=self._feed_accelerometer, daemon=True)
            self.motion_thread.start()
        return self

    def unregister(self) -> None:
        if self in SOFTWARE:
            SOFTWARE.remove(self)
        if self.motion_thread is not None:
            self.motion_stopped.set()
            self.motion_thread.join(5)
            self.motion_thread = None

    def _feed_accelerometer(self):
        """`accel` at ACCEL_HZ (a reader that has not opened the stream misses them, as from a camera)."""
        rs = self.rs_module()
        number, t0 = 0, time.perf_counter()
        while not self.motion_stopped.is_set():
            f, v = rs.software_motion_frame(), rs.vector()
            v.x, v.y, v.z = self.accel
            f.data, f.timestamp, f.domain = v, 1000.0 * number / ACCEL_HZ, rs.timestamp_domain.hardware_clock
            f.frame_number, f.profile = number, self.motion
            self.motion_sensor.on_motion_frame(f)
            number += 1
            time.sleep(max(0.0, t0 + number / ACCEL_HZ - time.perf_counter()))

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
        own recorder: a ROS 2 .db3 with compressedDepth images; with `accel`, the accelerometer's
        readings beside them); returns the frames written."""
        import gc
        import threading

        rs = self.rs_module()
        recorder = rs.recorder(str(path), self.device)
        sensors = recorder.query_sensors()
        got = []
        sensors[0].open(sensors[0].get_stream_profiles()[0])
        sensors[0].start(lambda f: got.append(f.get_frame_number()))
        motion = sensors[1] if self.motion is not None else None
        if motion is not None:  # its readings recorded while the frames are
            readings = []
            motion.open(motion.get_stream_profiles()[0])
            motion.start(lambda f: readings.append(f.get_frame_number()))
            self.motion_stopped.clear()
            feed = threading.Thread(target=self._feed_accelerometer, daemon=True)
            feed.start()
            deadline = time.perf_counter() + 5.0
            while len(readings) < 20 and time.perf_counter() < deadline:  # some before the first frame
                time.sleep(0.002)
        for i, img in enumerate(self.frames):
            self._send(rs, img, i)
            deadline = time.perf_counter() + 5.0
            while len(got) <= i and time.perf_counter() < deadline:
                time.sleep(0.002)
        for sensor in [sensors[0]] + ([motion] if motion is not None else []):
            sensor.stop()
            sensor.close()
        if motion is not None:
            self.motion_stopped.set()
            feed.join(5)
        del sensor, sensors, motion, recorder
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

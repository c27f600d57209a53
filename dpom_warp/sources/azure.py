"""Azure Kinect recordings (Matroska `.mkv`) through PyAV: the DEPTH track's 16-bit big-endian
samples in millimetres, and the depth camera from the `calibration.json` attachment.

The calibration's intrinsics are for the full 1024 x 1024 sensor, normalised by its size and
with (0, 0) at the corner of the first pixel; a depth mode crops and bins it (the Azure Kinect
SDK's table: NFOV unbinned 640 x 576 cropped at (192, 180); NFOV 2x2 binned 320 x 288 at
(96, 90) of 512 x 512; WFOV 2x2 binned 512 x 512; WFOV unbinned 1024 x 1024), and pixel
centres move to integers. Its lens model (Brown-Conrady with k1..k6, p1, p2) is OpenCV's
rational model.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterator

import numpy as np

from ..io import InputError
from .base import Frame, Source, SourceInfo, gravity_direction, need

MODES = {  # depth mode: (binned sensor size, crop offset, output size)
    "NFOV_UNBINNED": ((1024, 1024), (192, 180), (640, 576)),
    "NFOV_2X2BINNED": ((512, 512), (96, 90), (320, 288)),
    "WFOV_2X2BINNED": ((512, 512), (0, 0), (512, 512)),
    "WFOV_UNBINNED": ((1024, 1024), (0, 0), (1024, 1024)),
    "PASSIVE_IR": ((1024, 1024), (0, 0), (1024, 1024)),
}


def gravity_up(calibration: dict, samples: list[tuple[float, float, float]]) -> list | None:
    """The mean accelerometer reading (m/s^2, +g upwards at rest) in the depth camera's frame:
    calibration.json's accelerometer rotation R maps depth-camera coordinates to the
    accelerometer's, so a reading a becomes R^T a there."""
    sensors = calibration["CalibrationInformation"].get("InertialSensors", [])
    acc = next((x for x in sensors if x.get("SensorType") == "CALIBRATION_InertialSensorType_Accelerometer"), None)
    if acc is None or not samples:
        return None
    r = np.asarray(acc["Rt"]["Rotation"], float).reshape(3, 3)
    return gravity_direction([r.T @ np.mean(np.asarray(samples, float), axis=0)])  # the mean reading a as R^T a


def imu_samples(c, limit: int = 200) -> list[tuple[float, float, float]]:
    """Accelerometer readings of the IMU track: 40-byte samples (accelerometer timestamp ns,
    3 float32 m/s^2, gyroscope timestamp ns, 3 float32 rad/s), little-endian."""
    import struct

    tracks = [s for s in c.streams if s.metadata.get("title") == "IMU"]
    out = []
    if not tracks:
        return out
    for pkt in c.demux(tracks[0]):
        data = bytes(pkt)
        for i in range(0, len(data) - 39, 40):
            out.append(struct.unpack_from("<3f", data, i + 8))
        if len(out) >= limit:
            break
    return out


def depth_camera(calibration: dict, mode: str) -> tuple[dict, list]:
    """The depth camera's intrinsics (fx, fy, cx, cy, pixels, centres at integers) and its
    distortion (k1, k2, p1, p2, k3, k4, k5, k6) in `mode`, from calibration.json."""
    cams = calibration["CalibrationInformation"]["Cameras"]
    cam = next(c for c in cams if c.get("Purpose") == "CALIBRATION_CameraPurposeDepth")
    p = cam["Intrinsics"]["ModelParameters"]
    cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, _codx, _cody, p2, p1 = p[:14]
    (bw, bh), (ox, oy), _ = MODES[mode]
    intr = {"fx": fx * bw, "fy": fy * bh, "cx": cx * bw - ox - 0.5, "cy": cy * bh - oy - 0.5}
    return intr, [k1, k2, p1, p2, k3, k4, k5, k6]


class AzureKinect(Source):
    def __init__(self, path: Path, topic: str | None = None, key: str = "input.frames"):
        """`topic`: unused (a Matroska file has one depth track), as every recording reader takes."""
        need("av", f"{key}: {path} (an Azure Kinect recording)")
        self.path, self.key = Path(path), key
        self._info = None

    def _open(self):
        import av

        try:
            return av.open(str(self.path))
        except Exception as e:  # noqa: BLE001 - PyAV raises FFmpeg's kinds
            raise InputError(f"{self.key}: {self.path}: not a readable Matroska file ({e})") from None

    def _depth_stream(self, c):
        depth = [s for s in c.streams if s.type == "video" and (s.metadata.get("title") == "DEPTH"
                                                                 or "K4A_DEPTH_MODE" in s.metadata)]
        if not depth:
            tracks = ", ".join(s.metadata.get("title", s.type) for s in c.streams)
            raise InputError(f"{self.key}: {self.path} has no Azure Kinect DEPTH track; found {tracks}")
        return depth[0]

    def info(self) -> SourceInfo:
        if self._info is not None:
            return self._info
        with self._open() as c:
            s = self._depth_stream(c)
            mode = s.metadata.get("K4A_DEPTH_MODE", "")
            if mode not in MODES:
                raise InputError(f"{self.key}: {self.path}: depth mode {mode!r}; expected one of {', '.join(MODES)}")
            att = [a for a in c.streams if a.type == "attachment" and a.metadata.get("filename") == "calibration.json"]
            intr = dist = up = None
            if att:
                try:
                    calibration = json.loads(bytes(att[0].data))
                    intr, dist = depth_camera(calibration, mode)
                except (KeyError, StopIteration, ValueError, TypeError) as e:
                    raise InputError(f"{self.key}: {self.path}: calibration.json has no usable depth camera "
                                     f"({type(e).__name__}: {e})") from None
            times = [p.pts for p in c.demux(s) if p.size > 0 and p.pts is not None]
            tb = float(s.time_base)
        with self._open() as c:  # the IMU track, from the start again
            if att:
                try:
                    up = gravity_up(calibration, imu_samples(c))
                except (KeyError, ValueError, TypeError):
                    up = None
            streams = [{"topic": a.metadata.get("title", a.type), "type": a.type,
                        "messages": None} for a in c.streams]
            imu = any(a.metadata.get("title") == "IMU" for a in c.streams)
            dur = (times[-1] - times[0]) * tb if len(times) > 1 else None
            w, h = MODES[mode][2]
            self._info = SourceInfo(kind="Azure Kinect recording", path=str(self.path), frames=len(times),
                                    width=w, height=h, intrinsics=intr, distortion=dist, depth_scale=0.001,
                                    encoding=f"16-bit big-endian ({mode})", topic="DEPTH", streams=streams,
                                    duration_s=dur, rate_hz=(len(times) - 1) / dur if dur else None, imu=imu,
                                    gravity_up=up)
        return self._info

    def frames(self) -> Iterator[Frame]:
        info = self.info()
        n = info.width * info.height * 2
        with self._open() as c:
            s = self._depth_stream(c)
            tb = float(s.time_base)
            i = 0
            for pkt in c.demux(s):
                if pkt.size == 0 or pkt.pts is None:
                    continue
                data = bytes(pkt)
                t = pkt.pts * tb
                if len(data) != n:
                    yield Frame(i, t, None, f"{len(data)} bytes, expected {n} ({info.width}x{info.height} "
                                            f"16-bit)")
                else:
                    yield Frame(i, t, np.frombuffer(data, ">u2").reshape(info.height, info.width).astype(np.uint16))
                i += 1

"""A config made ready to run: read from its file, overridden with --set, its camera keys
filled in from a camera file (`camera.file`) or from the recording or live camera input.frames
names, then validated (config.parse_config, which reads nothing). Every path from a YAML file or
a mapping to a RunConfig goes through here: the CLI, the Python API and the benchmarks."""

from __future__ import annotations

import copy
from pathlib import Path

from .config import (ConfigError, RunConfig, apply_overrides, camera_from_file, camera_shorthand, config_key, parse_config,
                     read_config, source_of)
from .io import InputError
from .names import is_live, is_recording, unknown_format
from .sources import open_source


def camera_from_recording(raw: dict) -> dict:
    """A config whose input.frames is a recording or a live camera, with the camera keys it leaves out
    (camera.width, height, intrinsics, distortion, input.depth_scale, and with extrinsics
    auto, written or left out, camera.ground.up from its accelerometer) taken from the
    recording (the keys it gives win: the run says where they differ)."""
    inp, cam = raw.get("input"), raw.get("camera", {})
    if isinstance(inp, dict) and isinstance(inp.get("frames"), str) and unknown_format(inp["frames"]):
        raise ConfigError(f"input.frames: {unknown_format(inp['frames'])}")  # before the camera keys it lacks
    if (not isinstance(inp, dict) or not isinstance(inp.get("frames"), str) or not isinstance(cam, dict)
            or not (is_recording(inp["frames"]) or is_live(inp["frames"]))):
        return raw
    missing = [k for k in ("width", "height", "intrinsics", "distortion") if k not in cam]
    ground = cam.get("ground") if isinstance(cam.get("ground"), dict) else {}
    # extrinsics left out are auto (CameraSection's default): the floor fit then takes the IMU's up too
    wants_up = cam.get("extrinsics", "auto") == "auto" and ground.get("up", "auto") == "auto"
    wants_tilt = bool(tilt_left_out(cam.get("extrinsics")))
    if not missing and "depth_scale" in inp and not wants_up and not wants_tilt:
        return raw
    try:
        info = open_source(inp["frames"], inp.get("topic")).info()
    except InputError as e:
        raise ConfigError(str(e)) from None
    out = copy.deepcopy(raw)
    cam = out.setdefault("camera", {})
    if "intrinsics" not in cam:
        if info.intrinsics is None:
            raise ConfigError(f"camera.intrinsics: required key is missing, and {inp['frames']} carries no "
                              f"camera information for {info.topic} (no sensor_msgs/CameraInfo); expected "
                              f"camera.intrinsics in the config")
        cam["intrinsics"] = dict(info.intrinsics)
    for key, value in (("width", info.width), ("height", info.height)):
        if key not in cam and value:
            cam[key] = value
    if "distortion" not in cam and info.distortion:
        cam["distortion"] = list(info.distortion)
    if "depth_scale" not in inp:
        out["input"]["depth_scale"] = float(f"{info.depth_scale:.7g}") if info.depth_scale else 0.001
    if wants_up and info.gravity_up:  # the accelerometer says where up is: the floor fit's prior
        if not isinstance(cam.get("ground"), dict):
            cam["ground"] = {}
        cam["ground"]["up"] = [round(float(x), 6) for x in info.gravity_up]
    if wants_tilt and info.gravity_up:
        tilt_from_gravity(cam["extrinsics"], info.gravity_up, inp["frames"])
    return out


TILT = ("pitch_deg", "roll_deg")


def tilt_left_out(extrinsics) -> list[str]:
    """The tilt angles (pitch_deg, roll_deg) that a camera.extrinsics of angles ({height, ...})
    leaves out: a recording with an accelerometer gives them (tilt_from_gravity)."""
    if not isinstance(extrinsics, dict) or "T_world_from_camera" in extrinsics or "height" not in extrinsics:
        return []
    return [k for k in TILT if k not in extrinsics]


def tilt_from_gravity(extrinsics: dict, up, frames: str) -> None:
    """camera.extrinsics' pitch_deg and roll_deg left out (a height written, the floor perhaps
    not in view) filled in from the recording's accelerometer: the pitch and roll of a camera
    that sees `up` (the depth camera's frame) as the world's up, as a floor with that normal
    would give them (ground.implied_pitch_roll); the angles the config gives win."""
    import numpy as np

    from .ground import implied_pitch_roll

    pitch, roll = implied_pitch_roll(np.asarray(up, dtype=np.float64))
    if pitch > 90:
        raise ConfigError(f"camera.extrinsics: {frames}'s accelerometer has the camera tilted past straight "
                          f"down (pitch {pitch:.1f} deg, which camera.extrinsics.pitch_deg cannot say); "
                          f"expected camera.extrinsics.pitch_deg and roll_deg, or T_world_from_camera")
    for key, value in zip(TILT, (pitch, roll)):
        extrinsics.setdefault(key, round(value, 3))


def config_from_mapping(raw: dict) -> RunConfig:
    """A config mapping (as loaded from YAML, overrides applied) validated into a RunConfig, with
    the camera keys it leaves out taken from `camera.file`, then from the recording it names; a
    rig's (`cameras:`) camera by camera (rig_from_mapping)."""
    if isinstance(raw, dict) and "cameras" in raw:
        return rig_from_mapping(raw)
    if not isinstance(raw, dict):
        return parse_config(raw)
    raw = camera_from_file(camera_shorthand(raw))
    cam = raw.get("camera")
    left_out = tilt_left_out(cam.get("extrinsics")) if isinstance(cam, dict) else []
    raw = camera_from_recording(raw)
    cfg = parse_config(raw)
    ext = raw["camera"]["extrinsics"] if left_out else {}
    cfg.imu_tilt = {k: ext[k] for k in left_out if k in ext}  # the angles the accelerometer gave
    return cfg


def rig_from_mapping(raw: dict) -> RunConfig:
    """A rig's config (`cameras:`): config.rig.parse_rig with each camera's keys filled in from
    its camera file or recording."""
    from .config.rig import parse_rig

    return parse_rig(raw, config_from_mapping)


def load_config(path: str | Path, overrides: list[str] | None = None) -> RunConfig:
    """Read, override and validate a YAML run config. Relative paths in the file are relative
    to its folder; those in `overrides` to the current folder."""
    raw = read_config(path)
    try:
        cfg = config_from_mapping(apply_overrides(raw, overrides or []))
    except ConfigError as e:  # said with where the value came from: the file, or --set
        key = config_key(str(e))
        raise ConfigError(f"{source_of(key, overrides or [], str(path)) if key else path}: {e}") from None
    cfg.origin = {"file": str(path), "set": list(overrides or [])}
    return cfg

"""A rig in the config (issue 61's contract): a top-level `cameras:` list, each item `{name, input,
camera}` with the single-camera config's `input` and `camera` sections, and the other sections
shared. `rig_items` splits such a mapping into one single-camera mapping per camera (what
loading validates camera by camera); `rig_key` names a camera's key in an error."""

from __future__ import annotations

import dataclasses
import re

from pydantic import Field, ValidationError

from .camera import CameraSection
from .sections import InputSection
from ..names import is_live
from ..values import ConfigError, Node, Num, Str, _first_error, _fmt

NAME = re.compile(r"^[A-Za-z0-9_-]+$")
PER_CAMERA = ("input", "camera")  # the sections each camera has; the others are shared
# object.width of a rig of several cameras where the config leaves it out: seen from every side
# (arms and swinging legs included) a person needs a wider body than one camera's 0.4 m
# (docs/rig.md: chosen on a tuning draw of the rig scenes)
RIG_WIDTH = 0.5
KINDS = {"recorded": "recorded frames", "live": "a live camera",
         "played": "frames played as a live camera's (input.play)"}  # a rig's cameras are all of one kind


class RigSection(Node):
    """How the cameras of a rig (`cameras:`) are put together."""

    tolerance: Num | None = Field(None, gt=0, description=(
        "seconds: a recording's frame is paired with the first camera's nearest frame within this (a live "
        "camera's by when it arrived), else that camera has no frame there (inferred from the others); null: "
        "half the first camera's frame period, 1 / (2 input.fps) (a live camera's own rate)"))


class RigCamera(Node):
    """One camera of a rig: its name (outputs and errors use it), its frames and its camera."""

    name: Str = Field(description="the camera's name: letters, digits, - and _, unique in the rig")
    input: InputSection = Field(description="the camera's frames and background: the keys of `input` above")
    camera: CameraSection | Str | None = Field(None, description=(
        "the camera: the keys of `camera` above, or a camera file; left out: the recording's"))


def rig_key(index: int, message: str) -> str:
    """A camera's error (`input.frames: ...`, `camera.width: ...`) said of `cameras[index]`."""
    for section in PER_CAMERA:
        if message.startswith(section + ".") or message.startswith(section + ":"):
            return f"cameras[{index}].{message}"
    return message


def rig_items(raw: dict) -> tuple[list[str], list[dict]]:
    """(names, one single-camera mapping a camera: the shared sections with the camera's input and
    camera) of a config mapping with `cameras:`; with several cameras, `object.width` left out is
    RIG_WIDTH. One-line errors for a list that is not one, an item without a name or input, names
    that repeat, `cameras:` beside a top-level input or camera, cameras of different KINDS, and
    one live camera twice."""
    cams = raw["cameras"]
    if not isinstance(cams, list) or not cams:
        found = "an empty list" if isinstance(cams, list) else _fmt(cams)
        raise ConfigError(f"cameras: expected a list of cameras, each {{name, input, camera}}, found {found}")
    both = [s for s in PER_CAMERA if s in raw]
    if both:
        raise ConfigError(f"cameras: expected either a cameras: list or a single {' and '.join(PER_CAMERA)}, found "
                          f"cameras: and a top-level {both[0]}: (move it into each camera)")
    shared = {k: v for k, v in raw.items() if k not in ("cameras", "rig")}
    obj = shared.get("object")
    if len(cams) > 1 and (obj is None or isinstance(obj, dict) and "width" not in obj):
        shared["object"] = {**(obj or {}), "width": RIG_WIDTH}
    names, singles, kinds = [], [], []
    for i, item in enumerate(cams):
        if not isinstance(item, dict):
            raise ConfigError(f"cameras[{i}]: expected a mapping {{name, input, camera}}, found {_fmt(item)}")
        extra = sorted(set(item) - {"name", *PER_CAMERA})
        if extra:
            raise ConfigError(f"cameras[{i}]: unknown key {extra[0]!r}; expected name, input and camera")
        name = item.get("name")
        if not isinstance(name, str) or not NAME.match(name):
            raise ConfigError(f"cameras[{i}].name: expected a name of letters, digits, - and _, found {_fmt(name)}")
        if name in names:
            raise ConfigError(f"cameras[{i}].name: expected a name unlike the other cameras', found {name!r} "
                              f"again (cameras[{names.index(name)}])")
        if "input" not in item:
            raise ConfigError(f"cameras[{i}].input: required key is missing (the camera's frames)")
        inp = item["input"] if isinstance(item["input"], dict) else {}
        kinds.append("played" if inp.get("play") is True else
                     "live" if isinstance(inp.get("frames"), str) and is_live(inp["frames"]) else "recorded")
        if kinds[i] != kinds[0]:
            key = "play" if "played" in (kinds[i], kinds[0]) else "frames"
            raise ConfigError(f"cameras[{i}].input.{key}: expected {KINDS[kinds[0]]} as cameras[0]'s (a rig is live, "
                              f"played or recorded), found {KINDS[kinds[i]]}")
        same = [j for j, other in enumerate(cams[:i])
                if kinds[i] == "live" and other["input"].get("frames") == inp["frames"]]
        if same:
            raise ConfigError(f"cameras[{i}].input.frames: expected another camera than cameras[{same[0]}]'s, found "
                              f"{inp['frames']} again (name each by its serial: realsense:SERIAL)")
        names.append(name)
        singles.append({**shared, "input": item["input"], **({"camera": item["camera"]} if "camera" in item else {})})
    return names, singles


def parse_rig(raw: dict, single):
    """A rig's config (`cameras:`): each camera validated by `single` (a mapping to a RunConfig:
    run.parse_config, or loading's, which fills camera keys in first) as a single-camera config of
    the shared sections with its own input and camera (errors naming `cameras[i]`), then what the
    cameras must share: one inference stride and reduction (one engine), one kind of frames (live,
    played or recorded: rig_items). The RunConfig's inputs and camera are the first camera's; `cameras`
    holds each camera's own."""

    names, singles = rig_items(raw)
    members = []
    for i, one in enumerate(singles):
        try:
            members.append(single(one))
        except ConfigError as e:
            raise ConfigError(rig_key(i, str(e))) from None
    first = members[0]
    for i, m in enumerate(members):
        for key in ("stride", "reduce"):
            if getattr(m.inputs, key) != getattr(first.inputs, key):
                raise ConfigError(f"cameras[{i}].input.{key}: expected cameras[0]'s {getattr(first.inputs, key)!r} (a "
                                  f"rig is inferred at one resolution), found {getattr(m.inputs, key)!r}")
        if not m.pose_auto and m.camera.centre[2] <= 0:
            raise ConfigError(f"cameras[{i}].camera.extrinsics: expected a pose above the floor (z = 0), found the "
                              f"camera {-m.camera.centre[2]:.2f} m {'under' if m.camera.centre[2] < 0 else 'on'} it")
    try:
        rig = RigSection.model_validate(raw.get("rig"))
    except ValidationError as e:
        raise ConfigError(f"rig.{_first_error(e)}") from None
    shared = {k: v for k, v in first.resolved.items() if k not in ("device", "input", "camera")}
    resolved = {"device": first.resolved["device"],
                "cameras": [{"name": n, "input": m.resolved["input"], "camera": m.resolved["camera"]}
                            for n, m in zip(names, members)],
                "rig": rig.model_dump(), **shared}
    return dataclasses.replace(first, cameras=tuple(zip(names, members)), rig=rig, resolved=resolved)

"""A config file read into a mapping: YAML, `--set` overrides, relative paths joined to the
file's folder, and the camera keys a camera file (`camera.file`) gives."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import yaml
from pydantic import ValidationError

from ..names import is_live
from .camera import CameraFile
from .schema import path_keys
from ..values import ConfigError, _first_error, _fmt, _read_yaml


def camera_shorthand(raw: dict) -> dict:
    """`camera: FILE` is `camera: {file: FILE}`."""
    if isinstance(raw, dict) and isinstance(raw.get("camera"), str):
        return {**raw, "camera": {"file": raw["camera"]}}
    return raw


def camera_from_file(raw: dict) -> dict:
    """A config with camera.file, with the keys it leaves out (camera.width, height,
    intrinsics or some of fx, fy, cx, cy, distortion, input.depth_scale) taken from that camera
    file (the config's own keys win)."""
    cam = raw.get("camera")
    if not isinstance(cam, dict) or not isinstance(cam.get("file"), str):
        return raw
    path = Path(cam["file"])
    try:
        c = CameraFile.model_validate(_read_yaml(path, "camera file (camera.file)"))
    except ValidationError as e:
        raise ConfigError(f"camera.file: {path}: {_first_error(e)}") from None
    out = copy.deepcopy(raw)
    cam, given = out["camera"], c.model_dump(exclude_none=True)
    for key in ("width", "height", "intrinsics", "distortion"):
        if key not in cam and key in given:
            cam[key] = given[key]
    if isinstance(cam["intrinsics"], dict):  # camera.intrinsics.fx alone changes fx alone
        cam["intrinsics"] = {**given["intrinsics"], **cam["intrinsics"]}
    inp = out.get("input")
    if isinstance(inp, dict) and "depth_scale" not in inp:
        inp["depth_scale"] = c.depth_scale
    return out


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `key.path=value` overrides (value parsed as YAML) to a copy of `raw`; on a rig
    (`cameras:`), `input.KEY` is every camera's (`cameras.N.input.KEY` one camera's)."""
    out = copy.deepcopy(raw) if raw else {}
    for item in overrides or []:
        if "=" not in item:
            raise ConfigError(f"--set {item}: expected key.path=value")
        path, value = item.split("=", 1)
        keys = path.strip().split(".")
        if keys[0] == "input" and isinstance(out.get("cameras"), list) and "input" not in out:
            # a rig's input keys are its cameras': input.KEY sets every camera's (--play, --set)
            out = apply_overrides(out, [f"cameras.{i}.{path.strip()}={value}" for i in range(len(out["cameras"]))])
            continue
        node = out
        for k in keys[:-1]:
            if isinstance(node, list):  # a rig's camera by its index: cameras.1.input.frames
                node = _list_item(node, k, path)
                continue
            if not isinstance(node.get(k), (dict, list)):
                node[k] = {} if node.get(k) is None else node[k]
                if not isinstance(node[k], dict):
                    raise ConfigError(f"--set {path}: {k} is not a mapping")
            node = node[k]
        try:
            parsed = yaml.safe_load(value)
        except yaml.YAMLError as e:
            raise ConfigError(f"--set {path}: value is not valid YAML ({e.problem})") from None
        if isinstance(node, list):
            _list_item(node, keys[-1], path)
            node[int(keys[-1])] = parsed
        else:
            node[keys[-1]] = parsed
    return out


def _list_item(items: list, key: str, path: str):
    """items[int(key)] of an override's path, else a one-line error."""
    if not key.isdigit() or int(key) >= len(items):
        raise ConfigError(f"--set {path}: expected an index below {len(items)} for the list, found {key!r}")
    return items[int(key)]


def resolve_paths(raw: dict, base: str | Path) -> dict:
    """A copy of `raw` whose relative path values (path_keys) are joined to `base`, the config
    file's folder (normalised, so a config in configs/ naming ../x gives x); `auto` and a live
    camera (`realsense[:SERIAL]`) are not paths."""
    out = copy.deepcopy(camera_shorthand(raw))
    for key in path_keys():
        *parents, last = key.split(".")
        node = out
        for p in parents:
            node = node.get(p) if isinstance(node, dict) else None
        if not isinstance(node, dict):
            continue
        v = node.get(last)
        if (isinstance(v, str) and v not in ("auto", "-") and not is_live(v)
                and not os.path.isabs(os.path.expanduser(v))):
            node[last] = os.path.normpath(os.path.join(base, v))
    if isinstance(out.get("cameras"), list):  # a rig: each camera's input and camera sections too
        out["cameras"] = [{**item, **{k: v for k, v in resolve_paths(
            {k: item[k] for k in ("input", "camera") if k in item}, base).items()}}
            if isinstance(item, dict) else item for item in out["cameras"]]
    return out


def read_config(path: str | Path) -> dict:
    """A config file's mapping, its relative paths made relative to the current folder."""
    path = Path(path)
    raw = _read_yaml(path, "config file")
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a YAML mapping at the top, found {_fmt(raw)}")
    return resolve_paths(raw, path.parent)

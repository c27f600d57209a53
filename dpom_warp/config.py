"""Run configuration: YAML validated once, at the edge, into typed objects.

Every error is one line naming the key, what was expected and what was found.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .geometry import Camera, Grid, ObjectBox, pose_from_angles
from .ground import GroundOptions
from .model import AutoBackground, ModelParams
from .resolution import REDUCERS
from .synthetic import SceneSpec


class ConfigError(ValueError):
    """Invalid configuration; str(e) is one line naming the key."""


def _fmt(v):
    return repr(v) if not isinstance(v, (dict, list)) else type(v).__name__


class _Section:
    """Reads one mapping of the config, remembering the keys used so unknown ones are errors."""

    def __init__(self, raw, path: str):
        if raw is None:
            raw = {}
        if not isinstance(raw, dict):
            raise ConfigError(f"{path or 'config'}: expected a mapping, found {_fmt(raw)}")
        self.raw, self.path, self.used = raw, path, set()

    def key(self, name):
        return f"{self.path}.{name}" if self.path else name

    def get(self, name, default=None, required=False):
        self.used.add(name)
        v = self.raw.get(name)
        if v is None:
            if required:
                raise ConfigError(f"{self.key(name)}: required key is missing")
            return default
        return v

    def section(self, name) -> "_Section":
        return _Section(self.get(name), self.key(name))

    def number(self, name, default=None, *, lo=None, hi=None, lo_open=False, hi_open=False,
               integer=False, required=False):
        v = self.get(name, default, required)
        if v is None:
            return None
        if isinstance(v, str) and not integer:  # YAML 1.1 reads 1e-3 (no dot) as a string
            try:
                v = float(v) if np.isfinite(float(v)) else v
            except ValueError:
                pass
        ok_type = isinstance(v, int) if integer else isinstance(v, (int, float))
        if isinstance(v, bool) or not ok_type:
            kind = "an integer" if integer else "a number"
            raise ConfigError(f"{self.key(name)}: expected {kind}, found {_fmt(v)}")
        check_range(self.key(name), v, lo, hi, lo_open, hi_open)
        return int(v) if integer else float(v)

    def string(self, name, default=None, required=False, choices=None, nullable=False):
        v = self.get(name, default, required)
        if v is None and (nullable or default is None):
            return None
        if not isinstance(v, str):
            raise ConfigError(f"{self.key(name)}: expected a string, found {_fmt(v)}")
        if choices and v not in choices:
            raise ConfigError(f"{self.key(name)}: expected one of {', '.join(choices)}, found {v!r}")
        return v

    def boolean(self, name, default):
        v = self.get(name, default)
        if not isinstance(v, bool):
            raise ConfigError(f"{self.key(name)}: expected true or false, found {_fmt(v)}")
        return v

    def numbers(self, name, n, default=None, required=False):
        v = self.get(name, default, required)
        if v is None:
            return None
        if (not isinstance(v, (list, tuple)) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            raise ConfigError(f"{self.key(name)}: expected a list of {n} numbers, found {_fmt(v)}"
                              + (f" of length {len(v)}" if isinstance(v, list) else ""))
        return tuple(float(x) for x in v)

    def done(self):
        unknown = sorted(set(self.raw) - self.used)
        if unknown:
            raise ConfigError(f"{self.key(unknown[0])}: unknown key (expected one of "
                              f"{', '.join(sorted(self.used))})")


def check_device(device: str, key: str = "device") -> str:
    if device not in ("auto", "cpu", "cuda") and not (device.startswith("cuda:") and device[5:].isdigit()):
        raise ConfigError(f"{key}: expected auto, cpu, cuda or cuda:N, found {device!r}")
    return device


def check_range(key, v, lo=None, hi=None, lo_open=False, hi_open=False):
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ConfigError(f"{key}: expected a value {'>' if lo_open else '>='} {lo}, found {v!r}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ConfigError(f"{key}: expected a value {'<' if hi_open else '<='} {hi}, found {v!r}")


@dataclass(frozen=True)
class Detection:
    threshold: float = 0.5
    nms_radius: float = 0.4


@dataclass(frozen=True)
class Evaluation:
    ground_truth: str | None = None
    match_distance: float = 0.5
    hidden_visibility: float = 0.1
    plots: bool = False


@dataclass(frozen=True)
class Inputs:
    frames: str
    background: str | None = None
    depth_scale: float = 0.001
    stride: int | str = "auto"  # "auto" or an integer >= 1 (dpom_warp.resolution)
    reduce: str = "median"
    background_auto: AutoBackground = AutoBackground()  # for background: auto

    @property
    def auto_background(self) -> bool:
        return self.background == "auto"


@dataclass(frozen=True)
class Output:
    dir: str = "runs/out"
    images: bool = True
    ply: bool = False


@dataclass(frozen=True)
class EngineOptions:
    entries_per_pixel: float = 8.0
    max_entries: int | None = None
    memory_gb: float | None = 8.0
    batch: int = 1
    graph: str = "auto"
    exact: bool = False


@dataclass
class RunConfig:
    """A validated run configuration; `resolved` is the config with every default filled in.

    With `pose_auto` (camera.extrinsics: auto) the camera's pose is a placeholder until the
    run fits the floor with `ground` options on `ground_frames` frames.
    """

    device: str
    inputs: Inputs
    camera: Camera
    grid: Grid
    obj: ObjectBox
    model: ModelParams
    detection: Detection
    evaluation: Evaluation
    output: Output
    engine: EngineOptions
    synthetic: SceneSpec | None
    synthetic_cache: str | None
    resolved: dict
    pose_auto: bool = False
    ground: GroundOptions = GroundOptions()
    ground_frames: int = 5


def _axis(sec: _Section, name, required=True):
    v = sec.numbers(name, 3, required=required)
    if v is None:
        return None
    lo, hi, step = v
    if step <= 0:
        raise ConfigError(f"{sec.key(name)}: expected a step > 0 in [min, max, step], found {step!r}")
    if lo >= hi:
        raise ConfigError(f"{sec.key(name)}: expected min < max in [min, max, step], found {lo!r} >= {hi!r}")
    return v


FIT_REPORT_KEYS = ("camera_height", "pitch_deg", "roll_deg", "inlier_count")


def _pose(sec: _Section):
    if "T_world_from_camera" in sec.raw:
        t = sec.get("T_world_from_camera")
        if not (isinstance(t, list) and len(t) == 4 and all(
                isinstance(row, list) and len(row) == 4
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in row)
                for row in t)):
            raise ConfigError(f"{sec.key('T_world_from_camera')}: expected a 4x4 list of numbers, "
                              f"found {_fmt(t)}")
        sec.used.update(FIT_REPORT_KEYS)  # `dpom-warp fit-ground` output pastes in as it is
        m = np.array(t, dtype=np.float64)
        r = m[:3, :3]
        if (not np.allclose(r.T @ r, np.eye(3), atol=1e-3) or abs(np.linalg.det(r) - 1) > 1e-3
                or not np.allclose(m[3], [0, 0, 0, 1])):
            raise ConfigError(f"{sec.key('T_world_from_camera')}: expected a rigid transform "
                              f"(orthonormal rotation, last row 0 0 0 1), found a matrix that is not")
        sec.done()
        return m, {"T_world_from_camera": m.tolist()}
    h = sec.number("height", required=True, lo=0, lo_open=True)
    pitch = sec.number("pitch_deg", 0.0, lo=-90, hi=90)
    roll = sec.number("roll_deg", 0.0, lo=-180, hi=180)
    yaw = sec.number("yaw_deg", 0.0, lo=-360, hi=360)
    x, y = sec.number("x", 0.0), sec.number("y", 0.0)
    sec.done()
    m = pose_from_angles(h, pitch, roll, yaw, x, y)
    return m, {"height": h, "pitch_deg": pitch, "roll_deg": roll, "yaw_deg": yaw, "x": x, "y": y}


def parse_config(raw: dict[str, Any]) -> RunConfig:
    """Validate a config mapping (as loaded from YAML) into a RunConfig."""
    top = _Section(raw, "")
    device = check_device(top.string("device", "auto"))

    s = top.section("input")
    stride = s.get("stride", "auto")
    if isinstance(stride, str) and stride != "auto":
        raise ConfigError(f"input.stride: expected auto or an integer >= 1, found {stride!r}")
    if stride != "auto":
        stride = s.number("stride", integer=True, lo=1, hi=64)
    a = s.section("background_auto")
    d = AutoBackground()
    auto = AutoBackground(max_frames=a.number("max_frames", d.max_frames, integer=True, lo=1),
                          min_frames=a.number("min_frames", d.min_frames, integer=True, lo=1),
                          min_share=a.number("min_share", d.min_share, lo=0, hi=1, lo_open=True),
                          slots=a.number("slots", d.slots, integer=True, lo=1, hi=16),
                          cluster_sigmas=a.number("cluster_sigmas", d.cluster_sigmas, lo=0),
                          cluster_floor=a.number("cluster_floor", d.cluster_floor, lo=0))
    a.done()
    if auto.min_frames > auto.max_frames:
        raise ConfigError(f"input.background_auto.min_frames: expected at most max_frames "
                          f"({auto.max_frames}), found {auto.min_frames}")
    inputs = Inputs(frames=s.string("frames", required=True),
                    background=s.string("background", None, nullable=True),
                    depth_scale=s.number("depth_scale", 0.001, lo=0, lo_open=True),
                    stride=stride,
                    reduce=s.string("reduce", "median", choices=REDUCERS),
                    background_auto=auto)
    s.done()

    s = top.section("camera")
    width = s.number("width", required=True, integer=True, lo=1)
    height = s.number("height", required=True, integer=True, lo=1)
    i = s.section("intrinsics")
    fx = i.number("fx", required=True, lo=0, lo_open=True)
    fy = i.number("fy", required=True, lo=0, lo_open=True)
    cx = i.number("cx", required=True, lo=0, hi=width)
    cy = i.number("cy", required=True, lo=0, hi=height)
    i.done()
    ext = s.get("extrinsics", required=True)
    pose_auto = ext == "auto"
    if pose_auto:
        pose, pose_resolved = np.eye(4), "auto"
    elif isinstance(ext, str):
        raise ConfigError(f"camera.extrinsics: expected auto, {{T_world_from_camera: 4x4}} or "
                          f"{{height, pitch_deg, roll_deg}}, found {ext!r}")
    else:
        pose, pose_resolved = _pose(_Section(ext, "camera.extrinsics"))
    distortion = s.numbers("distortion", 5, None)
    g = s.section("ground")
    d = GroundOptions()
    ground = GroundOptions(
        up=g.numbers("up", 3, d.up),
        max_angle_deg=g.number("max_angle_deg", d.max_angle_deg, lo=0, hi=90, lo_open=True),
        distance_threshold=g.number("distance_threshold", d.distance_threshold, lo=0, lo_open=True),
        depth_max=g.number("depth_max", d.depth_max, lo=0, lo_open=True),
        min_inliers=g.number("min_inliers", d.min_inliers, integer=True, lo=3),
        stride=g.number("stride", d.stride, integer=True, lo=1),
        max_planes=g.number("max_planes", d.max_planes, integer=True, lo=1),
        voxel=g.number("voxel", d.voxel, lo=0, lo_open=True),
        noise=g.numbers("noise", 2, d.noise),
    )
    ground_frames = g.number("frames", 5, integer=True, lo=1)
    if np.linalg.norm(ground.up) == 0:
        raise ConfigError(f"camera.ground.up: expected a non-zero direction, found {list(ground.up)}")
    g.done()
    s.done()
    camera = Camera(width, height, fx, fy, cx, cy, pose, distortion)

    s = top.section("grid")
    mode = s.string("mode", "ground", choices=("ground", "voxel"))
    x_axis, y_axis = _axis(s, "x"), _axis(s, "y")
    z_axis = _axis(s, "z", required=mode == "voxel")
    if mode == "ground" and z_axis is not None:
        raise ConfigError("grid.z: expected no z axis in ground mode (objects stand on the floor); "
                          "use mode: voxel for a 3D grid")
    grid = Grid(x=x_axis, y=y_axis, mode=mode, z=z_axis)
    s.done()

    s = top.section("object")
    obj = ObjectBox(width=s.number("width", 0.5, lo=0, lo_open=True),
                    height=s.number("height", 1.8, lo=0, lo_open=True),
                    depth=s.number("depth", None, lo=0, lo_open=True))
    s.done()
    sizes = [("x", "width", obj.width), ("y", "depth" if obj.depth else "width", obj.depth or obj.width)]
    if mode == "voxel":
        sizes.append(("z", "height", obj.height))
    for axis, key, size in sizes:
        lo, hi, _ = getattr(grid, axis)
        if size > hi - lo:
            raise ConfigError(f"object.{key}: expected at most the grid's {axis} extent "
                              f"{hi - lo:g} m, found {size:g}")

    s = top.section("model")
    d = ModelParams()
    model = ModelParams(
        prior=s.number("prior", d.prior, lo=0, hi=1, lo_open=True, hi_open=True),
        sigma_object=s.number("sigma_object", d.sigma_object, lo=0, lo_open=True),
        sensor_noise=s.numbers("sensor_noise", 2, d.sensor_noise),
        outlier_prob=s.number("outlier_prob", d.outlier_prob, lo=0, hi=1, lo_open=True, hi_open=True),
        missing_prob=s.number("missing_prob", d.missing_prob, lo=0, hi=1, hi_open=True),
        z_max=s.number("z_max", d.z_max, lo=0, lo_open=True),
        alpha=s.number("alpha", d.alpha),
        beta=s.number("beta", d.beta),
        damping=s.number("damping", d.damping, lo=0, hi=1, lo_open=True),
        damping_growth=s.number("damping_growth", d.damping_growth, lo=1),
        damping_max=s.number("damping_max", None, lo=0, hi=1, lo_open=True),
        tolerance=s.number("tolerance", d.tolerance, lo=0, lo_open=True),
        max_iterations=s.number("max_iterations", d.max_iterations, integer=True, lo=1),
        check_every=s.number("check_every", d.check_every, integer=True, lo=1),
        missing_clip=s.number("missing_clip", d.missing_clip, lo=0, hi=0.5, lo_open=True, hi_open=True),
        background_outside_grid=s.boolean("background_outside_grid", d.background_outside_grid),
        background_occludes=s.boolean("background_occludes", d.background_occludes),
        occlusion_margin=s.number("occlusion_margin", d.occlusion_margin, lo=0),
        sparse_epsilon=s.number("sparse_epsilon", d.sparse_epsilon, lo=0, hi=0.5),
        warm_start=s.boolean("warm_start", d.warm_start),
        top_support=s.number("top_support", d.top_support, lo=0, hi=1),
        top_band=s.number("top_band", d.top_band, lo=0, hi=1, hi_open=True),
        top_hidden=s.number("top_hidden", d.top_hidden, lo=0, hi=1),
        top_slope=s.number("top_slope", d.top_slope, lo=0, lo_open=True),
        top_min_pixels=s.number("top_min_pixels", d.top_min_pixels, integer=True, lo=1),
    )
    if "damping_max" not in s.raw:  # default cap, never below the starting damping
        model = dataclasses.replace(model, damping_max=max(d.damping_max, model.damping))
    if model.damping_max < model.damping:
        raise ConfigError(f"model.damping_max: expected at least model.damping "
                          f"({model.damping}), found {model.damping_max}")
    if min(model.sensor_noise) < 0:
        raise ConfigError(f"model.sensor_noise: expected [a, b] >= 0, found {list(model.sensor_noise)}")
    s.done()

    s = top.section("detection")
    detection = Detection(threshold=s.number("threshold", 0.5, lo=0, hi=1, lo_open=True, hi_open=True),
                          nms_radius=s.number("nms_radius", 0.4, lo=0))
    s.done()

    s = top.section("evaluation")
    evaluation = Evaluation(ground_truth=s.string("ground_truth", None, nullable=True),
                            match_distance=s.number("match_distance", 0.5, lo=0, lo_open=True),
                            hidden_visibility=s.number("hidden_visibility", 0.1, lo=0, hi=1),
                            plots=s.boolean("plots", False))
    s.done()

    s = top.section("output")
    output = Output(dir=s.string("dir", "runs/out"), images=s.boolean("images", True),
                    ply=s.boolean("ply", False))
    s.done()

    s = top.section("engine")
    engine = EngineOptions(entries_per_pixel=s.number("entries_per_pixel", 8.0, lo=0, lo_open=True),
                           max_entries=s.number("max_entries", None, integer=True, lo=1),
                           memory_gb=s.number("memory_gb", 8.0, lo=0, lo_open=True),
                           batch=s.number("batch", 1, integer=True, lo=1),
                           graph=s.string("graph", "auto", choices=("auto", "on", "off")),
                           exact=s.boolean("exact", False))
    s.done()
    if engine.exact:  # the exact path: full resolution, every pass full, no warm start
        inputs = dataclasses.replace(inputs, stride=1)
        model = dataclasses.replace(model, sparse_epsilon=0.0, warm_start=False)

    synthetic, cache = None, None
    if top.get("synthetic") is not None and pose_auto:
        raise ConfigError("synthetic: rendering needs a camera pose; expected camera.extrinsics "
                          "given as {height, pitch_deg, ...} or a matrix, found auto")
    if top.get("synthetic") is not None:
        s = top.section("synthetic")
        d = SceneSpec()
        cache = s.string("cache", required=True)
        synthetic = SceneSpec(
            seed=s.number("seed", d.seed, integer=True, lo=0),
            frames=s.number("frames", d.frames, integer=True, lo=1),
            background_frames=s.number("background_frames", d.background_frames, integer=True, lo=0),
            people=s.number("people", d.people, integer=True, lo=0),
            kind=s.string("kind", d.kind, choices=("people", "drones")),
            area=s.numbers("area", 4, d.area),
            altitude=s.numbers("altitude", 2, d.altitude),
            obstacles=s.number("obstacles", d.obstacles, integer=True, lo=0),
            room=s.numbers("room", 5, d.room),
            furniture=s.number("furniture", d.furniture, integer=True, lo=0),
            step_m=s.number("step_m", d.step_m, lo=0),
            pair_gap=s.number("pair_gap", d.pair_gap, lo=0),
            noise=s.numbers("noise", 2, d.noise),
            dropout=s.number("dropout", d.dropout, lo=0, hi=1),
            edge_holes=s.number("edge_holes", d.edge_holes, lo=0, hi=1),
            range_m=s.numbers("range_m", 2, d.range_m),
        )
        s.done()
    top.done()

    resolved = {
        "device": device,
        "input": {**vars_of(inputs), "background_auto": vars_of(inputs.background_auto)},
        "camera": {"width": width, "height": height,
                   "intrinsics": {"fx": fx, "fy": fy, "cx": cx, "cy": cy},
                   "extrinsics": pose_resolved, "distortion": list(distortion) if distortion else None,
                   "ground": {"frames": ground_frames, **{k: (list(v) if isinstance(v, tuple) else v)
                                                          for k, v in vars_of(ground).items()}}},
        "grid": {"mode": mode, "x": list(grid.x), "y": list(grid.y),
                 **({"z": list(grid.z)} if grid.z else {})},
        "object": {"width": obj.width, "height": obj.height, "depth": obj.depth},
        "model": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars_of(model).items()},
        "detection": vars_of(detection), "evaluation": vars_of(evaluation),
        "output": vars_of(output), "engine": vars_of(engine),
    }
    if synthetic is not None:
        resolved["synthetic"] = {"cache": cache, **{k: (list(v) if isinstance(v, tuple) else v)
                                                    for k, v in vars_of(synthetic).items()}}
    return RunConfig(device, inputs, camera, grid, obj, model, detection, evaluation, output,
                     engine, synthetic, cache, resolved, pose_auto, ground, ground_frames)


def vars_of(dc) -> dict:
    return {f.name: getattr(dc, f.name) for f in fields(dc)}


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `key.path=value` overrides (value parsed as YAML) to a copy of `raw`."""
    out = copy.deepcopy(raw) if raw else {}
    for item in overrides or []:
        if "=" not in item:
            raise ConfigError(f"--set {item}: expected key.path=value")
        path, value = item.split("=", 1)
        keys = path.strip().split(".")
        node = out
        for k in keys[:-1]:
            if not isinstance(node.get(k), dict):
                node[k] = {} if node.get(k) is None else node[k]
                if not isinstance(node[k], dict):
                    raise ConfigError(f"--set {path}: {k} is not a mapping")
            node = node[k]
        try:
            node[keys[-1]] = yaml.safe_load(value)
        except yaml.YAMLError as e:
            raise ConfigError(f"--set {path}: value is not valid YAML ({e.problem})") from None
    return out


def _read_yaml(path: Path, what: str):
    if not path.is_file():
        raise ConfigError(f"{path}: no such {what}")
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}: not valid YAML{where} ({getattr(e, 'problem', e)})") from None


def load_config(path: str | Path, overrides: list[str] | None = None) -> RunConfig:
    """Read, override and validate a YAML run config."""
    path = Path(path)
    raw = _read_yaml(path, "config file")
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a YAML mapping at the top, found {_fmt(raw)}")
    try:
        return parse_config(apply_overrides(raw, overrides or []))
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def load_camera_file(path: str | Path) -> tuple[Camera, float]:
    """Read a camera file (width, height, intrinsics {fx, fy, cx, cy}, depth_scale, optional
    distortion [k1, k2, p1, p2, k3]) as in shared/data/real/*/camera.yaml.

    Returns:
        (camera with identity pose, depth_scale in metres per unit).
    """
    path = Path(path)
    raw = _read_yaml(path, "camera file")
    try:
        s = _Section(raw, "")
        width = s.number("width", required=True, integer=True, lo=1)
        height = s.number("height", required=True, integer=True, lo=1)
        i = s.section("intrinsics")
        cam = Camera(width, height, i.number("fx", required=True, lo=0, lo_open=True),
                     i.number("fy", required=True, lo=0, lo_open=True),
                     i.number("cx", required=True, lo=0, hi=width),
                     i.number("cy", required=True, lo=0, hi=height),
                     distortion=s.numbers("distortion", 5, None))
        i.done()
        scale = s.number("depth_scale", 0.001, lo=0, lo_open=True)
        s.done()
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None
    return cam, scale

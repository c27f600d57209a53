"""Run configuration: YAML validated once, at the edge, into typed objects.

The config's form is a tree of pydantic models (`ConfigFile` and its sections): one source
for validation, defaults, the JSON Schema that editors use (`dpom-warp schema`) and the
README's config reference (`python -m bench.docs`). Every error is one line naming the key,
what was expected and what was found. Relative paths in a config file are relative to the
file's folder; those given with `--set` (or in a mapping) to the current folder.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import os
import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
import yaml
from pydantic import (BaseModel, BeforeValidator, ConfigDict, Discriminator, Field, Tag,
                      ValidationError, model_validator)
from pydantic_core import PydanticCustomError

from .detect import EDGE_RADIUS, MIN_LOG_ODDS
from .geometry import Camera, Grid, ObjectBox, pose_from_angles
from .ground import GroundOptions
from .model import BEHIND_COST, EXACT_BETA, TOP_SHORTER, AutoBackground, ModelParams
from .names import is_live
from .resolution import REDUCERS
from .synthetic import SceneSpec
from .tracking import TrackingOptions


class ConfigError(ValueError):
    """Invalid configuration; str(e) is one line naming the key."""


def _fmt(v):
    return repr(v) if not isinstance(v, (dict, list, tuple)) else type(v).__name__


def _fail(message: str, key: str = "") -> PydanticCustomError:
    """An error with our own message; `key` (dotted) is appended to the error's location."""
    return PydanticCustomError("dpom", message, {"key": key}) if key else PydanticCustomError("dpom", message)


# -- value types: each checks its input and says what it expected ------------------------------
def _number(v):
    if isinstance(v, str):  # YAML 1.1 reads 1e-3 (no dot) as a string
        try:
            if np.isfinite(float(v)):
                return float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _fail(f"expected a number, found {_fmt(v)}")
    return v


def _integer(v):
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected an integer, found {_fmt(v)}")
    return v


def _boolean(v):
    if not isinstance(v, bool):
        raise _fail(f"expected true or false, found {_fmt(v)}")
    return v


def _string(v):
    if not isinstance(v, str):
        raise _fail(f"expected a string, found {_fmt(v)}")
    return v


def _numbers(n: int):
    def check(v):
        if (not isinstance(v, (list, tuple)) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            raise _fail(f"expected a list of {n} numbers, found {_fmt(v)}"
                        + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
        return tuple(float(x) for x in v)
    return BeforeValidator(check)


def _lens(v):
    """OpenCV's distortion: [k1, k2, p1, p2, k3] or the rational [k1, k2, p1, p2, k3, k4, k5, k6]."""
    if (not isinstance(v, (list, tuple)) or len(v) not in (5, 8)
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise _fail(f"expected a list of 5 or 8 numbers, found {_fmt(v)}"
                    + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
    return tuple(float(x) for x in v)


Lens = Annotated[tuple[float, ...], BeforeValidator(_lens)]


def _heights(v):
    """A list of heights in metres, each > 0 (model.top_heights)."""
    if (not isinstance(v, (list, tuple))
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0 for x in v)):
        found = list(v) if isinstance(v, (list, tuple)) else _fmt(v)
        raise _fail(f"expected a list of heights > 0 (metres), found {found}")
    return tuple(float(x) for x in v)


Heights = Annotated[tuple[float, ...], BeforeValidator(_heights)]


class PathValue:
    """Marks a config value that is a file, folder or glob: relative to the config's folder."""


Num = Annotated[float, BeforeValidator(_number)]
Int = Annotated[int, BeforeValidator(_integer)]
Bool = Annotated[bool, BeforeValidator(_boolean)]
Str = Annotated[str, BeforeValidator(_string)]
FilePath = Annotated[str, BeforeValidator(_string), PathValue()]
Pair = Annotated[tuple[float, float], _numbers(2)]
Triple = Annotated[tuple[float, float, float], _numbers(3)]


def _axis(v):
    lo, hi, step = _numbers(3).func(v)
    if step <= 0:
        raise _fail(f"expected a step > 0 in [min, max, step], found {step!r}")
    if lo >= hi:
        raise _fail(f"expected min < max in [min, max, step], found {lo!r} >= {hi!r}")
    return lo, hi, step


Axis = Annotated[tuple[float, float, float], BeforeValidator(_axis)]


def check_device(device: str, key: str = "device") -> str:
    if device not in ("auto", "cpu", "cuda") and not (device.startswith("cuda:") and device[5:].isdigit()):
        raise ConfigError(f"{key}: expected auto, cpu, cuda or cuda:N, found {device!r}")
    return device


def _device(v):
    try:
        return check_device(_string(v))
    except ConfigError:
        raise _fail(f"expected auto, cpu, cuda or cuda:N, found {v!r}") from None


Device = Annotated[str, BeforeValidator(_device), Field(pattern=r"^(auto|cpu|cuda(:[0-9]+)?)$")]


def _stride(v):
    if v == "auto":
        return v
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected auto or an integer >= 1, found {_fmt(v)}")
    if not 1 <= v <= 64:
        raise _fail(f"expected a value {'>= 1' if v < 1 else '<= 64'}, found {v}")
    return v


Stride = Annotated[Union[Literal["auto"], Annotated[int, Field(ge=1, le=64)]], BeforeValidator(_stride)]


def _batch(v):
    if v == "auto":
        return v
    if isinstance(v, bool) or not isinstance(v, int):
        raise _fail(f"expected auto or an integer >= 1, found {_fmt(v)}")
    if v < 1:
        raise _fail(f"expected a value >= 1, found {v}")
    return v


Batch = Annotated[Union[Literal["auto"], Annotated[int, Field(ge=1)]], BeforeValidator(_batch)]


def _up(v):
    if v == "auto":
        return v
    if (not isinstance(v, (list, tuple)) or len(v) != 3
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise _fail(f"expected auto or a list of 3 numbers, found {_fmt(v)}"
                    + (f" of length {len(v)}" if isinstance(v, (list, tuple)) else ""))
    return tuple(float(x) for x in v)


Up = Annotated[Union[Literal["auto"], tuple[float, float, float]], BeforeValidator(_up)]


# -- the sections -------------------------------------------------------------------------------
class Node(BaseModel):
    """A mapping of the config: unknown keys are errors that name the closest known key."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _mapping(cls, raw):
        if raw is None:
            return {}
        if not isinstance(raw, dict):
            raise _fail(f"expected a mapping, found {_fmt(raw)}")
        known = list(cls.model_fields)
        for key in raw:
            if key not in known:
                close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
                hint = f"did you mean {close[0]}? " if close else ""
                raise _fail(f"unknown key ({hint}expected one of {', '.join(known)})", str(key))
        return raw


def _d(cls, name):
    """The default of a domain dataclass's field: one place for every default."""
    return next(f.default for f in fields(cls) if f.name == name)


class BackgroundAutoSection(Node):
    """How `input.background: auto` estimates the background from the run's own frames."""

    max_frames: Int = Field(_d(AutoBackground, "max_frames"), ge=1,
                            description="frames used, evenly spread over the sequence")
    min_frames: Int = Field(_d(AutoBackground, "min_frames"), ge=1,
                            description="fewer frames: the floor-only model everywhere")
    min_share: Num = Field(_d(AutoBackground, "min_share"), gt=0, le=1,
                           description="share of the frames a cluster must hold to be the background")
    slots: Int = Field(_d(AutoBackground, "slots"), ge=1, le=16, description="clusters kept per pixel")
    cluster_sigmas: Num = Field(_d(AutoBackground, "cluster_sigmas"), ge=0,
                                description="a reading joins a cluster within cluster_sigmas sensor "
                                            "sigmas + cluster_floor of its mean")
    cluster_floor: Num = Field(_d(AutoBackground, "cluster_floor"), ge=0, description="metres")

    @model_validator(mode="after")
    def _frames(self):
        if self.min_frames > self.max_frames:
            raise _fail(f"expected at most max_frames ({self.max_frames}), found {self.min_frames}",
                        "min_frames")
        return self


class InputSection(Node):
    """The depth frames and the background."""

    frames: FilePath | None = Field(None, description="glob (or folder) of depth frames (16-bit PNG or .npy, "
                                                      "in depth units), processed in sorted order, or a "
                                                      "recording (.bag, .db3, .mcap, a ROS 2 bag folder, "
                                                      ".mkv); required by dpom-warp run")
    background: Union[Literal["auto"], FilePath, None] = Field(
        None, description="glob (or folder) of background frames (no people); auto: estimated from the "
                          "run's own frames; null: the floor-only background")
    depth_scale: Num = Field(0.001, gt=0, description="metres per unit of the files' values; 0 = no "
                                                      "reading (default: the recording's, else 0.001)")
    topic: Str | None = Field(None, description="a recording's depth stream (default: its only one)")
    stride: Stride = Field("auto", description="inference on blocks of stride x stride pixels; auto: the "
                                               "coarsest stride (up to 8) leaving 6 pixels across the "
                                               "object at the farthest cell; pictures, boxes and the "
                                               "floor fit stay at full resolution")
    reduce: Literal[REDUCERS] = Field("median", description="how a block becomes one reading: median "
                                                            "(lower median of its readings), nearest "
                                                            "(one pixel), min")
    fps: Num = Field(15.0, gt=0, description="frames per second of the frames (tracking's speeds)")
    background_auto: BackgroundAutoSection = BackgroundAutoSection()


class Intrinsics(Node):
    """Pinhole intrinsics in pixels, pixel centres at integers."""

    fx: Num = Field(gt=0, description="focal length along x, pixels")
    fy: Num = Field(gt=0, description="focal length along y, pixels")
    cx: Num = Field(ge=0, description="principal point x, pixels (pixel centres at integers)")
    cy: Num = Field(ge=0, description="principal point y, pixels")


def _matrix(v):
    if not (isinstance(v, list) and len(v) == 4 and all(
            isinstance(row, list) and len(row) == 4
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in row) for row in v)):
        raise _fail(f"expected a 4x4 list of numbers, found {_fmt(v)}")
    return v


class PoseMatrix(Node):
    """The camera's pose as a matrix (OpenCV camera frame to world: z up, floor z = 0);
    `dpom-warp fit-ground` output pastes in as it is (its report keys are ignored)."""

    T_world_from_camera: Annotated[list[list[float]], BeforeValidator(_matrix)] = Field(
        description="4x4 rigid transform, rows")
    camera_height: Num | None = Field(None, description="fit-ground report (ignored)")
    pitch_deg: Num | None = Field(None, description="fit-ground report (ignored)")
    roll_deg: Num | None = Field(None, description="fit-ground report (ignored)")
    inlier_count: Int | None = Field(None, description="fit-ground report (ignored)")

    @model_validator(mode="after")
    def _rigid(self):
        m = np.array(self.T_world_from_camera, dtype=np.float64)
        r = m[:3, :3]
        if (not np.allclose(r.T @ r, np.eye(3), atol=1e-3) or abs(np.linalg.det(r) - 1) > 1e-3
                or not np.allclose(m[3], [0, 0, 0, 1])):
            raise _fail("expected a rigid transform (orthonormal rotation, last row 0 0 0 1), found "
                        "a matrix that is not", "T_world_from_camera")
        return self


class PoseAngles(Node):
    """The camera at (x, y, height) looking along +y, tilted down by pitch."""

    height: Num = Field(gt=0, description="metres above the floor")
    pitch_deg: Num = Field(0.0, ge=-90, le=90, description="downward tilt, degrees")
    roll_deg: Num = Field(0.0, ge=-180, le=180, description="degrees")
    yaw_deg: Num = Field(0.0, ge=-360, le=360, description="degrees")
    x: Num = Field(0.0, description="metres")
    y: Num = Field(0.0, description="metres")


EXTRINSICS_EXPECTED = "auto, {T_world_from_camera: 4x4} or {height, pitch_deg, roll_deg}"


def _pose_kind(v):
    if v == "auto":
        return "<auto>"
    if isinstance(v, dict):
        return "<matrix>" if "T_world_from_camera" in v else "<angles>"
    return None


def _extrinsics(v):
    if _pose_kind(v) is None and not isinstance(v, BaseModel):
        raise _fail(f"expected {EXTRINSICS_EXPECTED}, found {_fmt(v)}")
    return v


Extrinsics = Annotated[
    Annotated[Union[Annotated[Literal["auto"], Tag("<auto>")], Annotated[PoseMatrix, Tag("<matrix>")],
                    Annotated[PoseAngles, Tag("<angles>")]], Discriminator(_pose_kind)],
    BeforeValidator(_extrinsics)]


class GroundSection(Node):
    """Floor fitting for `extrinsics: auto`."""

    frames: Int = Field(5, ge=1, description="first frames used when there are no background frames")
    up: Up = Field(
        _d(GroundOptions, "up"), description="up direction in the camera frame (the floor normal's prior); "
                                             "auto: the floor of any camera from level to looking straight "
                                             "down (a recording's accelerometer gives it where it has one)")
    max_angle_deg: Num = Field(_d(GroundOptions, "max_angle_deg"), gt=0, le=90,
                               description="largest angle between the floor normal and `up` (auto: the "
                                           "largest roll)")
    distance_threshold: Num = Field(_d(GroundOptions, "distance_threshold"), gt=0,
                                    description="RANSAC inlier distance, metres")
    depth_max: Num = Field(_d(GroundOptions, "depth_max"), gt=0, description="readings beyond are not used, metres")
    min_inliers: Int = Field(_d(GroundOptions, "min_inliers"), ge=3,
                             description="a floor candidate needs this many downsampled points")
    stride: Int = Field(_d(GroundOptions, "stride"), ge=1, description="every stride-th pixel")
    max_planes: Int = Field(_d(GroundOptions, "max_planes"), ge=1, description="planes peeled off, largest first")
    voxel: Num = Field(_d(GroundOptions, "voxel"), gt=0, description="downsampling voxel, metres")
    noise: Pair = Field(_d(GroundOptions, "noise"), description="depth noise a + b z^2 of the refinement, metres")

    @model_validator(mode="after")
    def _up(self):
        if not isinstance(self.up, str) and np.linalg.norm(self.up) == 0:
            raise _fail(f"expected a non-zero direction, found {list(self.up)}", "up")
        return self


def _inside_image(camera):
    """The principal point within the image (a camera section or file)."""
    i = camera.intrinsics
    for key, value, size in (("cx", i.cx, camera.width), ("cy", i.cy, camera.height)):
        if value > size:
            raise _fail(f"expected a value <= {size}, found {value:g}", f"intrinsics.{key}")
    return camera


class CameraSection(Node):
    """The depth camera: image size, intrinsics, pose, lens."""

    file: FilePath | None = Field(None, description="a camera file (width, height, intrinsics, depth_scale, "
                                                    "distortion; as fit-ground --camera takes) for the "
                                                    "keys this section and input.depth_scale leave out; "
                                                    "`camera: FILE` is short for it")
    width: Int = Field(ge=1, description="image width in pixels; frames must match (default: "
                                         "camera.file's, else the recording's)")
    height: Int = Field(ge=1, description="image height in pixels (default: camera.file's, else the "
                                          "recording's)")
    intrinsics: Intrinsics = Field(description="fx, fy, cx, cy (default: camera.file's, else the recording's "
                                                    "camera information)")
    extrinsics: Extrinsics = Field("auto", description="auto (fit the floor), {T_world_from_camera: 4x4} "
                                                       "or {height, pitch_deg, roll_deg, yaw_deg, x, y}")
    distortion: Lens | None = Field(
        None, description="[k1, k2, p1, p2, k3] or [k1, k2, p1, p2, k3, k4, k5, k6] (OpenCV's models); "
                          "default: camera.file's, else the recording's")
    ground: GroundSection = GroundSection()

    @model_validator(mode="after")
    def _principal_point(self):
        return _inside_image(self)


class GridSection(Node):
    """The locations: cells of a ground grid or voxels of a 3D grid."""

    mode: Literal["ground", "voxel"] = Field("ground", description="ground: objects standing on cells "
                                                                   "of the floor; voxel: objects centred "
                                                                   "on voxels")
    x: Axis = Field(description="[min, max, step] metres; cells tile [min, max]")
    y: Axis = Field(description="[min, max, step] metres")
    z: Axis | None = Field(None, description="[min, max, step] metres; voxel mode only")

    @model_validator(mode="after")
    def _z(self):
        if self.mode == "ground" and self.z is not None:
            raise _fail("expected no z axis in ground mode (objects stand on the floor); use mode: "
                        "voxel for a 3D grid", "z")
        if self.mode == "voxel" and self.z is None:
            raise _fail("required key is missing", "z")
        return self


class ObjectSection(Node):
    """The object's size and shape model, metres."""

    width: Num = Field(0.4, gt=0, description="metres, across the line of sight (the solid: its body's diameter)")
    height: Num = Field(1.85, gt=0, description="metres")
    depth: Num | None = Field(None, gt=0, description="default: = width")
    shape: Literal["plane", "solid"] = Field(
        _d(ObjectBox, "shape"), description="plane: a pixel expects the depth of the plane facing the "
        "camera (the paper); solid: the depth where its ray enters an upright body and head "
        "(README, How it works)")
    radius: Num | None = Field(None, gt=0, description="solid: body radius, metres (default width / 2)")
    head_radius: Num = Field(_d(ObjectBox, "head_radius"), ge=0,
                             description="solid: head radius, metres (0: no head; ground grids)")
    shoulder: Num = Field(_d(ObjectBox, "shoulder"), gt=0, le=1,
                          description="solid: where the head begins, share of the height")
    height_spread: Num = Field(_d(ObjectBox, "height_spread"), ge=0,
                               description="solid: spread of the heights of its tops, metres")
    leg_radius: Num | None = Field(_d(ObjectBox, "leg_radius"), gt=0,
                                   description="solid, ground grids: the legs' radius below hip x "
                                               "height, metres (null: the body reaches the floor)")
    hip: Num = Field(_d(ObjectBox, "hip"), gt=0, lt=1,
                     description="solid: where the legs end, share of the height")
    depth_radius: Num | None = Field(_d(ObjectBox, "depth_radius"), gt=0,
                                     description="solid, ground grids: the body's half-depth along the line of sight, "
                                                 "metres (an ellipse facing the camera; null: = radius)")


class ModelSection(Node):
    """The DPOM pixel models and mean-field inference (../shared/MODEL.md)."""

    prior: Num = Field(_d(ModelParams, "prior"), gt=0, lt=1, description="prior occupancy of every cell")
    sigma_object: Num = Field(_d(ModelParams, "sigma_object"), gt=0,
                              description="spread of an object's surface about the depth its model expects "
                                          "(the solid's surface, or the facing plane), metres")
    sensor_noise: Pair = Field(_d(ModelParams, "sensor_noise"),
                               description="sensor sigma(z) = a + b z^2, metres; adds to sigma_object "
                                           "and floors the background spread")
    outlier_prob: Num = Field(_d(ModelParams, "outlier_prob"), gt=0, lt=1, description="pi_out")
    missing_prob: Num = Field(_d(ModelParams, "missing_prob"), ge=0, lt=1,
                              description="pi_inf of objects and of the floor-only background")
    z_max: Num = Field(_d(ModelParams, "z_max"), gt=0, description="sensor range, metres")
    alpha: Num = Field(_d(ModelParams, "alpha"), description="soft threshold rho* = sigmoid(alpha e + beta) rho")
    beta: Num | None = Field(None, description=f"see alpha; null: {_d(ModelParams, 'beta'):g}, on the exact path "
                                               f"(engine.exact) {EXACT_BETA:g}")
    share_of: Literal["silhouette", "unhidden"] = Field(
        _d(ModelParams, "share_of"), description="eq. 13's e: share of the silhouette, or of its "
        "pixels not hidden by something nearer (README, How it works)")
    damping: Num = Field(_d(ModelParams, "damping"), gt=0, le=1,
                         description="lambda of the damped update at the first iteration")
    damping_growth: Num = Field(_d(ModelParams, "damping_growth"), ge=1, description="growth of lambda per iteration")
    damping_max: Num | None = Field(None, gt=0, le=1,
                                    description=f"cap of lambda (default {_d(ModelParams, 'damping_max')}, "
                                                f"never below damping)")
    damping_streak: Num = Field(_d(ModelParams, "damping_streak"), ge=1,
                                description="per-location growth of lambda while a location's target stays on one side of "
                                            "its rho (1: off)")
    damping_streak_max: Num = Field(_d(ModelParams, "damping_streak_max"), gt=0, le=1,
                                    description="cap of the per-location lambda (never below the iteration's lambda)")
    tolerance: Num = Field(_d(ModelParams, "tolerance"), gt=0,
                           description="stop when max |rho_new - rho| is below it")
    max_iterations: Int = Field(_d(ModelParams, "max_iterations"), ge=1,
                                description="iteration cap; frames that reach it unconverged are counted")
    check_every: Int = Field(_d(ModelParams, "check_every"), ge=1,
                             description="iterations between convergence checks")
    missing_clip: Num = Field(_d(ModelParams, "missing_clip"), gt=0, lt=0.5,
                              description="background pi_inf is clipped to [c, 1 - c]")
    background_outside_grid: Bool = Field(_d(ModelParams, "background_outside_grid"),
                                          description="floor-only background: readings out of every "
                                                      "object box are background")
    background_occludes: Bool = Field(_d(ModelParams, "background_occludes"),
                                      description="a location does not claim pixels where the known "
                                                  "background is in front of it by occlusion_margin")
    occlusion_margin: Num = Field(_d(ModelParams, "occlusion_margin"), ge=0, description="metres")
    sparse_epsilon: Num = Field(_d(ModelParams, "sparse_epsilon"), ge=0, le=0.5,
                                description="sparse iterations: cells whose rho and rho_new are below "
                                            "it leave the lists until a full pass; 0: every pass full")
    sparse_drop: Num = Field(_d(ModelParams, "sparse_drop"), ge=0, le=1,
                             description="sparse iterations: a full pass also drops, setting its rho to 0, a cell "
                                         "whose rho_new is below sparse_epsilon and rho below this; 0: off")
    bound_rounds: Int = Field(_d(ModelParams, "bound_rounds"), ge=0,
                              description="with sparse iterations: rounds of the pruning bound, which "
                                          "removes before the first pass the cells whose rho_new can "
                                          "never reach sparse_epsilon; 0: no pruning")
    warm_start: Bool = Field(_d(ModelParams, "warm_start"),
                             description="start each frame from the previous frame's rho capped at the "
                                         "prior (not with --workers or --ray)")
    top_support: Num = Field(_d(ModelParams, "top_support"), ge=0, le=1,
                             description="the top-band test: rho* x sigmoid(top_slope (u - top_support)); 0: off")
    top_band: Num = Field(_d(ModelParams, "top_band"), ge=0, lt=1,
                          description="the band starts at top_band x the object height")
    top_hidden: Num = Field(_d(ModelParams, "top_hidden"), ge=0, le=1,
                            description="a hidden band pixel counts as this much of a supporting one")
    top_slope: Num = Field(_d(ModelParams, "top_slope"), gt=0, description="steepness of the top-band sigmoid")
    top_min_pixels: Int = Field(_d(ModelParams, "top_min_pixels"), ge=1,
                                description="fewer readings in the band: not judged")
    top_unseen: Num | None = Field(None, ge=0, le=1,
                                   description="the top-band factor where fewer than top_min_pixels (or "
                                               "top_unseen_part of the silhouette) of the band are in the image "
                                               "(its top out of view); 1: not judged; "
                                               "default 1 with a background (frames or auto: people at the "
                                               "image's edges), 0 floor-only (furniture there passes)")
    top_unseen_share: Num = Field(_d(ModelParams, "top_unseen_share"), ge=0, le=1,
                                  description="where the band is out of view, rho* also x sigmoid(top_slope "
                                              "(e - this)), e eq. 13's share; 0: off")
    top_unseen_part: Num = Field(_d(ModelParams, "top_unseen_part"), ge=0, le=1,
                                 description="a band with fewer than this share of the silhouette's pixels in "
                                             "the image also counts as out of view")
    top_sigmas: Num = Field(_d(ModelParams, "top_sigmas"), ge=0,
                            description="a band pixel supports the object within this many sigma of "
                                        "its depth; 0: the mask test")
    top_heights: Heights | None = Field(None, description=f"heights (metres, below object.height) of shorter people "
                                                          f"whose top band is also tried, the best kept (README, How "
                                                          f"it works); default [object.height - {TOP_SHORTER:g}] with "
                                                          f"the solid on ground grids, objects taller than 1 m and a "
                                                          f"background (frames or auto), else [] (floor-only: "
                                                          f"furniture that tall would pass)")
    top_missing: Num = Field(_d(ModelParams, "top_missing"), ge=0, le=1,
                             description="a band pixel with no reading where the object lies within z_max "
                                         "(the sensor would read it there) and the background is mostly "
                                         "read counts as this much of one reading behind it; 0: none")
    exclusion: Num | None = Field(None, ge=0,
                                  description=f"two objects cannot stand within exclusion_radius: a "
                                              f"location's evidence loses exclusion x its neighbours' rho "
                                              f"above exclusion_gate (README, How it works); default "
                                              f"{_d(ModelParams, 'exclusion'):g} on ground grids, 0 (off) "
                                              f"in voxel mode")
    exclusion_radius: Num = Field(_d(ModelParams, "exclusion_radius"), gt=0, description="metres")
    exclusion_gate: Num = Field(_d(ModelParams, "exclusion_gate"), ge=0, lt=1,
                                description="neighbours' rho above it count")
    behind_cost: Num | None = Field(None, ge=0,
                                    description=f"evidence a location loses per pixel of its silhouette's "
                                                f"core that reads behind its object (README, How it works); "
                                                f"default {BEHIND_COST:g} with the solid on "
                                                f"ground grids, else 0 (off: the paper, such pixels say nothing)")
    behind_side: Num = Field(_d(ModelParams, "behind_side"), ge=0, lt=0.5,
                             description="share of each silhouette row left out at either end")
    behind_low: Num = Field(_d(ModelParams, "behind_low"), ge=0, le=1,
                            description="pixels whose object point lies below behind_low x the height "
                                        "are left out (ground grids)")
    behind_high: Num = Field(_d(ModelParams, "behind_high"), ge=0, le=1,
                             description="pixels whose object point lies above behind_high x the height "
                                         "are left out (ground grids)")
    behind_step: int = Field(_d(ModelParams, "behind_step"), ge=1,
                             description="counted on every behind_step-th row and column, each pixel "
                                         "standing for behind_step^2")

    @model_validator(mode="after")
    def _checks(self):
        if min(self.sensor_noise) < 0:
            raise _fail(f"expected [a, b] >= 0, found {list(self.sensor_noise)}", "sensor_noise")
        if self.damping_max is not None and self.damping_max < self.damping:
            raise _fail(f"expected at least model.damping ({self.damping}), found {self.damping_max}",
                        "damping_max")
        return self


class DetectionSection(Node):
    """Detections from the rho* map."""

    threshold: Num = Field(0.5, gt=0, lt=1, description="minimum rho* of a detection (a local maximum)")
    nms_radius: Num = Field(0.4, ge=0, description="greedy non-maximum suppression: a weaker maximum closer than "
                                                   "this (by more than rounding) goes, metres")
    edge_radius: Num | None = Field(None, ge=0, description=(
        "a detection whose silhouette is mostly outside the image (its share in view under edge_view) is dropped "
        f"within this distance of one in view, metres (README, Known behaviour); default {EDGE_RADIUS:g} on ground "
        f"grids, 0 (off) in voxel mode"))
    edge_view: Num = Field(0.5, gt=0, le=1, description=(
        "the share of a silhouette's rectangle inside the image under which edge_radius applies"))
    min_log_odds: Num = Field(MIN_LOG_ODDS, ge=0, description=(
        "the joint test: a detection whose log posterior odds, with the other detections present and nothing "
        "else, is under this (nats) leaves the map (README, How it works); 0: off"))


class EvaluationSection(Node):
    """Scores against ground truth."""

    ground_truth: FilePath | None = Field(None, description="ground-truth JSON; scores go into summary.json")
    match_distance: Num = Field(0.5, gt=0, description="matching gate on the ground plane, metres")
    hidden_visibility: Num = Field(0.1, ge=0, le=1,
                                   description="people less visible than this are not penalised in "
                                               "the second protocol")
    plots: Bool = Field(False, description="also write the evaluation figures into plots/")


def _td(name):
    return _d(TrackingOptions, name)


def _switch(v):
    """YAML 1.1 reads a bare on / off as true / false: the words they were."""
    return {True: "on", False: "off"}.get(v, v) if isinstance(v, bool) else v


Switch = BeforeValidator(_switch)


class TrackingSection(Node):
    """Tracks with identities over the run's maps (K-shortest paths as a min-cost flow)."""

    method: Annotated[Literal["auto", "ksp", "online", "off"], Switch] = Field(
        _td("method"), description="auto: ksp for runs of two frames or more; ksp: offline, globally "
                                   "optimal; online: causal, committed `delay` frames behind; off: no tracks")
    max_speed: Num = Field(_td("max_speed"), gt=0, description="fastest move between frames, m/s")
    prune: Num = Field(_td("prune"), gt=0, lt=1, description="cells below this rho* are left out of the graph")
    peak: Num = Field(_td("peak"), gt=0, lt=1, description="map peaks at least this high may be bridged "
                                                           "across hidden frames")
    min_rho: Num = Field(_td("min_rho"), gt=0, lt=0.5, description="rho* floor of a node's cost: a "
                                                                   "bridged frame costs -log(min_rho / (1 - min_rho))")
    max_rho: Num = Field(_td("max_rho"), gt=0.5, lt=1, description="rho* ceiling of a node's cost")
    jitter: Num = Field(_td("jitter"), ge=0, description="how far a map's peak may wander from the "
                                                         "person between frames, metres (reach = "
                                                         "max_speed / fps + jitter)")
    entry_cost: Num = Field(_td("entry_cost"), ge=0, description="starting or ending a track at an entry "
                                                                 "cell (grid border, edge of the view, regions)")
    appear_cost: Num = Field(_td("appear_cost"), ge=0, description="starting or ending one anywhere else")
    max_gap: Int = Field(_td("max_gap"), ge=0, description="most frames a track is bridged across")
    window: Int = Field(_td("window"), ge=2, description="ksp: frames per solved window")
    overlap: Int = Field(_td("overlap"), ge=0, description="ksp: frames two windows share (stitched there)")
    delay: Int = Field(_td("delay"), ge=0, description="online: frames between the newest and the committed one")
    regions: list[Annotated[tuple[float, float, float, float], _numbers(4)]] = Field(
        [], description="more entry areas [x_min, x_max, y_min, y_max], metres (doors)")
    trail: Int = Field(_td("trail"), ge=0, description="frames of trail drawn behind a track in the pictures")


class OutputSection(Node):
    """What the run writes."""

    dir: FilePath = Field("runs/out", description="output folder (--output overrides)")
    images: Bool = Field(True, description="a picture per frame")
    images_every: Int = Field(1, ge=1, description="a picture of every Nth frame done (the 1st, the "
                                                   "N+1th, ...; a long recording's run draws fewer)")
    rerun: FilePath | None = Field(None, description="also write a Rerun recording (.rrd) here: depth, "
                                                     "boxes, map and tracks per frame (the view extra)")
    ply: Bool = Field(False, description="the frame's points and the detected boxes as .ply files")


class EngineSection(Node):
    """The Warp engine's buffers and launches."""

    entries_per_pixel: Num = Field(8.0, gt=0, description="initial mask-list capacity per pixel")
    max_entries: Int | None = Field(None, ge=1, description="hard cap on the list capacity; a frame "
                                                            "above it is refused, never truncated")
    memory_gb: Num | None = Field(8.0, gt=0, description="memory budget of the engine's buffers, GiB")
    batch: Batch = Field("auto", description="frames per engine call; auto: 16 for a recorded run on a GPU "
                                             "(fewer where engine.memory_gb holds fewer), else 1 (the CPU, a "
                                             "live camera, the Python API)")
    graph: Annotated[Literal["auto", "on", "off"], Switch] = Field("auto", description="replay the iteration loop as a "
                                                                    "captured graph; auto: on CUDA only")
    exact: Bool = Field(False, description="the exact path: full resolution, every pass full, no warm "
                                           "start (the NumPy reference's results to 1e-6)")
    mask_index: Literal["auto", "table", "tiles"] = Field(
        "auto", description="the static index the mask lists are built from (the same lists): table: "
                            "every silhouette pixel's object depth stored; tiles: image tiles, less "
                            "memory; auto: the table with a solid where it takes <= 256 MiB and fits "
                            "memory_gb")


def _sd(name):
    return _d(SceneSpec, name)


class SyntheticSection(Node):
    """Render a synthetic sequence before the run (once; later runs reuse it)."""

    cache: FilePath = Field(description="folder of the rendered frames, background and ground truth")
    seed: Int = Field(_sd("seed"), ge=0, description="seed of the whole sequence")
    frames: Int = Field(_sd("frames"), ge=1, description="frames with people")
    background_frames: Int = Field(_sd("background_frames"), ge=0, description="frames of the empty room")
    people: Int = Field(_sd("people"), ge=0, description="people walking, or drones flying")
    kind: Literal["people", "drones"] = Field(_sd("kind"), description="what is rendered")
    area: Annotated[tuple[float, float, float, float], _numbers(4)] = Field(
        _sd("area"), description="x_min, x_max, y_min, y_max where they move, metres")
    altitude: Pair = Field(_sd("altitude"), description="drones' heights, metres")
    obstacles: Int = Field(_sd("obstacles"), ge=0, description="free-standing cabinets")
    room: Annotated[tuple[float, float, float, float, float], _numbers(5)] = Field(
        _sd("room"), description="x_min, x_max, y_min, y_max, height of the walls, metres")
    furniture: Int = Field(_sd("furniture"), ge=0, description="furniture pieces placed in the room")
    step_m: Num = Field(_sd("step_m"), ge=0, description="walk per frame, metres")
    pair_gap: Num = Field(_sd("pair_gap"), ge=0, description="> 0: people walk in pairs this far apart")
    min_gap: Num = Field(_sd("min_gap"), gt=0, description="people keep this far apart, metres")
    tables: Int = Field(_sd("tables"), ge=0, description="free-standing tables inside the area")
    in_view: Literal["body", "head"] = Field(_sd("in_view"), description="what of a person must be in "
                                             "the image: body (eye level) or head (ceiling cameras)")
    motion: Literal["random", "paths"] = Field(_sd("motion"), description="random: a random walk in view; "
                                               "paths: straight walks to waypoints with stops (tracking scenes)")
    leave: Num = Field(_sd("leave"), ge=0, description="paths: waypoints up to this far outside the area "
                                                       "(people leave the view and come back), metres")
    noise: Pair = Field(_sd("noise"), description="depth noise a + b z^2, metres")
    dropout: Num = Field(_sd("dropout"), ge=0, le=1, description="share of pixels with no reading")
    edge_holes: Num = Field(_sd("edge_holes"), ge=0, le=1,
                            description="probability of no reading at a depth edge")
    range_m: Pair = Field(_sd("range_m"), description="near, far sensor range, metres")


class ConfigFile(Node):
    """A dpom-warp run config (`dpom-warp run CONFIG`)."""

    model_config = ConfigDict(title="dpom-warp run config")

    device: Device = Field("auto", description="auto (first CUDA device, else the CPU), cpu, cuda, cuda:N")
    input: InputSection
    camera: CameraSection
    grid: GridSection
    object: ObjectSection = ObjectSection()
    model: ModelSection = ModelSection()
    detection: DetectionSection = DetectionSection()
    evaluation: EvaluationSection = EvaluationSection()
    tracking: TrackingSection = TrackingSection()
    output: OutputSection = OutputSection()
    engine: EngineSection = EngineSection()
    synthetic: SyntheticSection | None = None

    @model_validator(mode="after")
    def _across_sections(self):
        grid, obj = self.grid, self.object
        sizes = [("x", "width", obj.width), ("y", "depth" if obj.depth else "width", obj.depth or obj.width)]
        if grid.mode == "voxel":
            sizes.append(("z", "height", obj.height))
        for axis, key, size in sizes:
            lo, hi, _ = getattr(grid, axis)
            if size > hi - lo:
                raise _fail(f"expected at most the grid's {axis} extent {hi - lo:g} m, found {size:g}",
                            f"object.{key}")
        heights = self.model.top_heights or ()
        if grid.mode == "voxel" and heights:
            raise _fail(f"expected [] in voxel mode (no top-band test there), found {list(heights)}",
                        "model.top_heights")
        if any(h >= obj.height for h in heights):
            raise _fail(f"expected heights below object.height ({obj.height:g} m), found {list(heights)}",
                        "model.top_heights")
        if self.synthetic is not None and self.camera.extrinsics == "auto":
            raise _fail("rendering needs a camera pose; expected camera.extrinsics given as "
                        "{height, pitch_deg, ...} or a matrix, found auto", "synthetic")
        return self


def json_schema() -> dict:
    """The JSON Schema of a run config (what `dpom-warp schema` writes)."""
    schema = ConfigFile.model_json_schema()
    # width, height and intrinsics may come from camera.file or a recording, the whole section
    # from a recording (parse_config says when they come from neither), and `camera: FILE` is
    # short for {file: FILE}
    schema["$defs"]["CameraSection"].pop("required", None)
    schema["required"] = [k for k in schema["required"] if k != "camera"]
    schema["properties"]["camera"] = {"anyOf": [
        {"$ref": "#/$defs/CameraSection"},
        {"type": "string", "description": "a camera file: short for {file: FILE}"}]}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def path_keys(model: type[BaseModel] = ConfigFile, prefix: str = "") -> list[str]:
    """Dotted keys of the config values that are paths (PathValue), from the models."""
    keys = []
    for name, info in model.model_fields.items():
        key = f"{prefix}{name}"
        if any(isinstance(m, PathValue) for m in info.metadata) or _has_path(info.annotation):
            keys.append(key)
        for sub in _sections(info.annotation):
            keys += path_keys(sub, key + ".")
    return keys


def _args(tp):
    return getattr(tp, "__args__", ()) or ()


def _has_path(tp) -> bool:
    meta = getattr(tp, "__metadata__", ())
    return any(isinstance(m, PathValue) for m in meta) or any(_has_path(a) for a in _args(tp))


def _sections(tp) -> list[type[BaseModel]]:
    if isinstance(tp, type) and issubclass(tp, Node):
        return [tp]
    return [s for a in _args(tp) for s in _sections(a)]


# -- errors as one line -------------------------------------------------------------------------
def _g(x):
    return f"{x:g}" if isinstance(x, (int, float)) else str(x)


def _one_line(error: dict) -> str:
    loc = [str(p) for p in error["loc"] if not str(p).startswith("<")]
    ctx = error.get("ctx") or {}
    if ctx.get("key"):
        loc.append(ctx["key"])
    key = ".".join(loc) or "config"
    kind, found = error["type"], _fmt(error.get("input"))
    bounds = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}
    if kind == "missing":
        text = "required key is missing"
    elif kind in bounds:
        limit = ctx.get({">": "gt", ">=": "ge", "<": "lt", "<=": "le"}[bounds[kind]])
        text = f"expected a value {bounds[kind]} {_g(limit)}, found {found}"
    elif kind == "literal_error":
        choices = re.findall(r"'([^']*)'", str(ctx.get("expected", "")))
        text = f"expected one of {', '.join(choices)}, found {found}"
    elif kind == "dpom":
        text = error["msg"]
    else:
        text = f"{error['msg'][0].lower()}{error['msg'][1:]}, found {found}"
    return f"{key}: {text}"


def _first_error(e: ValidationError) -> str:
    errors = e.errors(include_url=False)
    unknown = [x for x in errors if x["type"] == "dpom" and x["msg"].startswith("unknown key")]
    return _one_line((unknown or errors)[0])


# -- the typed run config the pipeline uses ----------------------------------------------------
@dataclass(frozen=True)
class Detection:
    threshold: float = 0.5
    nms_radius: float = 0.4
    edge_radius: float = 0.0
    edge_view: float = 0.5
    min_log_odds: float = MIN_LOG_ODDS


@dataclass(frozen=True)
class Evaluation:
    ground_truth: str | None = None
    match_distance: float = 0.5
    hidden_visibility: float = 0.1
    plots: bool = False


@dataclass(frozen=True)
class Inputs:
    frames: str | None = None
    background: str | None = None
    depth_scale: float = 0.001
    fps: float = 15.0
    topic: str | None = None
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
    images_every: int = 1
    rerun: str | None = None
    ply: bool = False


@dataclass(frozen=True)
class EngineOptions:
    entries_per_pixel: float = 8.0
    max_entries: int | None = None
    memory_gb: float | None = 8.0
    batch: int | str = "auto"  # (an int once a run has chosen: pipeline.set_up)
    graph: str = "auto"
    exact: bool = False
    mask_index: str = "auto"


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
    tracking: TrackingOptions = TrackingOptions()


def _fill(cls, section: BaseModel, **changes):
    """A domain dataclass from a validated section (the fields they share)."""
    names = {f.name for f in fields(cls)} - set(changes)
    return cls(**{k: v for k, v in section.model_dump().items() if k in names}, **changes)


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


def parse_config(raw: dict[str, Any]) -> RunConfig:
    """Validate a config mapping into a RunConfig. No file is read: the camera keys a camera file
    or a recording gives are filled in before (loading.config_from_mapping; a run folder's
    run.json has them all)."""
    try:
        c = ConfigFile.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_first_error(e)) from None
    s = c.input
    inputs = Inputs(frames=s.frames, background=s.background, depth_scale=s.depth_scale, fps=s.fps,
                    topic=s.topic, stride=s.stride, reduce=s.reduce,
                    background_auto=_fill(AutoBackground, s.background_auto))
    cam, ext = c.camera, c.camera.extrinsics
    pose_auto = ext == "auto"
    if pose_auto:
        pose, pose_resolved = np.eye(4), "auto"
    elif isinstance(ext, PoseMatrix):
        pose = np.array(ext.T_world_from_camera, dtype=np.float64)
        pose_resolved = {"T_world_from_camera": pose.tolist()}
    else:
        pose_resolved = ext.model_dump()
        pose = pose_from_angles(ext.height, ext.pitch_deg, ext.roll_deg, ext.yaw_deg, ext.x, ext.y)
    i = cam.intrinsics
    camera = Camera(cam.width, cam.height, i.fx, i.fy, i.cx, i.cy, pose, cam.distortion)
    ground = _fill(GroundOptions, cam.ground)
    grid = Grid(x=c.grid.x, y=c.grid.y, mode=c.grid.mode, z=c.grid.z)
    obj = _fill(ObjectBox, c.object)
    m = c.model
    damping_max = m.damping_max if m.damping_max is not None else max(_d(ModelParams, "damping_max"), m.damping)
    exclusion = m.exclusion if m.exclusion is not None else (_d(ModelParams, "exclusion") if c.grid.mode == "ground" else 0.0)
    behind_cost = (m.behind_cost if m.behind_cost is not None else  # the core is the solid's
                   (BEHIND_COST if c.grid.mode == "ground" and c.object.shape == "solid" else 0.0))
    # a person shorter than the solid; not floor-only, where the band is what tells furniture
    # from people and a shorter one lets a cabinet of that height through
    top_heights = (m.top_heights if m.top_heights is not None else
                   ((round(c.object.height - TOP_SHORTER, 6),) if c.grid.mode == "ground" and c.object.shape == "solid"
                    and c.object.height > 1.0 and c.input.background is not None else ()))
    # a cell whose band is out of the image is not judged by it (people entering the view, a
    # ceiling camera's edges); floor-only it is rejected: a table at the image's edge supports
    # the lower part of such a solid, and without a background nothing tells it from a person
    top_unseen = m.top_unseen if m.top_unseen is not None else (1.0 if c.input.background is not None else 0.0)
    # eq. 13's cut-off, chosen for each path on the tuning draw (README, Defaults and why)
    beta = m.beta if m.beta is not None else (EXACT_BETA if c.engine.exact else _d(ModelParams, "beta"))
    model = _fill(ModelParams, m, damping_max=damping_max, exclusion=exclusion, behind_cost=behind_cost,
                  top_heights=top_heights, top_unseen=top_unseen, beta=beta)
    edge_radius = (c.detection.edge_radius if c.detection.edge_radius is not None else
                   EDGE_RADIUS if c.grid.mode == "ground" else 0.0)
    detection = _fill(Detection, c.detection, edge_radius=edge_radius)
    evaluation = _fill(Evaluation, c.evaluation)
    output = _fill(Output, c.output)
    engine = _fill(EngineOptions, c.engine)
    tracking = _fill(TrackingOptions, c.tracking, regions=tuple(tuple(r) for r in c.tracking.regions))
    if engine.exact:  # the exact path: full resolution, every pass full, no warm start
        inputs = dataclasses.replace(inputs, stride=1)
        model = dataclasses.replace(model, sparse_epsilon=0.0, warm_start=False)
    synthetic = _fill(SceneSpec, c.synthetic) if c.synthetic is not None else None
    cache = c.synthetic.cache if c.synthetic is not None else None

    def plain(v):
        return list(v) if isinstance(v, tuple) else v

    resolved = {
        "device": c.device,
        "input": {**vars_of(inputs), "background_auto": vars_of(inputs.background_auto)},
        "camera": {"width": cam.width, "height": cam.height,
                   "intrinsics": {"fx": i.fx, "fy": i.fy, "cx": i.cx, "cy": i.cy},
                   "extrinsics": pose_resolved,
                   "distortion": list(cam.distortion) if cam.distortion else None,
                   "ground": {"frames": cam.ground.frames, **{k: plain(v) for k, v in vars_of(ground).items()}}},
        "grid": {"mode": grid.mode, "x": list(grid.x), "y": list(grid.y), **({"z": list(grid.z)} if grid.z else {})},
        "object": vars_of(obj),
        "model": {k: plain(v) for k, v in vars_of(model).items()},
        "detection": vars_of(detection), "evaluation": vars_of(evaluation),
        "tracking": {**vars_of(tracking), "regions": [list(r) for r in tracking.regions]},
        "output": vars_of(output), "engine": vars_of(engine),
    }
    if synthetic is not None:
        resolved["synthetic"] = {"cache": cache, **{k: plain(v) for k, v in vars_of(synthetic).items()}}
    return RunConfig(c.device, inputs, camera, grid, obj, model, detection, evaluation, output,
                     engine, synthetic, cache, resolved, pose_auto, ground, cam.ground.frames, tracking)


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
        if (isinstance(v, str) and v != "auto" and not is_live(v)
                and not os.path.isabs(os.path.expanduser(v))):
            node[last] = os.path.normpath(os.path.join(base, v))
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


def read_config(path: str | Path) -> dict:
    """A config file's mapping, its relative paths made relative to the current folder."""
    path = Path(path)
    raw = _read_yaml(path, "config file")
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a YAML mapping at the top, found {_fmt(raw)}")
    return resolve_paths(raw, path.parent)


class CameraFile(Node):
    """A camera file as in shared/data/real/*/camera.yaml."""

    width: Int = Field(ge=1)
    height: Int = Field(ge=1)
    intrinsics: Intrinsics
    depth_scale: Num = Field(0.001, gt=0)
    distortion: Lens | None = None

    @model_validator(mode="after")
    def _principal_point(self):
        return _inside_image(self)


def load_camera_file(path: str | Path) -> tuple[Camera, float]:
    """Read a camera file (width, height, intrinsics {fx, fy, cx, cy}, depth_scale, optional
    distortion [k1, k2, p1, p2, k3]) as in shared/data/real/*/camera.yaml.

    Returns:
        (camera with identity pose, depth_scale in metres per unit).
    """
    path = Path(path)
    raw = _read_yaml(path, "camera file")
    try:
        c = CameraFile.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(f"{path}: {_first_error(e)}") from None
    i = c.intrinsics
    return Camera(c.width, c.height, i.fx, i.fy, i.cx, i.cy, distortion=c.distortion), c.depth_scale

"""The `camera` section: size, intrinsics, distortion, the pose (a 4x4, angles or `auto`) and the
floor fit's options; and camera files (`camera.file`, `dpom-warp fit-ground --camera`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    model_validator,
)

from ..geometry import Camera, pose_from_angles
from ..ground import GroundOptions
from ..values import (
    ConfigError,
    FilePath,
    Int,
    Lens,
    Node,
    Num,
    _fail,
    _first_error,
    _fmt,
    _read_yaml,
)


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
    pitch_deg: Num = Field(0.0, ge=-90, le=90, description="downward tilt, degrees (left out: the recording's "
                                                           "accelerometer's, where it has one)")
    roll_deg: Num = Field(0.0, ge=-180, le=180, description="degrees (left out: the accelerometer's, as pitch_deg)")
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


class GroundSection(GroundOptions):
    """Floor fitting for `extrinsics: auto`."""

    frames: Int = Field(5, ge=1, description="first frames used when there are no background frames")

    def options(self) -> GroundOptions:
        """How to look for the floor (the section without the frames it is fitted on)."""
        return GroundOptions(**self.model_dump(exclude={"frames"}))


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

    def build(self) -> tuple[Camera, dict | str]:
        """The camera (identity pose with `extrinsics: auto`, fitted later) and its extrinsics as
        the resolved config writes them."""
        ext, i = self.extrinsics, self.intrinsics
        if ext == "auto":
            pose, resolved = np.eye(4), "auto"
        elif isinstance(ext, PoseMatrix):
            pose = np.array(ext.T_world_from_camera, dtype=np.float64)
            resolved = {"T_world_from_camera": pose.tolist()}
        else:
            resolved = ext.model_dump()
            pose = pose_from_angles(ext.height, ext.pitch_deg, ext.roll_deg, ext.yaw_deg, ext.x, ext.y)
        return Camera(self.width, self.height, i.fx, i.fy, i.cx, i.cy, pose, self.distortion), resolved


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

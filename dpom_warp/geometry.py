"""Camera, location grid and the per-location silhouette, facing plane and solid (MODEL.md, Geometry).

Everything here is computed once per camera and grid, in float64 NumPy, and shared by the Warp
engine and the NumPy reference, so both paths see exactly the same geometry.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from .shapes import FacingPlane, ObjectBox, Shape
from .values import Axis, Node, _fail

__all__ = ["Camera", "Geometry", "Grid", "ObjectBox", "build_geometry", "closer", "neighbour_lists", "pose_from_angles"]


def pose_from_angles(height_m: float, pitch_deg: float, roll_deg: float = 0.0,
                     yaw_deg: float = 0.0, x_m: float = 0.0, y_m: float = 0.0) -> np.ndarray:
    """Build `T_world_from_camera` for a camera at (x, y, height) looking along world +y.

    Args:
        height_m: height of the camera centre above the floor (z = 0), metres.
        pitch_deg: downward tilt of the optical axis below the horizon, degrees.
        roll_deg: rotation about the optical axis, degrees (positive turns the image clockwise).
        yaw_deg: rotation of the viewing direction about world z, degrees (0 looks along +y).
        x_m, y_m: camera position on the floor plane, metres.

    Returns:
        (4, 4) float64 rigid transform from the OpenCV camera frame (x right, y down, z forward)
        to the world frame (z up, floor at z = 0).
    """
    p, r, w = np.deg2rad([pitch_deg, roll_deg, yaw_deg])
    # Camera axes in the world for yaw = 0, roll = 0: right, down, forward (columns).
    right = np.array([1.0, 0.0, 0.0])
    down = np.array([0.0, -np.sin(p), -np.cos(p)])
    forward = np.array([0.0, np.cos(p), -np.sin(p)])
    r_level = np.stack([right, down, forward], axis=1)
    roll = np.array([[np.cos(r), -np.sin(r), 0.0], [np.sin(r), np.cos(r), 0.0], [0.0, 0.0, 1.0]])
    yaw = np.array([[np.cos(w), -np.sin(w), 0.0], [np.sin(w), np.cos(w), 0.0], [0.0, 0.0, 1.0]])
    t = np.eye(4)
    t[:3, :3] = yaw @ r_level @ roll
    t[:3, 3] = [x_m, y_m, height_m]
    return t


@dataclass(frozen=True)
class Camera:
    """Pinhole depth camera: image size, intrinsics (pixels), pose in the world frame and
    optional lens distortion (k1, k2, p1, p2, k3; OpenCV's Brown-Conrady model, or its rational
    model k1, k2, p1, p2, k3, k4, k5, k6: the radial factor divided by 1 + k4 r^2 + k5 r^4 +
    k6 r^6, as Azure Kinect calibrations give it)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    T_world_from_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    distortion: tuple[float, ...] | None = None

    def distort(self, x, y):
        """Distorted normalised image coordinates of undistorted ones (x = X/Z, y = Y/Z)."""
        if self.distortion is None:
            return x, y
        k1, k2, p1, p2, k3, k4, k5, k6 = (tuple(self.distortion) + (0.0, 0.0, 0.0))[:8]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)

    def undistort(self, xd, yd, iterations: int = 50):
        """Inverse of `distort`, by fixed-point iteration (exact to ~1e-12 for lens-like
        distortion within the image)."""
        if self.distortion is None:
            return xd, yd
        x, y = xd, yd
        for _ in range(iterations):
            dx, dy = self.distort(x, y)
            x, y = x + (xd - dx), y + (yd - dy)
        return x, y

    def normalised(self, u, v):
        """Undistorted normalised coordinates (x, y) of pixel (u, v); the ray is (x, y, 1)."""
        return self.undistort((np.asarray(u, np.float64) - self.cx) / self.fx,
                              (np.asarray(v, np.float64) - self.cy) / self.fy)

    @property
    def centre(self) -> np.ndarray:
        """Camera centre C in world coordinates (metres)."""
        return np.asarray(self.T_world_from_camera, dtype=np.float64)[:3, 3].copy()

    @property
    def R_wc(self) -> np.ndarray:
        return np.asarray(self.T_world_from_camera, dtype=np.float64)[:3, :3]

    def rays(self) -> np.ndarray:
        """World direction of every pixel's ray, scaled so that the ray parameter is z-depth.

        Returns:
            (height, width, 3) float64 array `d = R_wc @ [(u - cx)/fx, (v - cy)/fy, 1]`.
        """
        uu, vv = np.meshgrid(np.arange(self.width), np.arange(self.height))
        x, y = self.normalised(uu, vv)
        return np.stack([x, y, np.ones_like(x)], -1) @ self.R_wc.T

    def project(self, points_w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project world points to pixels.

        Returns:
            (u, v, z): pixel coordinates and z-depth (metres) in the camera frame.
        """
        pc = (np.asarray(points_w, dtype=np.float64) - self.centre) @ self.R_wc
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = self.distort(pc[..., 0] / z, pc[..., 1] / z)
        return self.fx * x + self.cx, self.fy * y + self.cy, z


def axis_cells(lo: float, hi: float, step: float) -> np.ndarray:
    """Centres of the cells of width `step` that tile [lo, hi] (the last one may overhang)."""
    n = max(1, int(np.ceil((hi - lo) / step - 1e-9)))
    return lo + (np.arange(n) + 0.5) * step


class Grid(Node):  # the config's `grid` section
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

    @property
    def xs(self) -> np.ndarray:
        return axis_cells(*self.x)

    @property
    def ys(self) -> np.ndarray:
        return axis_cells(*self.y)

    @property
    def zs(self) -> np.ndarray:
        return axis_cells(*self.z) if self.mode == "voxel" else np.zeros(1)

    @property
    def shape(self) -> tuple[int, ...]:
        """Map shape: (ny, nx) for ground grids, (nz, ny, nx) for voxel grids."""
        if self.mode == "voxel":
            return (len(self.zs), len(self.ys), len(self.xs))
        return (len(self.ys), len(self.xs))

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def centres(self) -> np.ndarray:
        """(K, 3) location centres in world metres, in map order (z slowest, x fastest)."""
        zz, yy, xx = np.meshgrid(self.zs, self.ys, self.xs, indexing="ij")
        return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)


@dataclass
class Geometry:
    """Per-location quantities shared by the Warp engine and the NumPy reference.

    Attributes:
        rays: (H, W, 3) world ray directions, ray parameter = z-depth.
        centre: camera centre C (3,).
        locations: (K, 3) location centres.
        rect: (K, 4) int32 silhouette rectangle u0, v0, u1, v1 (inclusive pixel indices,
            clipped to the image); u1 < u0 for a location with no silhouette.
        rect_area: (K,) pixels of the silhouette rectangle inside the image, 0 when there is
            none (its footprint: the locations the camera sees).
        normal: (K, 3) unit normal of the facing plane (pointing at the camera).
        plane: (K,) n . (P_k - C); the object depth along pixel ray d is plane / (n . d).
        bounds: (6,) x_min, x_max, y_min, y_max, z_min, z_max of all object boxes: a point
            outside can belong to no object.
        height: the height of the boxes standing on the floor (ground mode); 0 for boxes
            centred on voxels, where the top-band test of the soft threshold does not apply.
        shape: the object's shape (shapes.py: the facing plane or the solid), its depth and
            the kernels' fields.
        view_part: (K,) the share of each silhouette rectangle (before clipping) inside the
            image, 0 with none (detection.edge_radius); None: not known, every location whole.
        area: |S_k| (property): the rectangle's area for the facing plane; with a solid, the
            pixels of the rectangle whose rays enter it, counted on first use (seconds at
            full resolution: only the engine and the reference need it, not the pictures).
    """

    rays: np.ndarray
    centre: np.ndarray
    locations: np.ndarray
    rect: np.ndarray
    rect_area: np.ndarray
    normal: np.ndarray
    plane: np.ndarray
    bounds: np.ndarray
    height: float = 0.0
    shape: Shape = field(default_factory=lambda: FacingPlane(bottom=0.0, top=0.0))
    view_part: np.ndarray | None = None

    @cached_property
    def area(self) -> np.ndarray:
        if not self.shape.counted_area:
            return self.rect_area
        area = np.zeros_like(self.rect_area)
        for k in np.flatnonzero(self.rect_area > 0):  # the silhouette is the solid's projection
            u0, v0, u1, v1 = self.rect[k]
            mu, _ = self.object_depth(k, self.rays[v0:v1 + 1, u0:u1 + 1])
            area[k] = np.count_nonzero(mu > 0)
        return area

    def shorter(self, height: float) -> "Geometry":
        """The same locations with an object of `height` (<= self.height, ground grids): the
        solid's shoulder and top scaled by height / self.height above its bottom, its radii
        and legs kept (the hip no higher than the new shoulder), so where the head is no
        wider than the body its projection lies inside each silhouette rectangle, which is
        kept (the band of the top-band test for people shorter than the solid,
        ModelParams.top_heights)."""
        if not 0 < height <= self.height:
            raise ValueError(f"shorter: expected a height in (0, {self.height:g}], found {height:g}")
        return replace(self, height=float(height), shape=self.shape.scaled(height / self.height))

    def object_depth(self, k: int, rays: np.ndarray):
        """(mu, var): the depth each of `rays` (..., 3) expects of location k (-1: not the
        object's) and the variance the shape adds to it (0 on a facing plane)."""
        return self.shape.depth(self, k, rays)


def build_geometry(camera: Camera, grid: Grid, obj: ObjectBox) -> Geometry:
    """Silhouette rectangles and facing planes for every location of `grid` seen by `camera`."""
    locs = grid.centres()
    shape = obj.build(grid.mode)
    corners = shape.corners(locs)
    u, v, z = camera.project(corners)
    in_front = np.all(z > 1e-6, axis=1)
    with warnings.catch_warnings():  # boxes (partly) behind the camera: all-NaN rows, no silhouette
        warnings.simplefilter("ignore", RuntimeWarning)
        u0 = np.ceil(np.nanmin(np.where(in_front[:, None], u, np.nan), axis=1))
        u1 = np.floor(np.nanmax(np.where(in_front[:, None], u, np.nan), axis=1))
        v0 = np.ceil(np.nanmin(np.where(in_front[:, None], v, np.nan), axis=1))
        v1 = np.floor(np.nanmax(np.where(in_front[:, None], v, np.nan), axis=1))
    with np.errstate(invalid="ignore"):  # the rectangle before clipping (NaN: no silhouette)
        whole = (u1 - u0 + 1) * (v1 - v0 + 1)
    big = 1e9
    u0 = np.clip(np.nan_to_num(u0, nan=big), 0, camera.width)
    v0 = np.clip(np.nan_to_num(v0, nan=big), 0, camera.height)
    u1 = np.clip(np.nan_to_num(u1, nan=-big), -1, camera.width - 1)
    v1 = np.clip(np.nan_to_num(v1, nan=-big), -1, camera.height - 1)
    empty = ~in_front | (u1 < u0) | (v1 < v0)
    rect = np.stack([u0, v0, u1, v1], axis=1).astype(np.int64)
    rect[empty] = (0, 0, -1, -1)
    area = np.where(empty, 0, (rect[:, 2] - rect[:, 0] + 1) * (rect[:, 3] - rect[:, 1] + 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        view_part = np.where(empty, 0.0, area / np.where(whole > 0, whole, np.inf))

    c = camera.centre
    to_cam = c[None, :] - locs
    if grid.mode == "ground":
        to_cam[:, 2] = 0.0  # people: vertical facing plane
    norm = np.linalg.norm(to_cam, axis=1)
    fallback = -camera.R_wc[:, 2].copy()  # camera directly above a location: face the camera axis
    if grid.mode == "ground":
        fallback[2] = 0.0
    fallback /= max(np.linalg.norm(fallback), 1e-12)
    normal = np.where(norm[:, None] > 1e-9, to_cam / np.maximum(norm, 1e-12)[:, None], fallback)
    plane = np.einsum("kj,kj->k", normal, locs - c[None, :])
    return Geometry(
        rays=camera.rays(), centre=c, locations=locs, rect=rect.astype(np.int32),
        rect_area=area.astype(np.int64), normal=normal, plane=plane,
        bounds=np.stack([corners.min(axis=(0, 1)), corners.max(axis=(0, 1))], 1).ravel(),
        height=float(obj.height) if grid.mode == "ground" else 0.0, shape=shape,
        view_part=np.clip(view_part, 0.0, 1.0),
    )


ROUNDING = 1e-9  # metres: two cells whose distance equals a radius up to rounding are not closer


def closer(distance, radius: float):
    """Whether `distance` (metres) is closer than `radius`: less by more than rounding (cells
    4 steps of 0.1 m apart are 0.39999999999999997 or 0.4000000000000001 m apart, by where the
    grid starts; both are 0.4, not closer than 0.4). The detections' suppression, the edge rule,
    the tracker's peaks and the exclusion prior's neighbours (neighbour_lists) all go by it."""
    return distance < radius - ROUNDING


def neighbour_lists(locations: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(start (K + 1,), neighbours): location k's neighbours, the other locations closer than
    `radius` (metres, 3D; closer()), are neighbours[start[k]:start[k + 1]], in index order;
    radius 0: none."""
    from scipy.spatial import cKDTree

    n = len(locations)
    if radius <= 0 or n == 0:
        return np.zeros(n + 1, np.int32), np.zeros(1, np.int32)
    pairs = cKDTree(locations).query_pairs(radius - ROUNDING, output_type="ndarray")  # (at most it)
    if len(pairs):  # query_pairs keeps distances equal to its radius: closer() does not
        pairs = pairs[closer(np.linalg.norm(locations[pairs[:, 0]] - locations[pairs[:, 1]], axis=1), radius)]
    both = np.concatenate([pairs, pairs[:, ::-1]]) if len(pairs) else np.zeros((0, 2), np.int64)
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(both[:, 0], minlength=n), out=start[1:])
    return start.astype(np.int32), (both[:, 1].astype(np.int32) if len(both) else np.zeros(1, np.int32))


@dataclass
class RigGeometry:
    """A rig's full-resolution geometries (`parts`, one a camera, over one grid) as what reads one
    geometry needs of them: the locations; the first camera's rectangles (detections.csv's box);
    each location's largest rectangle area and share in view over the cameras (in view of any
    one: detections, tracking's entry cells, the map's footprint: worked out once, they are read
    every frame); the first camera's centre."""

    parts: list

    @property
    def locations(self) -> np.ndarray:
        return self.parts[0].locations

    @property
    def rect(self) -> np.ndarray:
        return self.parts[0].rect

    @cached_property
    def rect_area(self) -> np.ndarray:
        return np.max([g.rect_area for g in self.parts], axis=0)

    @cached_property
    def view_part(self) -> np.ndarray:
        return np.max([g.view_part for g in self.parts], axis=0)

    @property
    def centre(self) -> np.ndarray:
        return self.parts[0].centre

"""Static structure as background where no background frames say otherwise (issue 60).

The floor-only model explains the floor and nothing else, and `auto` leaves to it the pixels
it could not estimate: every wall, cupboard or desk inside the grid is then evidence for
objects (the end wall of the five-people corridor was three "people"; an office wall faced
level, four a frame). Large planes are no people: the planes Open3D's plane segmentation finds
in the run's first frames (their per-pixel median, which leaves out most of what moves), other
than the floor, that extend at least `min_extent` metres both ways along the plane, cover at
least `min_fill` of their rectangle, stand over the grid and are no person (a plane that is not
level reaches higher than the object; a level one, a desk or a table, lies below `flat_below`),
become background: each pixel whose ray meets such a
plane inside its rectangle (dilated by `margin`) before the floor expects the plane's depth
there (its reading in the frames' median where that lies on the plane: a real wall is not flat
to the sensor's noise), as background frames would have said. A person standing against a wall, or half hidden
in front of one, is at least a body's depth nearer than the plane, so their pixels are not the
plane's and stay evidence for them; what the plane explains is the wall seen between people.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from ._open3d import o3d
from .geometry import Camera
from .values import Bool, Int, Node, Num


class StructureOptions(Node):  # the config's `input.structure` section
    """Large static planes (walls, cupboard fronts, desks) made background without background frames."""

    planes: Bool = Field(True, description="find large planes other than the floor in the first frames and "
                                           "make them background (floor-only, and auto's floor-only pixels)")
    frames: Int = Field(5, ge=1, description="first frames whose per-pixel median the planes are found in")
    min_extent: Num = Field(1.0, gt=0, description="a plane is structure when its inliers span at least this "
                                                   "both ways along it, metres (a person is narrower)")
    min_fill: Num = Field(0.3, gt=0, le=1, description="and cover at least this share of their rectangle")
    distance: Num = Field(0.03, gt=0, description="RANSAC inlier distance, metres")
    margin: Num = Field(0.1, ge=0, description="the plane's rectangle is dilated by this, metres")
    max_planes: Int = Field(8, ge=1, description="planes peeled off the points, largest first")
    floor_gap: Num = Field(0.08, ge=0, description="points this close to the floor are the floor's, metres")
    flat_below: Num = Field(1.0, ge=0, description="a level plane (a desk, a table) counts only below this "
                                                   "height, metres (above it, from a ceiling camera, people's "
                                                   "shoulders and heads make level planes)")
    in_grid: Num = Field(0.2, ge=0, le=1, description="a plane counts when at least this share of its patch lies "
                                                      "over the grid's object boxes (outside them, "
                                                      "model.background_outside_grid already explains walls)")


@dataclass
class StaticPlane:
    """A plane n . X + d = 0 (world, unit n) and the rectangle its inliers span along it:
    origin + a u + b v with a, b within `extent` = (a0, a1, b0, b1)."""

    normal: np.ndarray
    d: float
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    extent: tuple[float, float, float, float]
    inliers: int

    def report(self) -> dict:
        a0, a1, b0, b1 = self.extent
        return {"normal": [round(float(x), 4) for x in self.normal], "d": round(float(self.d), 4),
                "size_m": [round(a1 - a0, 2), round(b1 - b0, 2)], "inliers": self.inliers}


def median_frame(frames_m: list[np.ndarray]) -> np.ndarray:
    """The per-pixel median of the readings of `frames_m` (0 where none has one)."""
    stack = np.stack([np.where(f > 0, f, np.nan) for f in frames_m]).astype(np.float64)
    with warnings.catch_warnings():  # (a pixel no frame reads: its median is nan, then 0)
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(stack, axis=0) if len(frames_m) > 1 else stack[0]
    return np.nan_to_num(med, nan=0.0)


def find_planes(depth_m: np.ndarray, camera: Camera, options: StructureOptions, z_max: float,
                grid_xy: tuple[float, float, float, float], taller: float = 0.0, voxel: float = 0.04,
                min_points: int = 200) -> list[StaticPlane]:
    """The large planes other than the floor among the readings of `depth_m` (module doc), for
    the posed `camera` (the floor is z = 0), that stand over the grid (`grid_xy`: x_min, x_max,
    y_min, y_max of its object boxes) and, where not level, reach higher than `taller` metres
    (no person is that tall: people standing side by side make planes up to their height)."""
    ok = (depth_m > 0) & (depth_m <= z_max)
    if not ok.any():
        return []
    points = camera.centre + depth_m[ok][:, None] * camera.rays()[ok]
    points = points[points[:, 2] > options.floor_gap]  # the floor is the floor model's
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(voxel)
    o3d.utility.random.seed(0)
    planes = []
    for _ in range(options.max_planes):
        if len(cloud.points) < min_points:
            break
        model, idx = cloud.segment_plane(options.distance, 3, 1000)
        if len(idx) < min_points:
            break
        inl = np.asarray(cloud.points)[idx]
        cloud = cloud.select_by_index(idx, invert=True)
        plane = _rectangle(np.asarray(model, np.float64), inl, options, grid_xy, taller)
        if plane is not None:
            planes.append(plane)
    return planes


def _rectangle(model: np.ndarray, inliers: np.ndarray, options: StructureOptions, grid_xy, taller: float,
               cell: float = 0.1) -> StaticPlane | None:
    """The plane of `model` (a, b, c, d) with the rectangle of its largest connected patch of
    inliers (on a `cell` grid along two in-plane axes: horizontal, and up the plane where it is
    not level), or None where that patch is no structure: narrower than min_extent either way
    (people side by side make planes of several person-wide patches), filling less than
    min_fill of its rectangle, level above flat_below, not level and no taller than `taller`, or
    mostly beside the grid."""
    from scipy import ndimage

    n = model[:3] / np.linalg.norm(model[:3])
    d = model[3] / np.linalg.norm(model[:3])
    up = np.array([0.0, 0.0, 1.0])
    u = np.cross(up, n) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    origin = -d * n
    ab = np.stack([(inliers - origin) @ u, (inliers - origin) @ v], 1)
    lo = ab.min(0)
    ij = np.floor((ab - lo) / cell).astype(np.int64)
    grid = np.zeros(ij.max(0) + 1, bool)
    grid[ij[:, 0], ij[:, 1]] = True
    labels, count = ndimage.label(ndimage.binary_closing(grid, iterations=1, border_value=0) | grid)
    if count == 0:
        return None
    sizes = np.bincount(labels[ij[:, 0], ij[:, 1]], minlength=count + 1)
    sizes[0] = 0
    keep = labels[ij[:, 0], ij[:, 1]] == np.argmax(sizes)
    patch = ab[keep]
    points = inliers[keep]
    x0, x1, y0, y1 = grid_xy
    over = (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    level = abs(n[2]) > 0.7
    if (over.mean() < options.in_grid or (level and np.median(points[:, 2]) > options.flat_below)
            or (not level and np.percentile(points[:, 2], 98) <= taller)):
        return None
    a0, a1 = np.percentile(patch[:, 0], [1, 99])
    b0, b1 = np.percentile(patch[:, 1], [1, 99])
    filled = len(np.unique(ij[keep], axis=0)) * cell ** 2
    if min(a1 - a0, b1 - b0) < options.min_extent or filled < options.min_fill * (a1 - a0) * (b1 - b0):
        return None
    return StaticPlane(n, float(d), origin, u, v, (float(a0), float(a1), float(b0), float(b1)), int(keep.sum()))


def plane_depths(planes: list[StaticPlane], rays: np.ndarray, centre: np.ndarray, margin: float) -> np.ndarray:
    """(H, W) the z-depth at which each pixel's ray (rays: world directions whose parameter is
    z-depth) meets the nearest plane inside its dilated rectangle, before the floor; inf where
    it meets none."""
    out = np.full(rays.shape[:2], np.inf)
    floor = np.where(rays[..., 2] < -1e-12, -centre[2] / np.minimum(rays[..., 2], -1e-12), np.inf)
    for p in planes:
        along = rays @ p.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(p.normal @ centre + p.d) / along
        hit = centre + t[..., None] * rays
        a, b = (hit - p.origin) @ p.u, (hit - p.origin) @ p.v
        a0, a1, b0, b1 = p.extent
        inside = ((t > 0) & np.isfinite(t) & (a >= a0 - margin) & (a <= a1 + margin) & (b >= b0 - margin)
                  & (b <= b1 + margin) & (t < floor))
        out = np.where(inside & (t < out), t, out)
    return out

"""Static structure as background where no background frames say otherwise (issue 60).

The floor-only model explains the floor and nothing else, and `auto` leaves to it the pixels it
could not estimate: every wall, cupboard or desk inside the grid is then evidence for objects
(the end wall of the five-people corridor was three "people"; an office wall faced level, four
a frame). Walls are no people: of the planes RANSAC (planes.py: the same planes on every run)
finds in the run's first frames (their per-pixel median, which leaves out most of what moves,
downsampled by Open3D), other than the floor (beside the grid a plane's whole noise band goes
with it: `_peeled`), each connected patch of inliers is judged alone;
an upright one that extends at least `min_extent` metres both ways, covers at least `min_fill`
of its rectangle, stands over the grid and reaches higher than the object becomes background,
and so do flat, solid faces of furniture however high (a cabinet's front or end, a desk:
upright ones `solid_width` wide and `solid_height` tall from the floor up, level ones
`solid_width` both ways below `flat_below`, each column filled over `solid_fill` of their
height, of the part in the image where its edge cuts a column; a person's front fails one of
these), and narrower faces meeting such a face at its
edge (a shelf's end, a cabinet's top). Planes tilted more than 10 degrees from level or upright
are none of these (RANSAC finds such planes through a crowd), nor are level ones under 0.25 m
(the floor, misread by a drifting frame). Each pixel whose ray meets such a plane inside its
rectangle (dilated by `margin`) before the floor, and whose reading in the frames' median is
not beyond it (a ray past a cabinet's edge, inside the margin), expects the plane's depth there
(its reading in the frames' median where that lies on the plane: a real wall is not flat to the
sensor's noise), as background frames would have said. A person standing against a wall, or
half hidden in front of one, is at least a body's depth nearer than the plane, so their pixels
are not the plane's and stay evidence for them; what the plane explains is the wall seen
between people.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
from pydantic import Field

from ._open3d import o3d
from .geometry import Camera
from .planes import segment_plane
from .values import Bool, Int, Node, Num


COS_10, SIN_10 = float(np.cos(np.radians(10))), float(np.sin(np.radians(10)))
LOWEST = 0.25  # metres: a level plane lower than this is the floor (no desk is as low)
BAND = 3.0  # inlier distances: beside the grid, a plane's points this close go with it (its noise band)


class StructureOptions(Node):  # the config's `input.structure` section
    """Large static planes (walls, cupboard fronts, desks) made background without background frames."""

    planes: Bool = Field(True, description="find large planes other than the floor in the first frames and "
                                           "make them background (floor-only, and auto's floor-only pixels)")
    frames: Int = Field(5, ge=1, description="first frames whose per-pixel median the planes are found in")
    min_extent: Num = Field(1.0, gt=0, description="an upright plane (a wall) is structure when its inliers "
                                                   "span at least this both ways along it, metres (a person is "
                                                   "narrower) ...")
    min_fill: Num = Field(0.3, gt=0, le=1, description="... cover at least this share of their rectangle and reach "
                                                       "above object.height + 0.1 m")
    solid_width: Num = Field(0.5, gt=0, description="a flat, solid face (a cabinet's front or side, a desk) is "
                                                    "structure, however high, when its patch is at least this "
                                                    "wide, metres (on the real five-people frame, people's fronts "
                                                    "made flat patches up to 0.48 m wide) ...")
    solid_height: Num = Field(1.0, gt=0, description="... and, upright, at least this tall from the floor up "
                                                     "(level: at least solid_width deep), metres ...")
    solid_fill: Num = Field(0.85, gt=0, le=1, description="... counting only the columns (0.1 m) its inliers "
                                                         "fill over at least this share of its height (there, "
                                                         "fronts reaching the floor filled at most 0.71 of their "
                                                         "rectangle; fuller ones began 0.25 m above it)")
    distance: Num = Field(0.03, gt=0, description="RANSAC inlier distance, metres (or, where larger, the noise "
                                                  "at the point's range of the frames' median: "
                                                  "model.sensor_noise's sigma times sqrt(pi / 2 frames), at "
                                                  "most sigma)")
    margin: Num = Field(0.1, ge=0, description="the plane's rectangle is dilated by this, metres")
    max_planes: Int = Field(16, ge=1, description="planes peeled off the points, largest first")
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
    fill: float = 1.0  # the share of the rectangle its inliers fill (0.1 m cells)
    heights: tuple[float, float, float] = (0.0, 0.0, 0.0)  # its inliers' 1st, 50th, 98th percentile of z
    columns: np.ndarray | None = None  # each 0.1 m column's share of the rectangle's rows (in view) filled ...
    columns_from: float = 0.0  # ... the first's a

    def solid_span(self, fill: float) -> tuple[float, float]:
        """(a0, a1) of the widest run of columns each filling at least `fill` of the rectangle's
        height (a cabinet's front; a person standing flush beside it fills a short band only),
        within the extent; (a0, a0) where none does."""
        a0, a1 = self.extent[:2]
        full = np.append(self.columns >= fill, False) if self.columns is not None else np.array([False])
        best, start = (a0, a0), None
        for i, ok in enumerate(full):
            if ok and start is None:
                start = i
            elif not ok and start is not None:
                lo, hi = max(a0, self.columns_from + 0.1 * start), min(a1, self.columns_from + 0.1 * i)
                best = (lo, hi) if hi - lo > best[1] - best[0] else best
                start = None
        return best

    def narrowed(self, span: tuple[float, float]) -> "StaticPlane":
        return replace(self, extent=(*span, *self.extent[2:]))

    @property
    def level(self) -> bool:
        return abs(self.normal[2]) >= COS_10

    def size(self) -> tuple[float, float]:
        a0, a1, b0, b1 = self.extent
        return a1 - a0, b1 - b0

    def corners(self) -> np.ndarray:
        """(4, 3) the rectangle's corners."""
        a0, a1, b0, b1 = self.extent
        return np.array([self.origin + a * self.u + b * self.v for a in (a0, a1) for b in (b0, b1)])

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


def median_noise(noise: tuple[float, float], frames: int) -> tuple[float, float]:
    """The noise (a, b) of sigma(r) = a + b r^2 of one reading brought to that of the per-pixel
    median of `frames` readings: sigma sqrt(pi / 2 n), the median's spread for many normal
    readings (a little above it for a few: 0.72 sigma for 3, where it is 0.67), at most sigma."""
    spread = min(1.0, float(np.sqrt(np.pi / (2 * max(frames, 1)))))
    return spread * noise[0], spread * noise[1]


def find_planes(depth_m: np.ndarray, camera: Camera, options: StructureOptions, z_max: float,
                grid_xy: tuple[float, float, float, float], taller: float = 0.0, voxel: float = 0.04,
                min_points: int = 200, noise: tuple[float, float] = (0.0, 0.0)) -> list[StaticPlane]:
    """The large planes other than the floor among the readings of `depth_m` (module doc), for
    the posed `camera` (the floor is z = 0), that stand over the grid (`grid_xy`: x_min, x_max,
    y_min, y_max of its object boxes) and, where not level, reach higher than `taller` metres
    (no person is that tall: people standing side by side make planes up to their height). A
    point is a plane's within `options.distance` or the noise at its range, `noise` (a, b) of
    sigma(r) = a + b r^2 (the median's: camera_setup.static_structure), whichever is larger (a
    Kinect's 6 m wall, bent by a few centimetres, is otherwise cut into bands)."""
    ok = (depth_m > 0) & (depth_m <= z_max)
    if not ok.any():
        return []
    points = camera.centre + depth_m[ok][:, None] * camera.rays()[ok]
    points = points[points[:, 2] > options.floor_gap]  # the floor is the floor model's
    cloud = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(voxel).points)
    r = np.linalg.norm(cloud - camera.centre, axis=1)
    tol = np.maximum(options.distance, noise[0] + noise[1] * r ** 2)
    planes, solids, faces = [], [], []
    in_view = seen_by(camera)
    for _ in range(options.max_planes):
        if len(cloud) < min_points:
            break
        model, idx = segment_plane(cloud, tol)
        if len(idx) < min_points:
            break
        for patch in _patches(model, cloud[idx], grid_xy, options.in_grid, min_points // 4, in_view=in_view):
            kind = _kind(patch, options, taller)
            if kind in ("solid", "face"):  # its solid columns only
                patch = patch.narrowed(patch.solid_span(options.solid_fill))
            if kind in ("large", "solid"):
                planes.append(patch)
            if kind == "solid":
                solids.append(patch)
            elif kind == "face":
                faces.append(patch)
        cloud, tol = _peeled(cloud, tol, model, idx, grid_xy)
    return planes + [f for f in faces if any(_meet(f, s, 2 * options.margin) for s in solids)]


def over_grid(points: np.ndarray, grid_xy) -> np.ndarray:
    """Which of `points` (n, 3) lie over the grid's object boxes (`grid_xy`: x_min, x_max, y_min,
    y_max, edges included)."""
    x0, x1, y0, y1 = grid_xy
    return (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)


def _peeled(cloud: np.ndarray, tol: np.ndarray, model: np.ndarray, inliers: np.ndarray, grid_xy) -> tuple:
    """`cloud` and its `tol` less a found plane's `inliers` and, beside the grid's object boxes
    (`grid_xy`), every point within BAND inlier distances of it: a wall beyond the grid is
    model.background_outside_grid's, and the third of its noisy readings outside one inlier
    distance was left as a band that later, tilted planes cut through (16 planes went on a far
    wall's bands and slices of them before a cabinet over the grid's corner was reached)."""
    gone = ~over_grid(cloud, grid_xy) & (np.abs(cloud @ model[:3] + model[3]) <= BAND * tol)
    gone[inliers] = True
    return cloud[~gone], tol[~gone]


def seen_by(camera: Camera):
    """Whether world points (n, 3) lie in `camera`'s image, in front of it."""
    def in_view(points: np.ndarray) -> np.ndarray:
        u, v, z = camera.project(points)
        return (z > 0) & (u >= 0) & (u <= camera.width) & (v >= 0) & (v <= camera.height)
    return in_view


def _patches(model: np.ndarray, inliers: np.ndarray, grid_xy, in_grid: float, min_points: int,
             cell: float = 0.1, in_view=None) -> list[StaticPlane]:
    """The plane of `model` (a, b, c, d) with the rectangle of each connected patch of its
    inliers of at least `min_points` (on a `cell` grid along two in-plane axes: horizontal, and
    up the plane where it is not level; two cabinets' fronts in one plane are two patches), its
    fill and heights, largest first; none where a patch lies mostly beside the grid (`grid_xy`:
    less than `in_grid` of it over) or the plane is tilted more than 10 degrees from level or
    upright (walls and furniture are either; RANSAC finds tilted planes through a crowd).
    `in_view(points) -> bool`: where given, each column's fill is of its rows whose centre lies
    in the image (the image's edge cuts a shelf's front seen from the side: what is in view is solid)."""
    from scipy import ndimage

    n = model[:3] / np.linalg.norm(model[:3])
    d = model[3] / np.linalg.norm(model[:3])
    if not (abs(n[2]) >= COS_10 or abs(n[2]) <= SIN_10):
        return []
    up = np.array([0.0, 0.0, 1.0])
    u = np.cross(up, n) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0]) - n[0] * n  # (in the plane)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    origin = -d * n
    ab = np.stack([(inliers - origin) @ u, (inliers - origin) @ v], 1)
    lo = ab.min(0)
    ij = np.floor((ab - lo) / cell).astype(np.int64)
    grid = np.zeros(ij.max(0) + 1, bool)
    grid[ij[:, 0], ij[:, 1]] = True
    labels, count = ndimage.label(ndimage.binary_closing(grid, iterations=1, border_value=0) | grid)
    label = labels[ij[:, 0], ij[:, 1]]
    sizes = np.bincount(label, minlength=count + 1)
    sizes[0] = 0
    out = []
    for k in np.argsort(-sizes, kind="stable"):
        if sizes[k] < min_points:
            break
        keep = label == k
        patch, points = ab[keep], inliers[keep]
        if np.mean(over_grid(points, grid_xy)) < in_grid:
            continue
        a0, a1 = np.percentile(patch[:, 0], [1, 99])
        b0, b1 = np.percentile(patch[:, 1], [1, 99])
        cells = np.unique(ij[keep], axis=0)
        fill = len(cells) * cell ** 2 / max((a1 - a0) * (b1 - b0), cell ** 2)
        heights = tuple(float(z) for z in np.percentile(points[:, 2], [1, 50, 98]))
        rows = np.arange(np.floor((b0 - lo[1]) / cell), np.floor((b1 - lo[1]) / cell) + 1).astype(np.int64)
        inside = cells[np.isin(cells[:, 1], rows)]  # each column's filled rows within b0..b1
        columns = np.bincount(inside[:, 0], minlength=grid.shape[0]) / len(rows)
        if in_view is not None:  # a column the image's edge cuts: the share of its rows in view
            a = lo[0] + (np.arange(grid.shape[0]) + 0.5) * cell
            b = lo[1] + (rows + 0.5) * cell
            centres = origin + a[:, None, None] * u + b[None, :, None] * v
            seen = in_view(centres.reshape(-1, 3)).reshape(len(a), len(b)).sum(1)
            columns = np.where(seen > 0, np.minimum(columns * len(rows) / np.maximum(seen, 1), 1.0), 0.0)
        out.append(StaticPlane(n, float(d), origin, u, v, (float(a0), float(a1), float(b0), float(b1)),
                               int(keep.sum()), float(fill), heights, columns, float(lo[0])))
    return out


def _kind(p: StaticPlane, options: StructureOptions, taller: float) -> str | None:
    """What the patch `p` is (module doc): "large" (a wall), "solid" (a flat
    face of furniture), "face" (a flat face too narrow alone, structure where it meets a solid
    face at its edge: a shelf's end, a cabinet's top), or None (people side by side make planes
    of several person-wide patches, a person's front a narrow or gappy one)."""
    (w, h), (z_low, z_mid, z_top) = p.size(), p.heights
    if p.level and z_mid < LOWEST:  # the floor, misread (a frame that drifts 3 % from 3 m reads it 9 cm off)
        return None
    if p.level:  # a desk, a table: low; (above, from a ceiling camera, heads and shoulders)
        placed, tall_enough, standing = z_mid <= options.flat_below, h >= options.solid_width, True
    else:  # a wall reaches above any person; a cabinet's face stands on the floor
        placed, tall_enough = z_top > taller, h >= options.solid_height
        standing = z_low <= options.floor_gap + 0.1
    if min(w, h) >= options.min_extent and p.fill >= options.min_fill and placed and not p.level:
        return "large"  # (a level plane a third filled is as likely people's slices: desks must be solid)
    if not standing or (not p.level and not tall_enough):
        return None
    span = p.solid_span(options.solid_fill)
    if span[1] - span[0] >= options.solid_width and tall_enough and (placed or not p.level):
        return "solid"
    return "face" if min(span[1] - span[0], h) >= options.solid_width / 2 else None


def _meet(face: StaticPlane, solid: StaticPlane, within: float) -> bool:
    """Whether `face` meets `solid` at an edge: two of its corners each within `within` of one
    of the solid's, the two planes at least 60 degrees apart (a box's faces)."""
    if abs(face.normal @ solid.normal) > 0.5:
        return False
    gaps = np.linalg.norm(face.corners()[:, None] - solid.corners()[None], axis=2).min(1)
    return int(np.sum(gaps <= within)) >= 2


def plane_depths(planes: list[StaticPlane], rays: np.ndarray, centre: np.ndarray, margin: float,
                 seen: np.ndarray | None = None, tolerance: float = 0.0) -> np.ndarray:
    """(H, W) the z-depth at which each pixel's ray (rays: world directions whose parameter is
    z-depth) meets the nearest plane inside its dilated rectangle, before the floor and, where
    `seen` (H, W) reads the pixel, no nearer than its reading - `tolerance` (a ray that saw
    beyond a plane passed it: past a cabinet's edge, inside the margin); inf where it meets none."""
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
        if seen is not None:
            inside &= ~((seen > 0) & (seen > t + tolerance))
        out = np.where(inside & (t < out), t, out)
    return out

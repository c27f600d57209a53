"""Object shapes: the depth a pixel's ray expects where it meets the object at a location (MODEL.md,
eq. 11's mu), the box whose projection is its silhouette rectangle, and the fields of the kernels'
GeometryArrays that select and describe its Warp function (kernels.pixel_model.object_depth).

A shape is one class here, its keys and its entry in the config's `object` section (ObjectBox,
which builds it) and, for the engine, one branch of object_depth in kernels/pixel_model.py (its
`code`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import ClassVar, Literal

import numpy as np
from pydantic import ConfigDict, Field

from .values import Node, Num

# the kernels' codes of the shapes (kernels.pixel_model.SHAPE_PLANE, SHAPE_SOLID; a test holds
# them equal: kernels/ imports nothing of dpom_warp)
SHAPE_PLANE, SHAPE_SOLID = 0, 1

MIN_TOP_SLOPE = 0.3  # a top's depth spread is at most height_spread / MIN_TOP_SLOPE


@dataclass(frozen=True)
class Shape(ABC):
    """What an object looks like to a camera. Heights are relative to the location's centre
    (the floor point in ground mode, the voxel's centre in voxel mode).

    Class attributes:
        code: which branch of kernels.pixel_model.object_depth is its Warp function.
        counted_area: |S_k| counts the silhouette rectangle's pixels whose rays meet it (else
            the whole rectangle's).
        costly_depth: a ray's depth costs more than reading the engine's pixel table (the
            engine then prefers the table to the tiles, engine.view).
    """

    code: ClassVar[int]
    counted_area: ClassVar[bool] = False
    costly_depth: ClassVar[bool] = False

    bottom: float
    top: float

    @abstractmethod
    def half_extent(self) -> tuple[float, float]:
        """Half the box's size along x and y, metres (its silhouette is the box's projection)."""

    def corners(self, centre: np.ndarray) -> np.ndarray:
        """(K, 8, 3) corners of the boxes at `centre` (K, 3)."""
        hx, hy = self.half_extent()
        offs = np.array([[sx, sy, sz] for sx in (-hx, hx) for sy in (-hy, hy) for sz in (self.bottom, self.top)])
        return centre[:, None, :] + offs[None, :, :]

    @abstractmethod
    def depth(self, geometry, k: int, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mu, var): the z-depth each of `rays` (..., 3) expects of location k of `geometry`
        (geometry.Geometry; -1: the ray misses the object) and the variance the shape adds."""

    def kernel_fields(self) -> dict[str, float]:
        """GeometryArrays' shape fields this shape sets (the others are 0), besides its code."""
        return {}

    def scaled(self, scale: float) -> "Shape":
        """The shape of an object `scale` (<= 1) times as tall above its bottom (a shorter
        person: geometry.Geometry.shorter); its widths kept."""
        return replace(self, top=self.bottom + (self.top - self.bottom) * scale)


@dataclass(frozen=True)
class FacingPlane(Shape):
    """The paper's model: each pixel of the silhouette rectangle expects the depth of the plane
    through the location that faces the camera (Geometry.normal and Geometry.plane); no extra
    variance."""

    code: ClassVar[int] = SHAPE_PLANE

    half_x: float = 0.2
    half_y: float = 0.2

    def half_extent(self) -> tuple[float, float]:
        return self.half_x, self.half_y

    def depth(self, geometry, k: int, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        denom = rays @ geometry.normal[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            mu = np.where(denom < -1e-12, geometry.plane[k] / denom, -1.0)
        return mu, np.zeros_like(mu)


@dataclass(frozen=True)
class Solid(Shape):
    """An upright solid: a vertical body from `hip` to `shoulder` (an ellipse of semi-axes
    `body_radius` across the line of sight and `depth_radius` along it, facing the camera),
    legs of `leg_radius` from `bottom` to `hip` (hip = bottom: none) and a head of
    `head_radius` from `shoulder` to `top` (0: none); a ray expects the depth where it enters
    the nearest of them, through a flat top with the variance of `height_spread` (README, How
    it works). Rays that miss it are not the object's."""

    code: ClassVar[int] = SHAPE_SOLID
    counted_area: ClassVar[bool] = True
    costly_depth: ClassVar[bool] = True

    body_radius: float = 0.2
    head_radius: float = 0.0
    shoulder: float = 0.0
    height_spread: float = 0.0
    leg_radius: float = 0.2
    hip: float = 0.0
    depth_radius: float = 0.2

    def half_extent(self) -> tuple[float, float]:
        return self.body_radius, self.body_radius

    def depth(self, geometry, k: int, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return solid_depth(geometry.centre, rays, geometry.locations[k], self)

    def kernel_fields(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in (
            "body_radius", "head_radius", "bottom", "shoulder", "top", "height_spread", "leg_radius", "hip",
            "depth_radius")}

    def scaled(self, scale: float) -> "Solid":
        """Shoulder and top scaled above the bottom, the radii and the legs kept (the hip no
        higher than the new shoulder), so where the head is no wider than the body its
        projection lies inside the taller solid's silhouette rectangle."""
        shoulder = self.bottom + (self.shoulder - self.bottom) * scale
        return replace(self, shoulder=shoulder, top=self.bottom + (self.top - self.bottom) * scale,
                       hip=min(self.hip, shoulder))


SHAPES: dict[str, type[Shape]] = {"plane": FacingPlane, "solid": Solid}  # object.shape's values


class ObjectBox(Node):  # the config's `object` section
    """The object's size and shape model, metres (`depth` defaults to `width`).

    Attributes:
        shape: 'plane': each pixel of the silhouette rectangle expects the object's depth on
            the plane through the location that faces the camera (the paper's model);
            'solid': each pixel expects the depth where its ray enters the object's upright
            solid, and pixels whose rays miss the solid are not the object's (README, "How
            it works"). The solid is a vertical cylinder of `radius` (the body)
            from the floor to `shoulder` x height, with a coaxial cylinder of `head_radius`
            (the head) up to the full height; centred on its voxel in voxel mode, without a
            head (a drone: a disc).
        radius: body radius, metres (None: width / 2).
        head_radius: head radius, metres (0: no head; ground mode only).
        shoulder: where the body ends and the head begins, share of the height.
        height_spread: standard deviation of the height of the solid's flat tops (people are
            not all of one height), metres; a pixel whose ray enters through a top expects a
            depth that spread / |ray's vertical share| wide (at most 1 / 0.3 of it).
        leg_radius: ground mode: the body's cylinder stops at `hip` x height and a coaxial
            one of this radius (the legs, metres) goes down to the floor; None (or the body
            radius): the body reaches the floor (README, How it works: measured, off).
        hip: where the legs end, share of the height.
        depth_radius: ground mode: the body's half-depth along the line of sight: its
            cross-section is an ellipse of semi-axes `radius` across the line of sight and
            this along it, facing the camera (a torso is narrower front to back than across,
            and the visible front of a person seen from any side is nearer its centre than
            the body's radius); None: a circle of `radius`.
    """

    model_config = ConfigDict(**Node.model_config,
                              json_schema_extra={"description": __doc__.splitlines()[0]})

    width: Num = Field(0.4, gt=0, description="metres, across the line of sight (the solid: its body's "
                                               "diameter); left out in a rig of several cameras: 0.5, a "
                                               "person seen from every side (docs/rig.md)")
    height: Num = Field(1.85, gt=0, description="metres")
    depth: Num | None = Field(None, gt=0, description="default: = width")
    shape: Literal["plane", "solid"] = Field(
        "solid", description="plane: a pixel expects the depth of the plane facing the "
        "camera (the paper); solid: the depth where its ray enters an upright body and head "
        "(README, How it works)")
    radius: Num | None = Field(None, gt=0, description="solid: body radius, metres (default width / 2)")
    head_radius: Num = Field(0.11, ge=0, description="solid: head radius, metres (0: no head; ground grids)")
    shoulder: Num = Field(0.8, gt=0, le=1, description="solid: where the head begins, share of the height")
    height_spread: Num = Field(0.12, ge=0, description="solid: spread of the heights of its tops, metres")
    leg_radius: Num | None = Field(None, gt=0, description="solid, ground grids: the legs' radius below hip x "
                                                           "height, metres (null: the body reaches the floor)")
    hip: Num = Field(0.45, gt=0, lt=1, description="solid: where the legs end, share of the height")
    depth_radius: Num | None = Field(0.12, gt=0,
                                     description="solid, ground grids: the body's half-depth along the line of sight, "
                                                 "metres (an ellipse facing the camera; null: = radius)")

    def __init__(self, *size, **values):
        """ObjectBox(width, height, **others) as well as by name."""
        super().__init__(**dict(zip(("width", "height"), size)), **values)

    @property
    def body_radius(self) -> float:
        return 0.5 * self.width if self.radius is None else float(self.radius)

    def corners(self, centre: np.ndarray, mode: str) -> np.ndarray:
        """(K, 8, 3) corners of the boxes at `centre` (K, 3): standing on it or centred on it.
        A solid's box is its bounding box (2 x radius across)."""
        return self.build(mode).corners(centre)

    def build(self, mode: str) -> Shape:
        """The object's shape in grid mode `mode` ('ground': standing on its location; 'voxel':
        centred on it): heights relative to the location, a solid's body from hip to shoulder
        and its legs below (hip = bottom: none); a drone (voxel mode) has no head."""
        r, h = self.body_radius, self.height
        if self.shape == "plane":
            z0, z1 = (0.0, h) if mode == "ground" else (-0.5 * h, 0.5 * h)
            return FacingPlane(bottom=z0, top=z1, half_x=0.5 * self.width,
                               half_y=0.5 * (self.width if self.depth is None else self.depth))
        if mode == "ground":
            head = self.head_radius > 0 and self.shoulder < 1
            z0, z1, z2 = 0.0, (self.shoulder * h if head else h), h
            rh = self.head_radius if head else 0.0
        else:
            z0, z1, z2, rh = -0.5 * h, 0.5 * h, 0.5 * h, 0.0
        rl = r if self.leg_radius is None else float(self.leg_radius)
        legs = mode == "ground" and rl != r and 0 < self.hip * h < z1
        rl, zh = (rl, self.hip * h) if legs else (r, z0)
        rd = r if self.depth_radius is None or mode != "ground" else float(self.depth_radius)
        return Solid(bottom=z0, top=z2, body_radius=r, head_radius=rh, shoulder=z1, height_spread=self.height_spread,
                     leg_radius=rl, hip=zh, depth_radius=rd)


def cylinder_entry(centre, rays, axis, radius, z0, z1, spread, depth_radius=None):
    """Where each ray enters the vertical cylinder of `radius` about `axis` (x, y) between
    heights z0 and z1 (the camera outside it), and the variance of that depth. With
    `depth_radius` the cross-section is an ellipse facing the camera: semi-axis `radius`
    across the horizontal line from the axis to the camera, `depth_radius` along it (a
    circle when the camera is right above the axis).

    In the ellipse's frame scaled to the unit circle, with u the horizontal unit vector from
    the axis to the camera, L the camera's horizontal distance and v across: the camera sits
    at (0, L / rd), a ray d at (d.v / r, d.u / rd); a circle is rd = r (the same quadratic,
    divided by r^2).

    Args:
        centre: camera centre (3,); rays: (..., 3) directions, ray parameter = z-depth.

    Returns:
        (t, var): (...,) entry z-depth (-1 where the ray misses) and the depth variance of
        the hit: (spread / max(|d_z|, MIN_TOP_SLOPE |d|))^2 through a flat top or bottom, 0
        through the side.
    """
    d = np.asarray(rays, np.float64)
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    ox, oy, cz = centre[0] - axis[0], centre[1] - axis[1], centre[2]
    dist = math.hypot(ox, oy)
    if dist > 1e-9:
        ux, uy, rd = ox / dist, oy / dist, radius if depth_radius is None else depth_radius
    else:  # right above the axis: a circle
        ux, uy, rd = 1.0, 0.0, radius
    du, dv = (dx * ux + dy * uy) / rd, (dy * ux - dx * uy) / radius  # the ray, scaled
    ou = dist / rd  # the camera, scaled (its v is 0)
    a = dx * dx + dy * dy  # the ray's horizontal share, for the top's slope
    a2 = du * du + dv * dv
    b = ou * du
    c = ou * ou - 1.0
    disc = b * b - a2 * c
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = (-b - np.sqrt(np.maximum(disc, 0.0))) / a2
        hs = cz + ts * dz
        side = (c > 0) & (a > 1e-18) & (disc >= 0) & (ts > 0) & (hs >= z0) & (hs <= z1)
        t = np.where(side, ts, np.inf)
        var = np.zeros_like(t)
        slope = np.maximum(np.abs(dz), MIN_TOP_SLOPE * np.sqrt(a + dz * dz))
        for zc, facing in ((z1, cz > z1), (z0, cz < z0)):  # the top seen from above, the bottom from below
            if not facing:
                continue
            tc = (zc - cz) / dz
            pu, pv = ou + tc * du, tc * dv
            cap = (np.abs(dz) > 1e-18) & (tc > 0) & (pu * pu + pv * pv <= 1.0) & (tc < t)
            t = np.where(cap, tc, t)
            var = np.where(cap, (spread / slope) ** 2, var)
    hit = np.isfinite(t)
    return np.where(hit, t, -1.0), np.where(hit, var, 0.0)


def solid_depth(centre, rays, location, solid: Solid):
    """Entry depth (-1: miss) and its variance of each ray into `solid` standing on, or centred
    at, `location` (3,): the nearest of legs, body and head."""
    s, lz = solid, location[2]
    t, var = cylinder_entry(centre, rays, location, s.body_radius, lz + s.hip, lz + s.shoulder, s.height_spread,
                            s.depth_radius)
    if s.hip > s.bottom:  # the legs, below the body
        tl, vl = cylinder_entry(centre, rays, location, s.leg_radius, lz + s.bottom, lz + s.hip, s.height_spread)
        legs = (tl > 0) & ((t < 0) | (tl < t))
        t, var = np.where(legs, tl, t), np.where(legs, vl, var)
    if s.head_radius > 0 and s.top > s.shoulder:
        th, vh = cylinder_entry(centre, rays, location, s.head_radius, lz + s.shoulder, lz + s.top, s.height_spread)
        head = (th > 0) & ((t < 0) | (th < t))
        t, var = np.where(head, th, t), np.where(head, vh, var)
    return t, var

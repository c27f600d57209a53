"""Where a detected person stands, finer than the grid's cells: the centre of their head, found
in the frame's points (docs/tracks.md, Positions).

A map peak puts a person on a cell centre, and the model's upright box over a walking body
(legs and arms swinging, a body turned) moves that cell by centimetres across the line of
sight: rendered walks put tracks 7 cm from the truth on a 0.1 m grid. The head is the body's
most stable part and the one a camera above people sees best. For each detection, each camera
that sees its place: the frame's points (not the background's) within half the object's width of
the cell, above half its height; the topmost of them (above the highest point less the head's
radius) are the upper half of the head, seen from one side. The upper half of a sphere of radius
r sampled evenly over its outline, seen from a distance, has its mean 2/3 r nearer the camera
than its centre along the line of sight (the mean depth of a hemisphere over its disc), so the
head's centre is their mean moved 2/3 r away from the camera along the ray through it; twice, the
second time around the first estimate with a slightly wider radius. A camera gives no position
when too few points are there (a hidden head), when some reach HEAD_ABOVE over the object's
height (a wall, a shelf, a door frame), when the topmost spread wider than a head (a shelf at
head height beside the person), when the head lies farther than FROM_CELL from the cell (a
taller neighbour's) or when the image's edge cuts it (its inner part's mean lies inward); a rig's
position is the mean of its cameras'. Tracks take their frame's detection's head (`place_tracks`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

HEAD_ABOVE = 0.3  # metres above object.height a head may reach (taller people than the box)
MIN_POINTS = 4  # fewer points of a head: no position from this camera
REACH = (0.5, 0.55)  # the two passes' radius around the estimate, in object widths
FROM_CELL = 0.5  # a head farther than this many object widths from its cell is another's
FOREGROUND_M = 0.1  # a point nearer than its pixel's background by this (or 3 sigma) is the frame's own
PIXELS_A_RADIUS = 5  # camera_points reads every step-th pixel, a head's radius this many steps at least
MATCH = 0.5  # a track takes the head of its frame's detection within this share of detection.nms_radius


def head_centre(points: np.ndarray, near: np.ndarray, centre: np.ndarray, width: float, height: float,
                radius: float) -> np.ndarray | None:
    """A head's centre (x, y, z) from one camera's points (N, 3) in the world, around `near`
    (x, y): see the module's docstring; None where the camera does not see a head there.
    `centre`: the camera's centre; `width`, `height`: the object's; `radius`: the head's."""
    est = np.asarray(near, np.float64)[:2]
    for reach in REACH:
        d = np.hypot(points[:, 0] - est[0], points[:, 1] - est[1])
        around = points[(d < reach * width) & (points[:, 2] > 0.5 * height)]
        if len(around) < MIN_POINTS or around[:, 2].max() > height + HEAD_ABOVE:  # (taller than a head: a wall)
            return None
        top = around[around[:, 2] > around[:, 2].max() - radius]
        if len(top) < MIN_POINTS:
            return None
        mean = top.mean(axis=0)
        spread = np.sqrt(np.mean(np.sum((top[:, :2] - mean[:2]) ** 2, axis=1)))
        if spread > radius:  # wider than a head's upper half (its points lie within r of the axis)
            return None
        ray = mean - centre
        head = mean + ray / np.linalg.norm(ray) * (2.0 / 3.0) * radius
        est = head[:2]
    return head


def head_pixels(camera, xy, width: float, height: float, radius: float):
    """Where a head over (x, y) may appear in `camera`'s image: the pixel ranges (row slice,
    column slice) of the box max(REACH) x width around (x, y) from half the object's `height` to
    HEAD_ABOVE and 0.2 m above it, projected, and the pixels a head's radius spans there (at the
    box's mean depth): (None, None, 0) where the box is behind the camera or out of the image."""
    reach = max(REACH) * width
    corners = np.array([[x, y, z] for x in (xy[0] - reach, xy[0] + reach) for y in (xy[1] - reach, xy[1] + reach)
                        for z in (0.5 * height, height + HEAD_ABOVE + 0.2)])  # (what rises above a head)
    u, v, z = camera.project(corners)
    if np.any(z <= 0.05):
        return None, None, 0.0
    u0, u1 = max(int(np.floor(u.min())), 0), min(int(np.ceil(u.max())) + 1, camera.width)
    v0, v1 = max(int(np.floor(v.min())), 0), min(int(np.ceil(v.max())) + 1, camera.height)
    if u0 >= u1 or v0 >= v1:
        return None, None, 0.0
    return slice(v0, v1), slice(u0, u1), camera.fx * radius / float(z.mean())


def inside(camera, head: np.ndarray, radius: float) -> bool:
    """Whether a head (its centre, world metres) lies whole inside `camera`'s image: one the
    image's edge cuts shows its inner part only, whose mean lies inward of the head's."""
    u, v, z = camera.project(head[None])
    r = camera.fx * radius / z[0] if z[0] > 0 else np.inf
    return bool(r <= u[0] <= camera.width - 1 - r and r <= v[0] <= camera.height - 1 - r)


def camera_points(depth: np.ndarray, geometry, rows: slice, cols: slice, background=None, stride: int = 1,
                  scale: float = 1.0, step: int = 1) -> np.ndarray:
    """The world points (N, 3) of one camera's frame (metres, full resolution) in `rows` and
    `cols` (head_pixels), every `step`-th pixel of them, that are not the background's: nearer
    than `background` (a model.Background at the engine's resolution, `stride` pixels a cell;
    its mu 0 where it has none) by FOREGROUND_M or three of its sigma, where it has one.
    `scale`: the frame's drift, divided out first."""
    vs, us = slice(rows.start, rows.stop, step), slice(cols.start, cols.stop, step)
    z = depth[vs, us].astype(np.float64) / scale
    seen = z > 0
    if background is not None:
        r = np.minimum(np.arange(vs.start, vs.stop, step) // stride, background.mu.shape[0] - 1)
        c = np.minimum(np.arange(us.start, us.stop, step) // stride, background.mu.shape[1] - 1)
        mu, sigma = background.mu[np.ix_(r, c)], background.sigma[np.ix_(r, c)]
        seen &= (mu <= 0) | (z < mu - np.maximum(FOREGROUND_M, 3.0 * sigma))
    return geometry.centre + z[seen][:, None] * geometry.rays[vs, us][seen]


def heads(dets, depths: list, cameras: list, geometries: list, backgrounds: list, stride: int, scales: list,
          obj) -> list[tuple[float, float] | None]:
    """Each detection's head position (x, y), or None where no camera sees its head: `depths`,
    `cameras` and `geometries` (full resolution), `backgrounds` (model.Background or None) and
    `scales` one a camera (a depth None: no frame of that camera); `obj` the config's object
    section."""
    radius = float(obj.head_radius)
    out = []
    for d in dets:
        found = []
        for depth, camera, g, bg, s in zip(depths, cameras, geometries, backgrounds, scales):
            if depth is None:
                continue
            rows, cols, pixels = head_pixels(camera, (d.x, d.y), obj.width, obj.height, radius)
            if rows is None:
                continue
            pts = camera_points(depth, g, rows, cols, bg, stride, s, max(1, int(pixels / PIXELS_A_RADIUS)))
            head = head_centre(pts, np.array([d.x, d.y]), g.centre, obj.width, obj.height, radius) if len(pts) else None
            if (head is not None and np.hypot(head[0] - d.x, head[1] - d.y) <= FROM_CELL * obj.width
                    and inside(camera, head, radius)):
                found.append(head[:2])
        out.append(tuple(float(v) for v in np.mean(found, axis=0)) if found else None)
    return out


class HeadFinder:
    """A run's heads (`heads`) frame by frame: its cameras (a rig's list) and geometry (full
    resolution; a rig's parts), its engine's backgrounds, read once at the first frame (set by
    then), the frames' drift divided out, and its object."""

    def __init__(self, cfg, engine, cameras, geometry):
        self.cfg, self.engine = cfg, engine
        self.cameras = list(cameras) if isinstance(cameras, (list, tuple)) else [cameras]
        self.rig = hasattr(geometry, "parts")
        self.parts = list(geometry.parts) if self.rig else [geometry]
        self.backgrounds: list | None = None

    def __call__(self, dets: list, depth, res) -> list:
        if not dets:
            return []
        if self.backgrounds is None:
            self.backgrounds = [head_background(self.engine.background_state(c)) for c in range(len(self.parts))]
        depths = depth if self.rig else [depth]
        drift = res.drift if isinstance(res.drift, list) else [res.drift] * len(depths)
        scales = [d.scale if d is not None and d.applied else 1.0 for d in drift]
        return heads(dets, depths, self.cameras, self.parts, self.backgrounds, self.engine.resolution.stride, scales, self.cfg.obj)


def head_background(state):
    """A camera's background for camera_points from its engine's background_state: None (the
    floor-only model: every point is the frame's), else its model.Background with no depth (mu
    0) where the floor model has the pixel, and each pixel's depth the nearest of its 3 x 3
    neighbours' (the engine's pixels are `stride` of the frame's: at a wall's edge a frame's pixel
    on the wall may fall in an engine pixel that reads what is behind it)."""
    from scipy.ndimage import minimum_filter

    if state is None:
        return None
    bg, fallback = state
    known = bg.mu > 0 if fallback is None else (bg.mu > 0) & ~np.asarray(fallback, bool)
    near = minimum_filter(np.where(known, bg.mu, np.inf), size=3, mode="nearest")
    return dataclasses.replace(bg, mu=np.where(np.isfinite(near), near, 0.0))


def can_place(cfg) -> bool:
    """Whether a run's detections get head positions: tracking.positions `head`, a ground grid
    and a solid object with a head."""
    return (cfg.tracking.positions == "head" and cfg.grid.mode == "ground" and cfg.obj.shape == "solid"
            and cfg.obj.head_radius > 0)


def found_in(record: dict) -> list:
    """A frame record's detections as placed_rows takes them: [(x, y, head (x, y) or None)]."""
    xy = record.get("xy", [])
    return [(p[0], p[1], h) for p, h in zip(xy, record.get("heads") or [None] * len(xy))]


def head_near(found: list | None, xyz, radius: float):
    """The head (x, y) of the nearest of a frame's detections (`found`: [(x, y, head (x, y) or
    None)]) within `radius` of `xyz`, or None."""
    if not found:
        return None
    dist = [np.hypot(x - xyz[0], y - xyz[1]) for x, y, _ in found]
    j = int(np.argmin(dist))
    return found[j][2] if dist[j] <= radius else None


def placed_rows(rows: list, found: list | None, radius: float) -> list:
    """A frame's track rows [(id, xyz, bridged)] with each row that is not bridged moved to the
    head of the nearest of the frame's detections within `radius` of it (head_near; `found`
    None: as they are)."""
    out = []
    for tid, xyz, bridged in rows:
        head = None if bridged else head_near(found, xyz, radius)
        out.append((tid, xyz if head is None else np.array([head[0], head[1], xyz[2]]), bridged))
    return out


def place_tracks(tracks: list, found: list, radius: float) -> int:
    """Tracks (track_files.Track, frames indexing `found`) moved in place: each frame that is
    not bridged at its detection's head (head_near; `found[t]`: frame t's detections); returns
    how many track-frames are at a head."""
    placed = 0
    for tr in tracks:
        for i, t in enumerate(tr.frames):
            head = None if tr.bridged[i] else head_near(found[t], tr.xyz[i], radius)
            if head is not None:
                tr.xyz[i, :2] = head
                placed += 1
    return placed


class Placer:
    """A run's tracks placed at their detections' heads: as each frame's detections come
    (`add`), the rows an online tracker commits (`rows`), and whole tracks (`tracks`). `of(cfg)`
    is None where the run places none (can_place)."""

    def __init__(self, radius: float):
        self.radius, self.found = radius, []

    @classmethod
    def of(cls, cfg) -> "Placer | None":
        return cls(MATCH * cfg.detection.nms_radius) if can_place(cfg) else None

    def add(self, found: list) -> None:
        self.found.append(found)

    def rows(self, frame: int, rows: list) -> list:
        return placed_rows(rows, self.found[frame], self.radius)

    def tracks(self, tracks: list, found: list | None = None) -> int:
        """place_tracks over the frames added (or `found`)."""
        return place_tracks(tracks, self.found if found is None else found, self.radius)

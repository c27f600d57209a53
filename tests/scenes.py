"""Small random scenes for comparing the Warp path with the NumPy reference."""

import numpy as np

from dpom_warp import reference as ref
from dpom_warp.geometry import Camera, Grid, ObjectBox, build_geometry, pose_from_angles
from dpom_warp.model import ModelParams


def draw_slab(depth, geom, k, below=None):
    """Draw location k's object depth (its facing plane, or its solid) into `depth` (in place)
    where it is nearer than what is there; with `below`, only where the object's points are
    lower than that (metres)."""
    u0, v0, u1, v1 = geom.rect[k]
    if u1 < u0:
        return
    rays = geom.rays[v0:v1 + 1, u0:u1 + 1]
    mu, _ = geom.object_depth(k, rays)
    patch = depth[v0:v1 + 1, u0:u1 + 1]
    front = (mu > 0) & ((patch == 0) | (mu < patch))
    if below is not None:
        front &= geom.centre[2] + mu * rays[..., 2] < below
    patch[front] = mu[front]


def random_scene(seed: int, width=48, height=40, shape="plane", step=0.3):
    """A tilted camera over a small grid; depth = floor background with a few fronto-parallel
    slabs standing on it (some hiding others), noise and dropouts; background frames too.
    With shape 'solid', people-like solids (random body and head radii) seen by a camera
    2.4 to 3.4 m high at any pitch from 10 to 90 degrees (tops and sides). `step`: the grid's
    (a finer one gives longer per-pixel lists)."""
    rng = np.random.default_rng(seed)
    pose = pose_from_angles(rng.uniform(1.5, 2.8), rng.uniform(10, 30), rng.uniform(-4, 4))
    height_m = rng.uniform(1.6, 1.9)
    obj = ObjectBox(0.5, height_m, shape="plane")
    if shape == "solid":
        extra = np.random.default_rng(1000 + seed)
        pitch = extra.uniform(10, 90)
        pose = pose_from_angles(extra.uniform(2.4, 3.4), pitch, extra.uniform(-4, 4), extra.uniform(-30, 30),
                                0.0, 3.2 if pitch > 60 else 0.0)
        obj = ObjectBox(0.5, height_m, shape="solid", radius=extra.uniform(0.15, 0.3),
                        head_radius=extra.choice([0.0, extra.uniform(0.08, 0.14)]),
                        shoulder=extra.uniform(0.75, 0.85), height_spread=extra.uniform(0.0, 0.2),
                        leg_radius=extra.choice([None, extra.uniform(0.08, 0.3)]),
                        hip=extra.uniform(0.4, 0.6), depth_radius=extra.choice([None, extra.uniform(0.08, 0.3)]))
    cam = Camera(width, height, 0.8 * width, 0.8 * width, (width - 1) / 2, (height - 1) / 2, pose)
    grid = Grid(x=(-1.5, 1.5, step), y=(1.5, 5.0, step))
    geom = build_geometry(cam, grid, obj)
    params = ModelParams(prior=rng.uniform(0.005, 0.05), sigma_object=rng.uniform(0.05, 0.2),
                         damping=rng.uniform(0.1, 0.4), max_iterations=int(rng.integers(20, 60)),
                         check_every=int(rng.integers(1, 6)), outlier_prob=rng.uniform(0.02, 0.2))
    floor = ref.floor_background(geom, params).mu
    depth = floor.copy()
    # slabs: people-sized boxes drawn at the depth of their facing plane
    for k in rng.choice(len(geom.rect), size=int(rng.integers(1, 5)), replace=False):
        draw_slab(depth, geom, k)
    bg_frames = np.stack([floor + rng.normal(0, 0.01, floor.shape) * (floor > 0) for _ in range(7)])
    bg_frames[rng.random(bg_frames.shape) < 0.1] = 0
    depth = depth + rng.normal(0, 0.02, depth.shape) * (depth > 0)
    depth[rng.random(depth.shape) < 0.05] = 0
    return geom, params, depth.astype(np.float32), bg_frames.astype(np.float32)


def random_rig(seed: int, cameras: int = 2, width=40, height=32, shape="plane", step=0.3):
    """random_scene's room seen by a rig: `cameras` cameras around one grid (the first in front
    of it, the others from its sides and its far end, looking at its middle), the same few
    objects drawn into every camera's frame (so an object hidden from one camera may be seen
    by another). Returns (geometries, params, frames, background frames): lists, one a camera."""
    rng = np.random.default_rng(seed)
    height_m = rng.uniform(1.6, 1.9)
    obj = ObjectBox(0.5, height_m, shape=shape, radius=0.22 if shape == "solid" else None)
    grid = Grid(x=(-1.5, 1.5, step), y=(1.5, 5.0, step))
    spots = [(0.0, 0.0, 0.0), (3.6, 3.25, 90.0), (0.0, 6.5, 180.0), (-3.6, 3.25, -90.0)]
    geoms = []
    for c in range(cameras):
        x, y, yaw = spots[c]
        # yaw turns the view from +y toward -x: (3.6, y) looks along -x at yaw 90
        pose = pose_from_angles(rng.uniform(2.0, 3.0), rng.uniform(20, 40), rng.uniform(-3, 3), yaw, x, y)
        cam = Camera(width, height, 0.7 * width, 0.7 * width, (width - 1) / 2, (height - 1) / 2, pose)
        geoms.append(build_geometry(cam, grid, obj))
    params = ModelParams(prior=rng.uniform(0.005, 0.05), sigma_object=rng.uniform(0.05, 0.2),
                         damping=rng.uniform(0.1, 0.4), max_iterations=int(rng.integers(20, 60)),
                         check_every=int(rng.integers(1, 6)), outlier_prob=rng.uniform(0.02, 0.2))
    people = rng.choice(len(geoms[0].rect), size=int(rng.integers(2, 6)), replace=False)
    frames, backgrounds = [], []
    for g in geoms:
        floor = ref.floor_background(g, params).mu
        depth = floor.copy()
        for k in people:
            draw_slab(depth, g, k)
        bg = np.stack([floor + rng.normal(0, 0.01, floor.shape) * (floor > 0) for _ in range(5)])
        bg[rng.random(bg.shape) < 0.1] = 0
        depth = depth + rng.normal(0, 0.02, depth.shape) * (depth > 0)
        depth[rng.random(depth.shape) < 0.05] = 0
        frames.append(depth.astype(np.float32))
        backgrounds.append(bg.astype(np.float32))
    return geoms, params, frames, backgrounds

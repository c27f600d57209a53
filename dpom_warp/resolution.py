"""Resolution matched to the objects: depth frames reduced by an integer stride before inference.

A person 7 m away still spans ~25 x 90 pixels of a Kinect v2 frame; DPOM's evidence is a sum
over a silhouette's pixels, so a quarter of them in each direction tells the same story for a
sixteenth of the work. The engine then runs on a smaller camera whose pixel (u', v') is the
block of s x s pixels starting at (s u', s v'), with its centre at s u' + (s - 1) / 2:

    fx' = fx / s,  cx' = (cx - (s - 1) / 2) / s   (likewise fy', cy'),

so every block's ray is exactly the full camera's ray through the block centre (lens
distortion acts on normalised coordinates and is unchanged). Pixels past the last whole block
are dropped.

How a block becomes one reading (`reduce`):
- `median` (default): the lower median of the block's readings, missing ones (0, or beyond
  z_max) ignored; no reading when fewer than `min_share` of the block has one. The lower
  median is one of the block's own readings, never a depth between a person and the wall
  behind at an edge, and a single noisy or mixed pixel does not move it.
- `nearest`: the reading of one pixel, (s // 2, s // 2) of the block (plain subsampling).
- `min`: the nearest reading of the block (foreground-biased at edges).

The sensor noise model is unchanged: a block's reading is one of its pixels' readings, whose
noise is the sensor's (the median of n readings of one surface is less noisy, by about
1.25 / sqrt(n), so the model errs on the broad side; sigma_object, 0.1 m, dominates anyway).

Frames, background frames and the floor fit are read at full resolution; only what goes into
the engine is reduced. Pictures, image boxes in detections.csv and ground truth stay in
full-resolution pixels.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np

from .geometry import Camera, Grid
from .shapes import ObjectBox

REDUCERS = ("median", "nearest", "min")
# `auto` keeps at least this many pixels across the object's width at the farthest location
# (measured on the people demo and the robustness scenes, README "Resolution").
AUTO_MIN_PIXELS = 6.0
AUTO_MAX_STRIDE = 8


def strided_camera(camera: Camera, stride: int) -> Camera:
    """The camera whose pixels are the whole s x s blocks of `camera`'s image."""
    if stride == 1:
        return camera
    s = float(stride)
    half = (stride - 1) / 2.0
    return dataclasses.replace(camera, width=camera.width // stride, height=camera.height // stride,
                               fx=camera.fx / s, fy=camera.fy / s, cx=(camera.cx - half) / s,
                               cy=(camera.cy - half) / s)


# blocks of up to this many pixels (stride 5) are sorted by a sorting network, larger ones by
# np.sort, whose time on these short rows is mostly per-row overhead: the median of a 512 x 424
# frame, np.sort against the network, stride 2 4.3 / 1.1 ms, 3 2.8 / 1.0, 4 2.2 / 1.2, 5 2.0 /
# 1.5, 6 2.1 / 2.0, 8 1.8 / 3.0 (2026-12-02, this project's 2-core VM, median of 20)
NETWORK_MAX_BLOCK = 25


@lru_cache(maxsize=None)
def sorting_network(n: int) -> tuple:
    """The comparators (a, b), a < b, of Batcher's odd-even merge sort for n keys: applied in
    order, each putting the smaller of keys a and b at a and the larger at b, they sort any n
    keys. Built for the next power of two; comparators reaching past n are dropped (the keys
    there would be +inf, which no comparator moves)."""
    size = 1
    while size < n:
        size *= 2
    pairs = []
    merged = 1  # sorted runs of this length are merged in pairs
    while merged < size:
        k = merged
        while k >= 1:
            j = k % merged
            while j + k < size:
                for i in range(min(k, size - j - k)):
                    a, b = i + j, i + j + k
                    if a // (2 * merged) == b // (2 * merged):
                        pairs.append((a, b))
                j += 2 * k
            k //= 2
        merged *= 2
    return tuple((a, b) for a, b in pairs if b < n)


def sort_rows(keys: np.ndarray, network_max: int = NETWORK_MAX_BLOCK) -> np.ndarray:
    """(n, ...) keys sorted along the first axis (no NaN): np.sort, or for n <= network_max
    sorting_network's comparators applied to whole rows at once, in place (the same result)."""
    n = len(keys)
    if n > network_max:
        return np.sort(keys, axis=0)
    low = np.empty_like(keys[0])
    for a, b in sorting_network(n):
        np.minimum(keys[a], keys[b], out=low)
        np.maximum(keys[a], keys[b], out=keys[b])
        keys[a] = low
    return keys


def min_readings(stride: int, min_share: float = 0.25) -> int:
    """Valid readings a stride x stride block needs for a min or median (else no reading)."""
    return max(1, int(np.ceil(min_share * stride * stride)))


def reduce_depth(depth_m: np.ndarray, stride: int, how: str = "median", z_max: float = np.inf,
                 min_share: float = 0.25, network_max: int = NETWORK_MAX_BLOCK) -> np.ndarray:
    """(..., H, W) depth in metres (0 = no reading) -> (..., H // s, W // s) float32.

    See the module docstring for `how`; readings above `z_max` count as missing.
    `network_max`: see sort_rows (the result does not depend on it).
    """
    d = np.asarray(depth_m, dtype=np.float32)
    if stride == 1:
        return d
    if how not in REDUCERS:
        raise ValueError(f"reduce: expected one of {', '.join(REDUCERS)}, found {how!r}")
    s = stride
    h, w = d.shape[-2] // s, d.shape[-1] // s
    lead = d.shape[:-2]
    blocks = d[..., :h * s, :w * s].reshape(lead + (h, s, w, s))
    if how == "nearest":
        return np.ascontiguousarray(blocks[..., :, s // 2, :, s // 2])
    blocks = np.moveaxis(blocks, (-3, -1), (0, 1)).reshape((s * s,) + lead + (h, w))  # a row per pixel
    valid = (blocks > 0) & (blocks <= z_max)
    n = valid.sum(0)
    keys = np.where(valid, blocks, np.float32(np.inf))
    if how == "min":
        out = keys.min(0)
    else:
        pick = np.maximum(n - 1, 0) // 2
        out = np.take_along_axis(sort_rows(keys, network_max), pick[None], 0)[0]
    enough = n >= min_readings(s, min_share)
    return np.where(enough, out, 0.0).astype(np.float32)


def farthest_object_pixels(camera: Camera, grid: Grid, obj: ObjectBox) -> float:
    """Width in pixels of the object at the farthest location whose centre is in view (its
    z-depth from the camera), the smallest silhouette the grid asks the engine to see."""
    locs = grid.centres()
    lift = 0.5 * obj.height if grid.mode == "ground" else 0.0
    centres = locs + np.array([0.0, 0.0, lift])
    u, v, z = camera.project(centres)
    seen = (z > 1e-6) & (u >= 0) & (u <= camera.width - 1) & (v >= 0) & (v <= camera.height - 1)
    if not seen.any():
        seen = z > 1e-6
    if not seen.any():
        return 0.0
    width = min(obj.width, obj.depth or obj.width)
    return float(camera.fx * width / z[seen].max())


def auto_stride(camera: Camera, grid: Grid, obj: ObjectBox, min_pixels: float = AUTO_MIN_PIXELS,
                max_stride: int = AUTO_MAX_STRIDE) -> int:
    """The coarsest stride (1, 2, 3, ... up to max_stride) at which the object at the farthest
    location still spans `min_pixels` pixels across, and the reduced image at least 16 x 16."""
    px = farthest_object_pixels(camera, grid, obj)
    s = int(max(1, min(max_stride, px // min_pixels)))
    while s > 1 and min(camera.width // s, camera.height // s) < 16:
        s -= 1
    return s


@dataclasses.dataclass(frozen=True)
class Resolution:
    """How frames reach the engine: the stride, the reducer, and the full-resolution shape."""

    stride: int = 1
    reduce: str = "median"
    z_max: float = np.inf

    def camera(self, camera: Camera) -> Camera:
        return strided_camera(camera, self.stride)

    def frames(self, depth_m: np.ndarray) -> np.ndarray:
        """Full-resolution frame(s) (..., H, W) -> the engine's frame(s)."""
        return reduce_depth(depth_m, self.stride, self.reduce, self.z_max)

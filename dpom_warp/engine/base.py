"""What the engine's parts share: the device, the pixel model's parameters, the buffers' sizes
(the memory budget), the errors and a frame's result."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .. import kernels as K
from ..drift import DriftEstimate
from ..joint import JointLists
from ..model import (
    ModelParams,
)
from ..warp_setup import init_warp


def resolve_device(name: str = "auto") -> str:
    """'auto' -> the first CUDA device when there is one, else 'cpu'; otherwise as given."""
    init_warp()
    if name == "auto":
        cuda = wp.get_cuda_devices()
        return str(cuda[0]) if cuda else "cpu"
    if name == "cuda":
        name = "cuda:0"
    have = [str(d) for d in wp.get_devices()]
    if name not in have:
        why = "" if any(d.startswith("cuda") for d in have) else " (Warp finds no CUDA device here)"
        raise ValueError(f"device: expected one of auto, {', '.join(have)}, found {name!r}{why}")
    return name


def pixel_model(params: ModelParams) -> K.PixelModel:
    pm = K.PixelModel()
    pm.sigma_object2 = params.sigma_object ** 2
    pm.noise_a, pm.noise_b = (float(x) for x in params.sensor_noise)
    pm.log_outlier = math.log(params.outlier_prob) - math.log(params.z_max)
    pm.log_inlier_weight = math.log1p(-params.outlier_prob)
    pm.log_reading = math.log1p(-params.missing_prob)
    pm.z_max = params.z_max
    pm.outlier_prob = params.outlier_prob
    pm.missing_prob = params.missing_prob
    pm.missing_clip = params.missing_clip
    pm.background_occludes = int(params.background_occludes)
    pm.occlusion_margin = params.occlusion_margin
    return pm


ENTRY_BYTES = 4 + 4 + 4 + 8 + 4 + 4  # location, object depth, Delta, B scratch, compact copy
PIXEL_BYTES = 24 + 4 + 4 + 4 + 8 + 32 + 32 + 8 + 4 + 4 + 4  # ray, depth, count, offset, Delta_bg, background
# and its logarithms, compact, floor mask, active and listed pixels
LOCATION_BYTES = 4 * 4 + 24 + 8 + 24 + 8 * 7 + 4 + 4 + 4 + 4 + 60 + 4 + 4  # rect, normal, plane,
# centre, area, five accumulators and the pruning bound, live, live and kept indices, entries,
# top-band, whole-silhouette and shorter band's counts (five each), the damping streak, the
# readings behind
# A batch counts pixel and location bytes once per frame (the geometry is shared: an overestimate).
PAIR_BYTES = 4 + 8 + 8  # tile index: location, lo, hi
TABLE_BYTES = 8 + 32  # pixel table: the walk's key (two float32), the pair (mu, sigma, log sigma, location, W)
TABLE_PIXEL_BYTES = 4  # its start
BEHIND_POINT_BYTES = 4 + 8 + 8 + 8  # model.behind_cost's lattice point: pixel, mu, var, W (Engine._fill_behind_table)
TABLE_BUDGET = 256 * 2**20  # table=None: the pixel table where it holds at most this



def memory_estimate(n_pixels: int, n_locations: int, entries: int, pairs: int = 0,
                    table_pairs: int = 0, table_pixels: int = 0) -> int:
    """Bytes of device memory the engine holds for lists of `entries` entries, a tile index
    of `pairs` (location, tile) pairs and a pixel table of `table_pairs` over `table_pixels`."""
    return (n_pixels * PIXEL_BYTES + n_locations * LOCATION_BYTES + entries * ENTRY_BYTES
            + pairs * PAIR_BYTES + table_pairs * TABLE_BYTES + table_pixels * TABLE_PIXEL_BYTES)


def tile_pairs(rect: np.ndarray, tile: int, tiles_x: int) -> tuple[np.ndarray, np.ndarray]:
    """(location, tile) of every tile that each silhouette rectangle overlaps (int32)."""
    rect = np.asarray(rect, dtype=np.int64)
    t0 = rect[:, :2] // tile
    n_uv = np.where((rect[:, 2:] >= rect[:, :2]).all(1, keepdims=True), rect[:, 2:] // tile - t0 + 1, 0)
    per_loc = n_uv[:, 0] * n_uv[:, 1]
    loc = np.repeat(np.arange(len(rect)), per_loc)
    local = np.arange(len(loc)) - np.repeat(np.cumsum(per_loc) - per_loc, per_loc)
    tx = t0[loc, 0] + local % n_uv[loc, 0]
    ty = t0[loc, 1] + local // n_uv[loc, 0]
    return loc.astype(np.int32), (ty * tiles_x + tx).astype(np.int32)


class MemoryBudgetError(ValueError):
    """The engine's buffers would not fit the memory budget; the message gives the estimate."""


class ListOverflow(RuntimeError):
    """The mask entries of a frame exceed the list capacity and growth is not allowed."""


@dataclass
class FrameResult:
    """Occupancy of one frame. Arrays are flat over locations (map order)."""

    rho: np.ndarray
    rho_star: np.ndarray
    evidence_share: np.ndarray
    iterations: int
    entries: int
    timings: dict = field(default_factory=dict)
    max_change: np.ndarray | None = None
    live: int | None = None  # live locations at the end (sparse iterations)
    kept_entries: int | None = None  # mask entries left after the pruning bound (None: not run)
    pruned: int = 0  # locations the pruning bound removed
    converged: bool = True  # False: stopped at max_iterations above the tolerance
    # with Engine.joint_threshold: what the detections' joint test needs of the frame, for the
    # locations whose rho* reaches that threshold (joint.JointLists; detect.joint_detections)
    joint: JointLists | None = None
    # the frame's depth scale (drift.py; None: not estimated; a rig: a list, one a camera)
    drift: DriftEstimate | list | None = None

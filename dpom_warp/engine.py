"""The Warp inference engine: buffers allocated once per camera and grid, one call per frame
(or per batch of frames)."""

from __future__ import annotations

import ctypes
import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from . import kernels as K
from .geometry import Geometry, neighbour_lists
from .joint import JointLists
from .model import BAND_ALL, MISSING_READ, TOP_MIN_RHO, AutoBackground, Background, ModelParams
from .resolution import Resolution, min_readings
from .warp_setup import init_warp


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


INT32_MAX = 2**31 - 1  # list offsets are int32
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


def _direct(cmd):
    """(entry point, argument block, field names, its address) of a recorded CPU launch that
    Warp invokes with a ctypes block of its arguments (warp's `invoke`, whose block type it
    caches per kernel at the first launch), for Engine._launch to call the entry point with
    a block it keeps; None where the launch is not such (a GPU, tiles, another Warp)."""
    try:
        if not cmd.device.is_cpu or cmd.block_dim > 1 or cmd.adjoint:
            return None
        cached = cmd.kernel._invoke_cache.get((tuple(type(p) for p in cmd.params[1:]), False))
        if cached is None:
            return None
        block_type, fields = cached
        block = block_type()
        names = [f[0] for f in fields]
        for i, name in enumerate(names):
            setattr(block, name, cmd.params[1 + i])
        return cmd.hooks.forward, block, names, ctypes.byref(block)
    except (AttributeError, TypeError, ValueError):
        return None


class _Recorded:
    """Engine._launch's record of one kernel: Warp's recorded command, the dim and inputs of
    its last launch, its direct call (_direct's tuple; None: Warp's Launch.launch) and, for a
    direct call, the bounds of the current dim and those of each dim seen (ctypes refs)."""

    __slots__ = ("cmd", "dim", "inputs", "direct", "bounds", "bounds_of")

    def __init__(self, cmd, dim: int, inputs: list, direct):
        self.cmd, self.dim, self.inputs, self.direct = cmd, dim, list(inputs), direct
        self.bounds = ctypes.byref(cmd.params[0])
        self.bounds_of = {dim: self.bounds}


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


class Engine:
    """DPOM inference for one camera and grid on one Warp device.

    Buffers (per-pixel lists, accumulators) are allocated up front; the list capacity grows
    (and says so in `grown`) only when a frame needs more entries than it holds, up to
    `max_entries` and to what `memory_gb` allows; a frame that needs more is refused with
    ListOverflow, and an engine whose first buffers already exceed the budget is refused
    with MemoryBudgetError, before anything is allocated.

    With `batch` > 1, `infer_batch` runs up to `batch` frames through every launch (their
    pixels and locations side by side); each frame stops at its own iteration, so every
    frame's result is the one `infer` gives it alone. With `graph`, the iteration loop is
    captured once as a graph (a CUDA graph on a GPU; Warp replays CPU graphs too) and replayed
    for every frame or batch: max_iterations launches, no host sync, converged frames skipped.

    Args:
        geometry: silhouettes, facing planes and rays (geometry.build_geometry).
        params: model and inference parameters.
        device: Warp device name ('cpu', 'cuda:0').
        entries_per_pixel: initial list capacity per pixel.
        max_entries: hard cap on the list capacity (None: no cap).
        memory_gb: memory budget of the engine's buffers, GiB (None: no budget).
        tile: edge in pixels of the image tiles of the static mask index (kernels.masks).
        table: the pixel table as the static mask index instead of the tiles (kernels.masks:
            the same lists, built without the object depths, ~1.5x faster with a solid);
            None: with a solid (a facing plane's depth costs little more than reading the
            table), where its pairs (at most the silhouette rectangles' area) take at most
            TABLE_BUDGET and fit memory_gb.
        batch: frames per launch.
        graph: capture the iteration loop as a graph (None: on CUDA devices only).
        resolution: how full-resolution frames are reduced to this engine's pixels (kept for
            the caller: the engine's own arrays are at the geometry's resolution).
        background_auto: the run estimates its background (background.BackgroundEstimator at
            this resolution): its state counts in the memory budget and memory_bytes.
    """

    def __init__(self, geometry: Geometry, params: ModelParams, device: str = "cpu",
                 entries_per_pixel: float = 8.0, max_entries: int | None = None,
                 memory_gb: float | None = None, tile: int = 8, batch: int = 1,
                 graph: bool | None = None, resolution: Resolution | None = None,
                 background_auto: AutoBackground | None = None, table: bool | None = None):
        init_warp()
        if min(params.sensor_noise) < 0:
            raise ValueError(f"sensor_noise: expected [a, b] >= 0, found {list(params.sensor_noise)}")
        if batch < 1 or tile < 1:
            raise ValueError(f"batch and tile: expected integers >= 1, found {batch} and {tile}")
        self.geometry, self.params, self.device = geometry, params, device
        # results carry the joint test's lists of the locations whose rho* reaches this (None: none)
        self.joint_threshold: float | None = None
        self.resolution = resolution or Resolution()
        self.height, self.width = geometry.rays.shape[:2]
        self.n_pixels = self.height * self.width
        self.n_locations = len(geometry.rect)
        self.batch = batch
        self.graph = wp.get_device(device).is_cuda if graph is None else graph
        # the passes' scratch (kernels.evidence_pass): global on a GPU, on the stack on the CPU
        self.local_scratch = 0 if wp.get_device(device).is_cuda else K.SIZED_STACK
        self.one_pass_lists = not wp.get_device(device).is_cuda  # a big stack spills on a GPU
        self._graph, self._graph_lists = None, None
        self._last_rho = None  # the last frame's rho, for params.warm_start
        # full-resolution frames are reduced on a GPU (kernels.frames), by NumPy on the CPU
        self.reduce_on_device = wp.get_device(device).is_cuda
        self._full = None  # their buffer, made at the first such frame
        # the joint test's lists copied out in pixel order by count, scan and fill on a GPU
        # (compact_once's atomics leave them in any order, which the host then sorted: with
        # the per-frame work since batched, half a batched frame's time on an H200), in one
        # pass on the CPU (in order there)
        self.ordered_joint_lists = wp.get_device(device).is_cuda
        # the top band counted a thread per row of each rectangle on a GPU (kernels.top_band_rows:
        # a thread per location, walking its whole rectangle, was the threshold step's longest
        # kernel there), a thread per location on the CPU (one thread: the rows' launch would be
        # the tallest rectangle's rows times longer for nothing)
        self.top_band_by_row = wp.get_device(device).is_cuda
        self.n_live = None  # live locations gathered for the sparse updates (None: every one)
        self.n_active = None  # pixels with live entries, for the sparse evidence passes (None: every one)
        self.sparse_on_lists = False  # the sparse passes walk the lists (nothing has died yet)
        self.n_kept = None  # locations neither pruned nor idle, for the full passes' updates
        self.n_listed = None  # pixels with entries after the pruning, for the passes over the lists
        self.tile, tiles_x = tile, -(-self.width // tile)
        self.n_tiles = tiles_x * -(-self.height // tile)
        P, L = batch * self.n_pixels, batch * self.n_locations
        # the optical axis: every ray's parameter is its z-depth, d . forward = 1
        rays = geometry.rays.reshape(-1, 3)
        self.forward = wp.vec3d(*(float(x) for x in np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)[0]))
        self.extra_bytes = background_auto.state_bytes(self.n_pixels) if background_auto else 0
        with wp.ScopedDevice(device):
            self.geo = self._geometry_arrays(geometry)
        self.pm = pixel_model(params)
        behind_points = self._count_behind_points()  # counted first: the table is in the budget
        self.behind_table = int(behind_points.sum())
        self.extra_bytes += BEHIND_POINT_BYTES * self.behind_table + 4 * (self.n_locations + 1)  # and its starts
        start, nbrs = neighbour_lists(geometry.locations, params.exclusion_radius if params.exclusion > 0 else 0.0)
        self.extra_bytes += 4 * (len(start) + len(nbrs))  # model.exclusion's neighbour lists
        most = int(geometry.rect_area.sum())  # the pixel table's pairs at most
        table_bytes = memory_estimate(0, 0, 0, table_pairs=most, table_pixels=self.n_pixels)
        if table is None:
            table = geometry.solid[0] > 0 and table_bytes <= TABLE_BUDGET and (
                memory_gb is None or memory_estimate(P, L, max(1024, int(entries_per_pixel * P)))
                + self.extra_bytes + table_bytes <= memory_gb * 2**30)
        self.use_table = bool(table)
        pair_loc, pair_tile = (np.zeros(0, np.int32),) * 2 if table else tile_pairs(geometry.rect, tile, tiles_x)
        index_bytes = table_bytes if table else memory_estimate(0, 0, 0, len(pair_loc))
        cap = INT32_MAX if max_entries is None else min(max_entries, INT32_MAX)
        if memory_gb is not None:
            fixed = memory_estimate(P, L, 0) + index_bytes + self.extra_bytes
            cap = min(cap, max(0, int((memory_gb * 2**30 - fixed) // ENTRY_BYTES)))
            first = memory_estimate(P, L, max(1024, int(entries_per_pixel * P))) + index_bytes + self.extra_bytes
            if first > memory_gb * 2**30:
                raise MemoryBudgetError(
                    f"the engine needs at least {first / 2**30:.2f} GiB for {self.n_locations} "
                    f"locations and {self.width}x{self.height} pixels "
                    f"({entries_per_pixel:g} list entries per pixel"
                    f"{f', {batch} frames a batch' if batch > 1 else ''}), above the budget of "
                    f"{memory_gb:g} GiB")
        self.max_entries = cap
        self.grown: list[int] = []
        with wp.ScopedDevice(device):
            self.area = wp.array(geometry.area.astype(np.float64), dtype=wp.float64)
            self.bounds = wp.array(geometry.bounds, dtype=wp.float64)
            self.centre = wp.vec3d(*(float(c) for c in geometry.centre))
            self.depth = wp.zeros((batch, self.height, self.width), dtype=wp.float32)
            self.counts = wp.zeros(P, dtype=wp.int32)
            self.offsets = wp.zeros(P, dtype=wp.int32)
            self.delta_bg = wp.zeros(P, dtype=wp.float64)
            self.bg = wp.zeros((P, 4), dtype=wp.float64)
            self.bg_logs = wp.zeros(P, dtype=wp.vec4d)  # its logarithms (kernels.background_delta)
            self.bg_fresh = True  # bg changed since bg_logs were written
            self.floor_pixels = wp.ones(self.n_pixels, dtype=wp.int32)  # floor-only model here
            self.rho = wp.zeros(L, dtype=wp.float64)
            self.upper = wp.zeros(L, dtype=wp.float64)  # the pruning bound (kernels.sparse)
            self.evidence = wp.zeros(L, dtype=wp.float64)
            self.visible = wp.zeros(L, dtype=wp.float64)
            self.share = wp.zeros(L, dtype=wp.float64)
            self.top_support = wp.zeros(L, dtype=wp.int32)
            self.top_against = wp.zeros(L, dtype=wp.int32)
            self.top_hidden = wp.zeros(L, dtype=wp.int32)
            self.top_missing = wp.zeros(L, dtype=wp.int32)  # no reading where the object would be read
            self.top_seen = wp.zeros(L, dtype=wp.int32)  # the band's pixels in the image (-1: not counted)
            # a shorter solid's band (params.top_heights): its GeometryArrays and counts
            self.shorter_top = [(h, self._geometry_arrays(geometry.shorter(h), self.geo)) for h in params.top_heights
                                if geometry.height > 0]
            self.other_top = [wp.zeros(L, dtype=wp.int32) for _ in range(5 if self.shorter_top else 0)]
            self.top_rows = int((geometry.rect[:, 3] - geometry.rect[:, 1]).max(initial=-1)) + 1  # (shared)
            self.all_support = wp.zeros(L, dtype=wp.int32)  # the same counts, whole silhouette
            self.all_against = wp.zeros(L, dtype=wp.int32)
            self.all_hidden = wp.zeros(L, dtype=wp.int32)
            self.all_missing = wp.zeros(L, dtype=wp.int32)
            self.all_seen = wp.zeros(L, dtype=wp.int32)
            self.rho_star = wp.zeros(L, dtype=wp.float64)
            self.max_change = wp.zeros((batch, max(1, params.max_iterations)), dtype=wp.float64)
            self.done = wp.zeros(batch, dtype=wp.int32)
            self.iterations = wp.zeros(batch, dtype=wp.int32)
            self.live = wp.ones(L, dtype=wp.int32)
            self.streak = wp.zeros(L, dtype=wp.int32)  # per-location damping runs (update_rho)
            self.n_behind = wp.zeros(L, dtype=wp.int32)  # silhouette pixels read behind (behind_count)
            self.live_counts = wp.zeros(P, dtype=wp.int32)
            self.live_offsets = wp.zeros(P, dtype=wp.int32)
            self.live_index = wp.zeros(L, dtype=wp.int32)  # kernels.sparse.gather_live
            self.kept_index = wp.zeros(L, dtype=wp.int32)
            self.per_location = wp.zeros(L, dtype=wp.int32)  # kernels.sparse.prune_lists
            # each frame's entries, live, pruned and kept entries (kernels.sparse.frame_tally)
            self.tallies = wp.zeros((4, batch), dtype=wp.int32)
            self.listed = wp.zeros(P, dtype=wp.int32)  # pixels whose list keeps an entry (prune_lists)
            self.n_listed_out = wp.zeros(1, dtype=wp.int32)
            self.live_count = wp.zeros(3, dtype=wp.int32)  # live locations, compact entries, active pixels
            self.active = wp.zeros(P, dtype=wp.int32)  # pixels with live entries (kernels.sparse.compact_once)
            self.live_changed = wp.zeros(2, dtype=wp.int32)  # live set changed, a location revived
            self.active_next = wp.zeros(P, dtype=wp.int32)  # kernels.sparse.compact_again's output
            self.no_index = wp.zeros(0, dtype=wp.int32)
            self.reserved = wp.zeros(2, dtype=wp.int32)  # kernels.masks.pixel_entries_once
            self.no_reserved = wp.zeros(0, dtype=wp.int32)
            self.candidate = wp.zeros(L, dtype=wp.int32)  # the joint test's locations (joint_lists)
            self.candidate_behind = wp.zeros(L, dtype=wp.int32)  # and their readings behind
            self.not_done = wp.zeros(batch, dtype=wp.int32)
            self.neighbour_start = wp.array(start, dtype=wp.int32)
            self.neighbours = wp.array(nbrs, dtype=wp.int32)
        self._fill_behind_table(behind_points)
        self.tiles = self._tile_index(pair_loc, pair_tile, tiles_x)
        self.table = self._pixel_table(self.use_table)
        self._allocate_lists(int(entries_per_pixel * P))
        self.set_floor_background()

    @staticmethod
    def _geometry_arrays(geometry: Geometry, first: K.GeometryArrays | None = None) -> K.GeometryArrays:
        """The kernels' view of `geometry`; with `first`, the view of a geometry that differs
        from it only in the solid (Geometry.shorter), sharing its arrays."""
        g = K.GeometryArrays()
        if first is None:
            g.rays = wp.array(geometry.rays, dtype=wp.vec3d)
            g.rect = wp.array(geometry.rect, dtype=wp.vec4i)
            g.normal = wp.array(geometry.normal, dtype=wp.vec3d)
            g.plane = wp.array(geometry.plane, dtype=wp.float64)
            g.location = wp.array(geometry.locations, dtype=wp.vec3d)
        else:
            g.rays, g.rect, g.normal, g.plane, g.location = (first.rays, first.rect, first.normal, first.plane,
                                                             first.location)
        g.centre = wp.vec3d(*(float(c) for c in geometry.centre))
        solid = [float(x) for x in geometry.solid]
        g.solid = int(solid[0] > 0)
        g.body_radius, g.head_radius, g.bottom, g.shoulder, g.top, g.height_spread = solid[1:7]
        g.leg_radius, g.hip, g.depth_radius = solid[7:10]
        return g

    def _behind_band(self) -> tuple[float, float]:
        """The heights between which model.behind_cost counts readings behind (ground grids)."""
        p, h = self.params, self.geometry.height
        return (p.behind_low * h, p.behind_high * h) if h > 0 else (-BAND_ALL, BAND_ALL)

    def _behind_statics(self) -> list:
        """behind_points' inputs that describe the core: geometry, band, side share, lattice."""
        p = self.params
        low, high = self._behind_band()
        return [self.geo, self.pm, float(self.geometry.centre[2]), p.behind_side, low, high, p.behind_step,
                self.forward]

    def _count_behind_points(self) -> np.ndarray:
        """How many lattice points of each location's silhouette core model.behind_cost counts
        (kernels.mean_field.behind_points, fill 0); none without behind_cost."""
        L = self.n_locations
        if self.params.behind_cost <= 0 or L == 0:
            return np.zeros(0, np.int64)
        with wp.ScopedDevice(self.device):
            counts = wp.zeros(L, dtype=wp.int32)
            none_i, none_f = wp.zeros(0, dtype=wp.int32), wp.zeros(0, dtype=wp.float64)
            wp.launch(K.behind_points, dim=L, inputs=self._behind_statics() + [0, none_i, counts, none_i, none_f,
                                                                               none_f, none_f])
        return counts.numpy().astype(np.int64)

    def _fill_behind_table(self, counts: np.ndarray):
        """The table of those points (`counts` from _count_behind_points): each one's pixel,
        the object's depth, variance and the mask test's half-width there (behind_points, fill
        1). Static, so built once here and only classified against each frame's readings
        (behind_count)."""
        with wp.ScopedDevice(self.device):
            first = np.zeros(self.n_locations + 1, np.int32)  # all 0: no points (no behind_cost)
            first[1:len(counts) + 1] = np.cumsum(counts)
            self.behind_first = wp.array(first, dtype=wp.int32)
            n = int(first[-1])
            self.behind_pixel = wp.zeros(n, dtype=wp.int32)
            self.behind_mu, self.behind_var, self.behind_half = (wp.zeros(n, dtype=wp.float64) for _ in range(3))
            if n:
                none_i = wp.zeros(0, dtype=wp.int32)
                wp.launch(K.behind_points, dim=len(counts),
                          inputs=self._behind_statics() + [1, self.behind_first, none_i, self.behind_pixel,
                                                           self.behind_mu, self.behind_var, self.behind_half])

    def _tile_index(self, pair_loc, pair_tile, tiles_x) -> K.TileIndex:
        """Depth bounds of every (location, tile) pair, sorted by tile then lo (kernels.masks)."""
        with wp.ScopedDevice(self.device):
            lo = wp.zeros(len(pair_loc), dtype=wp.float64)
            hi = wp.zeros(len(pair_loc), dtype=wp.float64)
            if len(pair_loc):
                wp.launch(K.pair_depth_bounds, dim=len(pair_loc),
                          inputs=[self.geo, self.pm, self.tile, tiles_x, wp.array(pair_loc),
                                  wp.array(pair_tile), lo, hi])
            lo, hi = lo.numpy(), hi.numpy()
            keep = hi >= lo
            order = np.lexsort((lo[keep], pair_tile[keep]))
            tile_of, lo, hi = pair_tile[keep][order], lo[keep][order], hi[keep][order]
            span = np.zeros(self.n_tiles)
            np.maximum.at(span, tile_of, hi - lo)
            t = K.TileIndex()
            t.size, t.tiles_x = self.tile, tiles_x
            t.start = wp.array(np.searchsorted(tile_of, np.arange(self.n_tiles + 1)).astype(np.int32))
            t.loc = wp.array(pair_loc[keep][order], dtype=wp.int32)
            t.lo = wp.array(lo, dtype=wp.float64)
            t.hi = wp.array(hi, dtype=wp.float64)
            t.span = wp.array(span, dtype=wp.float64)
        self.n_pairs = len(lo)
        return t

    def _pixel_table(self, use: bool) -> K.PixelTable:
        """The pixel table (kernels.masks; empty unless `use`): each location's pairs written
        by table_pairs into room for its rectangle's area, gathered, then sorted per pixel by
        (float32 mu, location)."""
        t = K.PixelTable()
        t.use, t.width = int(use), self.width
        n = 0
        with wp.ScopedDevice(self.device):
            if use and self.n_locations:
                room = self.geometry.rect_area.astype(np.int64)  # at most a pair per pixel
                first = np.concatenate([[0], np.cumsum(room)[:-1]])
                counts = wp.zeros(self.n_locations, dtype=wp.int32)
                out = [wp.zeros(int(room.sum()), dtype=d)
                       for d in (wp.int32, wp.int32, wp.float64, wp.float64, wp.float64, wp.float32)]
                wp.launch(K.table_pairs, dim=self.n_locations,
                          inputs=[self.geo, self.pm, self.width, wp.array(first.astype(np.int32)), counts] + out)
                c = counts.numpy()
                n = int(c.sum())
                written = np.repeat(first, c) + (np.arange(n) - np.repeat(np.cumsum(c) - c, c))
                pixel, loc, mu, sigma, log_sigma, half = (a.numpy()[written] for a in out)
                mu32 = mu.astype(np.float32)
                # sorted by (pixel, mu32, loc): the pairs come location by location, so a stable
                # sort on (pixel, mu32) keeps loc ascending among ties; a positive float32's bits
                # sort as its value (mu > 0 here). np.lexsort of the three: ~2x slower
                key = (pixel.astype(np.int64) << 32) | mu32.view(np.int32).astype(np.int64)
                order = np.argsort(key, kind="stable")
                start = np.searchsorted(pixel[order], np.arange(self.n_pixels + 1)).astype(np.int32)
                pairs = np.empty(n, dtype=K.TablePair.numpy_dtype())
                for name, a in (("mu", mu), ("sigma", sigma), ("log_sigma", log_sigma), ("loc", loc), ("half", half)):
                    pairs[name] = a[order]
                t.start, t.pair = wp.array(start), wp.array(pairs, dtype=K.TablePair)
                t.key = wp.zeros(n, dtype=wp.vec2f)  # the walk's window (kernels.masks)
                wp.launch(K.table_window, dim=self.n_pixels, inputs=[t.start, t.pair, t.key])
            else:
                t.start, t.key, t.pair = wp.zeros(1, dtype=wp.int32), wp.zeros(0, dtype=wp.vec2f), wp.zeros(
                    0, dtype=K.TablePair)
        self.n_table = n
        return t

    # -- buffers -------------------------------------------------------------------------
    @property
    def graph(self) -> bool:
        """Whether the iteration loop is captured once and replayed as a graph (engine.graph)."""
        return self._graph_on

    @graph.setter
    def graph(self, on: bool):
        # Engine._launch calls the CPU kernels' entry points itself, which a capture would not
        # record: with a graph every launch is Warp's, and the launches recorded before are dropped
        self._graph_on = bool(on)
        self.direct_launch = not self._graph_on
        self._recorded = {}

    def _allocate_lists(self, capacity: int):
        self._recorded = {}  # Engine._launch: the launches recorded with the old lists
        capacity = min(max(1024, capacity), self.max_entries)
        with wp.ScopedDevice(self.device):
            self.entry_loc = wp.zeros(capacity, dtype=wp.int32)
            self.entry_mu = wp.zeros(capacity, dtype=wp.float32)
            self.entry_delta = wp.zeros(capacity, dtype=wp.float32)
            self.behind = wp.zeros(capacity, dtype=wp.float64)
            self.live_loc = wp.zeros(capacity, dtype=wp.int32)
            self.live_delta = wp.zeros(capacity, dtype=wp.float32)
        self.capacity = capacity

    def memory_bytes(self) -> int:
        """Bytes the engine's buffers hold now (memory_estimate of its sizes, with the auto
        background's state)."""
        return memory_estimate(self.batch * self.n_pixels, self.batch * self.n_locations,
                               self.capacity, self.n_pairs, self.n_table,
                               self.n_pixels if self.use_table else 0) + self.extra_bytes

    # -- background ----------------------------------------------------------------------
    def set_floor_background(self):
        """Use the floor-only background of MODEL.md (no background frames); with
        params.background_outside_grid it is completed from each frame (see reference)."""
        self.floor_pixels.fill_(1)
        self.floor_mode, self.fallback_pixels = True, self.n_pixels
        self._floor_background(0)

    def _floor_background(self, outside_is_static: int):
        wp.launch(K.floor_background, dim=self.depth.shape, device=self.device,
                  inputs=[self.geo.rays, self.centre, self.depth, self.bounds, outside_is_static,
                          self.pm, self.floor_pixels, self.bg])
        self.bg_fresh = True

    def set_background_estimate(self, estimator):
        """Use an auto background (background.BackgroundEstimator at this engine's
        resolution); the pixels it leaves to the floor-only model get that model, completed
        from each frame like set_floor_background. Returns how many pixels those are."""
        if (estimator.height, estimator.width) != (self.height, self.width):
            raise ValueError(f"background estimate: expected {self.width}x{self.height} pixels, "
                             f"found {estimator.width}x{estimator.height}")
        return self.set_background(*estimator.result())

    def set_background_frames(self, frames_m: np.ndarray):
        """Estimate the background from (N, H, W) frames in metres (0 = no reading)."""
        frames = np.ascontiguousarray(frames_m, dtype=np.float32)
        with wp.ScopedDevice(self.device):
            f = wp.array(frames, dtype=wp.float32)
            scratch = wp.zeros((self.n_pixels, frames.shape[0]), dtype=wp.float64)
            wp.launch(K.background_from_frames, dim=(self.height, self.width),
                      inputs=[f, self.pm, scratch, self.batch, self.bg])
        self.floor_mode, self.fallback_pixels, self.bg_fresh = False, 0, True

    def set_background(self, bg: Background, fallback: np.ndarray | None = None):
        """Use a given per-pixel background distribution (arrays of shape (H, W)); pixels
        where `fallback` (H, W) is true get the floor-only model instead, per frame. Returns
        how many pixels those are."""
        b = np.stack([bg.mu, bg.sigma, bg.missing, bg.outlier], -1).reshape(self.n_pixels, 4)
        self.bg.assign(np.ascontiguousarray(np.tile(b, (self.batch, 1)), dtype=np.float64))
        self.bg_fresh = True
        mask = np.zeros(self.n_pixels, np.int32) if fallback is None else np.asarray(fallback).ravel()
        self.floor_pixels.assign(mask.astype(np.int32))
        self.fallback_pixels = int(mask.sum())
        self.floor_mode = self.fallback_pixels > 0
        if self.floor_mode:
            self._floor_background(0)
        return self.fallback_pixels

    def background_state(self) -> tuple | None:
        """What another engine of this camera and grid needs to hold this one's background
        (worker.WorkerSpec.background): None for the floor-only model, else (Background,
        the pixels left to the floor model or None)."""
        if self.floor_mode and self.fallback_pixels == self.n_pixels:
            return None  # the floor-only model, completed from each frame
        fallback = (self.floor_pixels.numpy().reshape(self.height, self.width) > 0
                    if self.fallback_pixels else None)
        return self.background(0), fallback

    def background(self, frame: int = 0) -> Background:
        """The background distribution of frame `frame` of the last batch (arrays (H, W))."""
        return self._background_of(self.bg.numpy(), frame)

    def _background_of(self, bg: np.ndarray, frame: int) -> Background:
        """Frame `frame`'s Background (copies) from the bg buffer as a host array."""
        b = bg.reshape(self.batch, self.height, self.width, 4)[frame]
        return Background(*(np.ascontiguousarray(b[..., i]) for i in range(4)))

    # -- one frame or one batch ----------------------------------------------------------
    def _frames(self, depth_m: np.ndarray) -> np.ndarray:
        """(batch, H', W') float32 of one (H', W') frame or of up to `batch` frames, zero-padded,
        where (H', W') is the engine's (H, W) or, with a stride s > 1, a full-resolution shape
        (H' // s, W' // s = H, W)."""
        d = np.asarray(depth_m, dtype=np.float32)
        d = d[None] if d.ndim == 2 else d
        s = self.resolution.stride
        full = s > 1 and d.ndim == 3 and (d.shape[1] // s, d.shape[2] // s) == (self.height, self.width)
        if d.ndim != 3 or not 1 <= len(d) <= self.batch or d.shape[1:] != (self.height, self.width) and not full:
            hint = f" (or a full-resolution frame at stride {s})" if s > 1 else ""
            raise ValueError(f"depth: expected (H, W) or (n <= {self.batch}, H, W) with H, W = "
                             f"{self.height}, {self.width}{hint}, found {d.shape}")
        if len(d) < self.batch:
            d = np.concatenate([d, np.zeros((self.batch - len(d),) + d.shape[1:], np.float32)])
        return np.ascontiguousarray(d)

    def _set_depth(self, depth_m: np.ndarray):
        """self.depth <- the frames: at the engine's resolution as given; at the camera's full
        resolution reduced as self.resolution says, on a GPU by kernels.frames (a batched
        frame's host work was mostly this reduction), on the CPU by NumPy
        (resolution.reduce_depth, vectorised, where the kernel has one thread)."""
        d = self._frames(depth_m)  # at the engine's (H, W), or else at full resolution
        if d.shape[1:] == (self.height, self.width):
            self.depth.assign(d)
        elif not self.reduce_on_device:
            self.depth.assign(self.resolution.frames(d))
        else:
            if self._full is None or self._full.shape != d.shape:
                self._full = wp.empty(d.shape, dtype=wp.float32, device=self.device)
                self.extra_bytes += d.nbytes
            # straight from the frames' memory: on an H200 a pinned staging copy first took
            # 0.165 ms a kinect_v2 frame at x64 against 0.13 ms (the host's copy cost more than
            # the pinned transfer saved)
            wp.copy(self._full, wp.array(d, dtype=wp.float32, device="cpu", copy=False))
            r = self.resolution
            self._launch(K.reduce_frames, self.depth.shape, [self._full, r.stride, K.frames.HOW[r.reduce],
                                                             float(r.z_max), min_readings(r.stride), self.depth])

    def build_lists(self, depth_m: np.ndarray) -> int:
        """Masks, Delta and depth-sorted per-pixel lists of a frame (H, W) or of up to `batch`
        frames (n, H, W), at the engine's resolution or the camera's full resolution (see
        _set_depth); returns the number of entries."""
        self._set_depth(depth_m)
        if self.floor_mode and self.params.background_outside_grid:
            self._floor_background(1)
        self._launch(K.background_delta, self.depth.shape, [self.depth, self.pm, self.bg, int(self.bg_fresh),
                                                            self.bg_logs, self.delta_bg])
        self.bg_fresh = False
        lists = [self.offsets, self.counts, self.capacity, self.entry_loc, self.entry_mu, self.entry_delta]
        inputs = [self.depth, self.geo, self.pm, self.bg, self.tiles, self.table, self.n_locations]
        if self.one_pass_lists:  # CPU: each mask test once (kernels.masks.pixel_entries_once)
            def one_pass():
                self.reserved.zero_()
                self._launch(K.pixel_entries_once, self.depth.shape, inputs + lists + [self.reserved])
                return (int(x) for x in self.reserved.numpy())

            total, long_lists = one_pass()
            if total > self.capacity:
                self._grow(total)
                lists[2:] = [self.capacity, self.entry_loc, self.entry_mu, self.entry_delta]
                total, long_lists = one_pass()
            if long_lists:  # lists longer than its stack buffer: filled as on a GPU, alone
                self._launch(K.pixel_entries, self.depth.shape, inputs + [1] + lists + [self.reserved])
            return total
        self._launch(K.pixel_entries, self.depth.shape, inputs + [0] + lists + [self.no_reserved])
        wp.utils.array_scan(self.counts, self.offsets, inclusive=False)
        total = int(self.offsets[-1:].numpy()[0]) + int(self.counts[-1:].numpy()[0])
        if total > self.capacity:
            self._grow(total)
            lists[2:] = [self.capacity, self.entry_loc, self.entry_mu, self.entry_delta]
        self._launch(K.pixel_entries, self.depth.shape, inputs + [1] + lists + [self.no_reserved])
        return total

    def _grow(self, total: int):
        """Lists for `total` entries (and a quarter more), or ListOverflow above the cap."""
        if total > self.max_entries or total < 0:
            what = "batch" if self.batch > 1 else "frame"
            raise ListOverflow(
                f"{what} needs {total} mask entries ({total * ENTRY_BYTES / 2**30:.2f} GiB), "
                f"above the cap of {self.max_entries} (engine.max_entries, engine.memory_gb "
                f"and the int32 offsets); coarsen the grid or raise the cap")
        self.grown.append(total)
        self._allocate_lists(int(total * 1.25))

    def iterate(self, it: int, logit_prior: float, damping: float, full: bool = True):
        """One mean-field iteration: evidence pass, then damped update (recording
        max |rho_new - rho| as max_change[frame, it]) of the frames not done. A full pass
        walks every list and updates every location; otherwise the compact lists of the live
        locations (see `compact`) and only those move (kernels.sparse)."""
        full_lists = full or self.sparse_on_lists
        lists = ((self.offsets, self.counts, self.entry_loc, self.entry_delta) if full_lists else
                 (self.live_offsets, self.live_counts, self.live_loc, self.live_delta))
        pixels, active = self.batch * self.n_pixels, self.no_index
        if not full_lists and self.n_active is not None:  # the pixels with live entries alone
            pixels, active = self.n_active, self.active
        elif full_lists and self.n_listed is not None:  # the pixels with entries alone
            pixels, active = self.n_listed, self.listed
        launch, p = self._launch, self.params
        if pixels:
            launch(K.evidence_pass, pixels, [*lists, self.delta_bg, self.rho, self.behind, self.evidence,
                                             self.n_pixels, self.done, self.local_scratch, active])
        index, dim = self.no_index, self.batch * self.n_locations
        if not full and self.n_live is not None:  # the live locations alone (gather_live)
            index, dim = self.live_index, self.n_live
        elif full and self.n_kept is not None:  # all but the pruned and idle ones
            index, dim = self.kept_index, self.n_kept
        if not dim:
            if len(index):  # nothing to update: the iteration still counts
                launch(K.count_iteration, self.batch, [it, self.done, self.iterations])
            return
        if p.exclusion > 0:  # neighbours above the gate push each other down
            launch(K.exclusion_pass, dim, [p.exclusion, p.exclusion_gate, self.rho, self.neighbour_start,
                                           self.neighbours, self.evidence, self.n_locations, self.done,
                                           int(full), self.live, index])
        launch(K.update_rho, dim, [logit_prior, damping, it, self.evidence, self.rho, self.n_locations,
                                   self.done, self.max_change, self.iterations, int(full), p.sparse_epsilon,
                                   self.live, index, self.live_changed, self.streak, p.damping_streak,
                                   p.damping_streak_max, p.behind_cost, self.n_behind, p.sparse_drop])

    def _launch(self, kernel, dim: int, inputs: list):
        """wp.launch of one of a frame's kernels, recorded at its first launch (one record a
        kernel) and replayed after with only the arguments that changed: a launch from Python
        takes ~15 to 30 us on the CPU, and a frame makes ~200. On the CPU outside a capture a
        replay calls the kernel's entry point with an argument block kept between launches (its
        changed fields rewritten, its bounds kept per dim) instead of Warp's Launch.launch,
        which builds the block anew each time (`_direct`)."""
        rec = self._recorded.get(kernel)
        if rec is None:
            cmd = wp.launch(kernel, dim=dim, inputs=inputs, device=self.device, record_cmd=True)
            cmd.launch()
            self._recorded[kernel] = _Recorded(cmd, dim, inputs, _direct(cmd) if self.direct_launch else None)
            return
        cmd, last, direct = rec.cmd, rec.inputs, rec.direct
        for i, v in enumerate(inputs):
            if v is not last[i] and not (type(v) is type(last[i]) and type(v) in (int, float) and v == last[i]):
                last[i] = v
                if direct is None:
                    cmd.set_param_at_index(i, v)
                elif type(v) in (int, float):  # (the iteration, the damping: the block's field takes it)
                    setattr(direct[1], direct[2][i], v)
                else:
                    cmd.set_param_at_index(i, v)
                    setattr(direct[1], direct[2][i], cmd.params[1 + i])
        if dim != rec.dim:
            rec.dim = dim
            if direct is None:
                cmd.set_dim(dim)
            else:  # the bounds of a dim seen before are reused (a few dims recur each frame)
                bounds = rec.bounds_of.get(dim)
                if bounds is None:
                    if len(rec.bounds_of) > 64:
                        rec.bounds_of.clear()
                    cmd.set_dim(dim)
                    bounds = rec.bounds_of[dim] = ctypes.byref(cmd.params[0])
                rec.bounds = bounds
        if direct is None:
            cmd.launch()
        else:
            direct[0](rec.bounds, direct[3])

    def compact(self, live=None, done=None):
        """Copy each pixel's list, in order, keeping the live locations (count, scan, fill):
        those of self.live of the frames not self.done, or of `live` of the frames not `done`."""
        dim = self.batch * self.n_pixels
        live = self.live if live is None else live
        self._launch(K.count_live, dim, [self.offsets, self.counts, self.entry_loc, live, self.n_pixels,
                                         self.done if done is None else done, self.live_counts])
        wp.utils.array_scan(self.live_counts, self.live_offsets, inclusive=False)
        self._launch(K.fill_live, dim, [self.offsets, self.counts, self.entry_loc, self.entry_delta, live,
                                        self.live_offsets, self.live_counts, self.live_loc, self.live_delta])

    def prune(self, logit_prior: float):
        """The pruning bound from the current rho (the start): params.bound_rounds rounds,
        then every location whose bound is below sparse_epsilon leaves the lists for the
        frame (kernels.sparse; no host sync). Without rounds nothing is pruned. Either way a
        location left in no list is marked idle."""
        p, dim = self.params, self.batch * self.n_pixels
        if p.bound_rounds > 0:
            if p.behind_cost > 0:  # a fixed part of each location's evidence: the bound's too
                self._count_behind()
            self.upper.fill_(1.0)
            self.evidence.zero_()
            for _ in range(p.bound_rounds):
                self._launch(K.bound_pass, dim, [self.offsets, self.counts, self.entry_loc, self.entry_delta,
                                                 self.delta_bg, self.rho, self.upper, self.behind, self.evidence,
                                                 self.n_pixels, self.done, self.local_scratch, p.sparse_epsilon])
                self._launch(K.update_bound, len(self.upper),
                             [logit_prior, p.behind_cost, self.n_behind, self.evidence, self.upper,
                              p.sparse_epsilon, self.rho])
            self._launch(K.prune, len(self.upper), [p.sparse_epsilon, self.upper, self.rho, self.live])
        self.per_location.zero_()
        self.n_listed_out.zero_()
        self._launch(K.prune_lists, dim, [self.offsets, self.counts, self.entry_loc, self.entry_mu,
                                          self.entry_delta, self.live, self.per_location, self.listed,
                                          self.n_listed_out])
        self._launch(K.mark_idle, len(self.live), [self.per_location, self.live])

    def _count_behind(self):
        """n_behind: what the lists leave out, the readings behind each listed location's
        object (kernels.behind_count), after counting each location's entries in the lists
        (before the pruning, or after it: the pruned ones are in no list)."""
        self.per_location.zero_()
        self._launch(K.count_entries, self.batch * self.n_pixels,
                     [self.offsets, self.counts, self.entry_loc, self.per_location])
        p = self.params
        self._launch(K.behind_count, len(self.live), [self.depth, self.pm, self.behind_first, self.behind_pixel,
                                                      self.behind_mu, self.behind_var, self.behind_half,
                                                      p.behind_step, self.per_location, self.n_behind])

    def _gather(self, index, compact: str | None = None) -> int:
        """The live locations of the frames not done into `index` (kernels.sparse.gather_live);
        returns how many (a host sync). With `compact`, the compact lists first: "lists" from
        the lists in one pass (kernels.sparse.compact_once), "again" from the compact lists
        themselves (compact_again: only deaths since); n_active, the pixels with live
        entries, is read back in the same sync."""
        self.live_count.zero_()
        if compact == "lists":
            self._launch(K.compact_once, self.batch * self.n_pixels,
                         [self.offsets, self.counts, self.entry_loc, self.entry_delta, self.live, self.n_pixels,
                          self.done, self.live_offsets, self.live_counts, self.live_loc, self.live_delta,
                          self.active, self.live_count])
        elif compact == "again" and self.n_active:
            self._launch(K.compact_again, self.n_active, [self.active, self.live_offsets, self.live_counts,
                                                          self.live_loc, self.live_delta, self.live,
                                                          self.n_pixels, self.done, self.active_next,
                                                          self.live_count])
            self.active, self.active_next = self.active_next, self.active
        self._launch(K.gather_live, len(self.live), [self.live, self.n_locations, self.done, index,
                                                     self.live_count])
        counts = self.live_count.numpy()
        if compact:
            self.n_active = int(counts[2])
        return int(counts[0])

    def _compact_if_changed(self):
        """Before a sparse pass: the compact lists. Driven from the host (no graph), they are
        rebuilt only when the full pass changed which locations are live (update_rho's
        `live_changed`), and the sparse updates then run over the live locations alone (their
        count read back with the flag: one sync, where the loop syncs for its check anyway)."""
        if self.graph:
            self.compact()
            return
        changed, revived = (int(x) for x in self.live_changed.numpy())
        if self.n_live is not None and not changed:
            return  # the same live locations: the compact lists and the index still hold
        self.live_changed.zero_()
        if self.n_live is None and not changed and self.n_kept is not None:
            # the first full pass killed nothing: the compact lists would be the lists, copied
            self.sparse_on_lists = True
            wp.copy(self.live_index, self.kept_index, count=self.n_kept)
            self.n_live = self.n_kept
            return
        again = self.n_live is not None and not revived and not self.sparse_on_lists
        self.sparse_on_lists = False
        self.n_live = self._gather(self.live_index, compact="again" if again else "lists")

    def _check(self, it: int):
        self._launch(K.check_converged, self.batch, [it, self.params.tolerance, self.max_change, self.done])

    def _iterate_all(self, logit_prior: float):
        """The whole loop: up to max_iterations, each frame stopping at its first check
        (every check_every iterations) whose largest change is below the tolerance. With
        sparse iterations the checked iterations are full passes, so a frame stops only when
        a pass over every location has found nothing to revive."""
        p = self.params
        full, self.n_live, self.n_active, self.sparse_on_lists = True, None, None, False
        self.live_changed.zero_()
        for it in range(p.max_iterations):
            was_full, full = full, p.full_pass(it)
            if not full and was_full:
                self._compact_if_changed()
            self.iterate(it, logit_prior, p.damping_at(it), full)
            if (it + 1) % p.check_every == 0:
                self._check(it)
                if not self.graph and self.done.numpy().all():
                    break

    def _run_loop(self, logit_prior: float):
        if not self.graph:
            self._iterate_all(logit_prior)
            return
        lists = (self.entry_loc.ptr, self.capacity)
        if self._graph is None or self._graph_lists != lists:  # new list buffers: new graph
            with wp.ScopedCapture(device=self.device) as capture:
                self._iterate_all(logit_prior)
            self._graph, self._graph_lists = capture.graph, lists
        wp.capture_launch(self._graph)

    def infer(self, depth_m: np.ndarray, start: np.ndarray | None = None) -> FrameResult:
        """Occupancy probabilities of one depth frame (metres, 0 = no reading); `start`:
        the rho to start from (a previous frame's, for warm starts) instead of the prior."""
        return self.infer_batch(np.asarray(depth_m)[None], start)[0]

    def infer_batch(self, depths_m: np.ndarray, start: np.ndarray | None = None) -> list[FrameResult]:
        """Occupancy of up to `batch` frames (n, H, W) at once; one result per frame, each
        equal to what `infer` gives that frame alone. Timings are the batch's. `start`
        (locations,): the rho every frame starts from instead of the prior."""
        p, dev = self.params, self.device
        n = len(depths_m)
        t0 = time.perf_counter()
        self.build_lists(depths_m)
        self.tallies.zero_()  # (the entries counted now: the bound's pruning changes the counts)
        self._launch(K.frame_tally, self.batch * self.n_pixels, [self.counts, self.n_pixels, K.TALLY_SUM, self.tallies, 0])
        wp.synchronize_device(dev)
        t1 = time.perf_counter()
        if start is None and p.warm_start and self._last_rho is not None:
            # capped at the prior: locations found empty start (nearly) empty, while occupied
            # ones start afresh (starting them occupied holds moving people back, +3 cm)
            start = np.minimum(self._last_rho, p.prior)
        if start is None:
            self.rho.fill_(p.prior)
        else:
            self.rho.assign(np.tile(np.asarray(start, dtype=np.float64), self.batch))
        self.live.fill_(1)
        self.streak.zero_()
        self.evidence.zero_()
        self.max_change.zero_()
        self.iterations.zero_()
        self.done.assign(np.arange(self.batch, dtype=np.int32) >= n)  # padding frames: done
        logit_prior = math.log(p.prior) - math.log1p(-p.prior)
        bound = p.sparse_epsilon > 0 and p.bound_rounds > 0
        self.n_kept = self.n_listed = None
        if p.sparse_epsilon > 0:  # the bound, then locations in no list stay where they start
            self.prune(logit_prior)
            if not self.graph:  # full passes update all but the pruned and idle ones, and the
                # passes over the lists run over the pixels with entries (read after one sync)
                self.n_kept = self._gather(self.kept_index)
                self.n_listed = int(self.n_listed_out.numpy()[0])
        if p.behind_cost > 0 and not bound:  # (with the bound, prune counted them first)
            self._count_behind()
        self._run_loop(logit_prior)
        wp.synchronize_device(dev)
        t2 = time.perf_counter()
        self.visible.zero_()
        self._launch(K.transparency_pass, self.batch * self.n_pixels,
                     [self.offsets, self.counts, self.entry_loc, self.rho, self.visible])
        top = p.top_support if self.geometry.height > 0 else 0.0
        unhidden = int(p.share_of == "unhidden")

        def soft_threshold(top_share):
            self._launch(K.soft_threshold, self.batch * self.n_locations,
                         [p.alpha, p.beta, self.area, self.visible, self.rho, self.top_support, self.top_against,
                          self.top_hidden, self.top_missing, self.top_seen, p.top_hidden, p.top_missing,
                          top_share, p.top_slope, p.top_min_pixels, p.top_unseen, p.top_unseen_share,
                          p.top_unseen_part, unhidden, self.all_support, self.all_against, self.share,
                          self.rho_star])

        def top_band(lo, hi, gate, counts, sigmas=0.0, geo=None):
            args = [self.depth, self.geo if geo is None else geo, self.pm, float(self.geometry.centre[2]), lo, hi,
                    TOP_MIN_RHO, sigmas, self.bg, MISSING_READ, gate]
            # (a thread a row while the launch's thread indices fit Warp's 32-bit tid)
            if self.top_band_by_row and self.batch * self.n_locations * self.top_rows < 2 ** 31:
                self._launch(K.top_band_clear, self.batch * self.n_locations, [gate, TOP_MIN_RHO, *counts])
                self._launch(K.top_band_rows, self.batch * self.n_locations * self.top_rows,
                             [*args, self.top_rows, *counts, self.forward])
            else:
                self._launch(K.top_band, self.batch * self.n_locations, [*args, *counts, self.forward])

        if unhidden:
            top_band(-BAND_ALL, BAND_ALL, self.rho,
                     (self.all_support, self.all_against, self.all_hidden, self.all_missing, self.all_seen))
        if top > 0:
            # counted only where rho* before the test (a factor <= 1) reaches TOP_MIN_RHO: the
            # silhouette walk is the threshold's whole cost, and most locations are far below
            if not unhidden:
                soft_threshold(0.0)
            h, gate = self.geometry.height, self.rho if unhidden else self.rho_star
            counts = (self.top_support, self.top_against, self.top_hidden, self.top_missing, self.top_seen)
            top_band(p.top_band * h, h, gate, counts, p.top_sigmas)
            for short, geo in self.shorter_top:  # shorter people: the band whose factor is larger
                top_band(p.top_band * short, short, gate, self.other_top, p.top_sigmas, geo)
                self._launch(K.keep_better_top, self.batch * self.n_locations,
                             [*counts, *self.other_top, p.top_hidden, p.top_missing, top, p.top_slope,
                              p.top_min_pixels, p.top_unseen, self.area, p.top_unseen_part])
        soft_threshold(top)
        # each frame's live and pruned locations and the entries prune_lists kept, counted by
        # location, tallied where they are (a GPU copies back a few integers, not the arrays)
        dim = self.batch * self.n_locations
        self._launch(K.frame_tally, dim, [self.live, self.n_locations, 1, self.tallies, 1])
        self._launch(K.frame_tally, dim, [self.live, self.n_locations, K.PRUNED, self.tallies, 2])
        if bound:
            self._launch(K.frame_tally, dim, [self.per_location, self.n_locations, K.TALLY_SUM, self.tallies, 3])
        entries, live, pruned, kept = self.tallies.numpy()
        kept = kept if bound else [None] * self.batch
        # the maps: a GPU's copies are the host's own (each frame's a row of them), the CPU's are
        # views of the engine's arrays (copied, as the next call rewrites them)
        rho, rho_star, share = (self._host(a).reshape(self.batch, self.n_locations)
                                for a in (self.rho, self.rho_star, self.share))
        iterations, max_change, done = self.iterations.numpy(), self.max_change.numpy(), self.done.numpy()
        self._last_rho = rho[n - 1].copy()
        tj = time.perf_counter()
        joint = [None] * n if self.joint_threshold is None else self.joint_lists(rho_star[:n])
        t3 = time.perf_counter()
        # (joint_lists_s: the part of threshold_s that copies the joint test's lists out)
        timings = {"lists_s": t1 - t0, "iterations_s": t2 - t1, "threshold_s": t3 - t2, "joint_lists_s": t3 - tj,
                   "total_s": t3 - t0}
        if self.batch > 1:
            timings["batch"] = n
        return [FrameResult(rho=rho[f], rho_star=rho_star[f], evidence_share=share[f],
                            iterations=int(iterations[f]), entries=int(entries[f]),
                            max_change=max_change[f, :iterations[f]].copy(), timings=dict(timings),
                            live=int(live[f]), converged=bool(done[f]),
                            kept_entries=None if kept[f] is None else int(kept[f]), pruned=int(pruned[f]),
                            joint=joint[f])
                for f in range(n)]

    @staticmethod
    def _host(a: wp.array) -> np.ndarray:
        """A host array of `a`'s values that the engine's next call leaves alone."""
        return a.numpy() if a.device.is_cuda else a.numpy().copy()

    def joint_lists(self, rho_star: np.ndarray) -> list[JointLists]:
        """After a batch's inference, each frame's JointLists for the locations whose rho*
        (float32, as detect reads the maps) reaches joint_threshold: their entries copied out of
        the lists in order (every frame taken) with each pixel's Delta_bg, and their readings
        behind (kernels.behind_count). A few launches and reads for the batch: on a GPU
        count, scan and fill (`compact`), whose slices come in pixel order, and the pixels
        with entries placed in that order (kernels.sparse.place_active); on the CPU
        kernels.sparse.compact_once in one pass, its slices placed by atomic adds (in pixel
        order on one thread, sorted to be sure) and read through NumPy views of the arrays."""
        n, locations = len(rho_star), self.n_locations
        marked = np.zeros((self.batch, locations), np.int32)
        marked[:n] = np.asarray(rho_star, np.float32) >= self.joint_threshold
        self.candidate.assign(marked.ravel())
        if self.ordered_joint_lists:
            self.compact(self.candidate, self.not_done)
            # the pixels with entries in order: a flag each (into active_next), its inclusive
            # scan (into listed), then each such pixel and its count placed at its rank (into
            # active and active_next: the flags are spent), arrays the iterations are done with
            dim = self.batch * self.n_pixels
            self._launch(K.has_entries, dim, [self.live_counts, self.active_next])
            wp.utils.array_scan(self.active_next, self.listed, inclusive=True)
            self._launch(K.place_active, dim, [self.live_counts, self.listed, self.active, self.active_next])
            pixels = int(self.listed[-1:].numpy()[0])
            index = self.active[:pixels]
            active, count = index.numpy(), self.active_next[:pixels].numpy()
            entries = int(count.sum())
            loc, delta = self.live_loc[:entries].numpy(), self.live_delta[:entries].numpy()
            dbg = self.delta_bg[index].numpy()
        else:
            self.live_count.zero_()
            self._launch(K.compact_once, self.batch * self.n_pixels,
                         [self.offsets, self.counts, self.entry_loc, self.entry_delta, self.candidate, self.n_pixels,
                          self.not_done, self.live_offsets, self.live_counts, self.live_loc, self.live_delta,
                          self.active, self.live_count])
            _, entries, pixels = (int(x) for x in self.live_count.numpy())
            active = np.sort(self.active[:pixels].numpy())
            first, count, dbg = (a.numpy()[active] for a in (self.live_offsets, self.live_counts, self.delta_bg))
            at = np.repeat(first, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
            loc, delta = self.live_loc[:entries].numpy()[at], self.live_delta[:entries].numpy()[at]
        p = self.params
        if p.behind_cost > 0:  # counted for every candidate (n_behind leaves out locations in no list)
            self._launch(K.behind_count, len(self.candidate),
                         [self.depth, self.pm, self.behind_first, self.behind_pixel, self.behind_mu, self.behind_var,
                          self.behind_half, p.behind_step, self.candidate, self.candidate_behind])
            behind = p.behind_cost * self.candidate_behind.numpy().reshape(self.batch, locations).astype(np.float64)
        else:
            behind = np.zeros((self.batch, locations))
        return JointLists.of_batch(np.flatnonzero(marked[:n]), active, count, loc, delta, dbg, behind[:n],
                                   self.geometry.locations, p, locations, self.n_pixels)

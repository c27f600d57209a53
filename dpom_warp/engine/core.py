"""The Warp inference engine: buffers allocated once per camera and grid, one call per frame
(or per batch of frames). The class is put together from one part per step, each in its own
file of this package: statics (the static arrays and buffers), backgrounds, lists (a frame's
per-pixel lists), iterations (the mean field) and threshold (what the joint test needs)."""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from .. import kernels as K
from ..geometry import Geometry, neighbour_lists
from ..drift import DriftOptions
from ..model import (
    AutoBackground,
    ModelParams,
)
from ..resolution import Resolution
from ..warp_setup import init_warp
from .backgrounds import BackgroundMixin
from .drift import DriftMixin
from .base import (
    BEHIND_POINT_BYTES,
    ENTRY_BYTES,
    TABLE_BUDGET,
    FrameResult,
    MemoryBudgetError,
    memory_estimate,
    pixel_model,
    tile_pairs,
)
from .iterations import IterationsMixin
from .lists import ListsMixin
from .statics import StaticsMixin
from .threshold import ThresholdMixin

INT32_MAX = 2**31 - 1  # list offsets are int32


class Engine(StaticsMixin, BackgroundMixin, DriftMixin, ListsMixin, IterationsMixin, ThresholdMixin):
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
        drift: each frame's depth scale estimated against the background and divided out
            before inference (drift.py; None: frames as given).
    """

    def __init__(self, geometry: Geometry, params: ModelParams, device: str = "cpu",
                 entries_per_pixel: float = 8.0, max_entries: int | None = None,
                 memory_gb: float | None = None, tile: int = 8, batch: int = 1,
                 graph: bool | None = None, resolution: Resolution | None = None,
                 background_auto: AutoBackground | None = None, table: bool | None = None,
                 drift: DriftOptions | None = None):
        init_warp()
        if min(params.sensor_noise) < 0:
            raise ValueError(f"sensor_noise: expected [a, b] >= 0, found {list(params.sensor_noise)}")
        if batch < 1 or tile < 1:
            raise ValueError(f"batch and tile: expected integers >= 1, found {batch} and {tile}")
        self.geometry, self.params, self.device, self.drift = geometry, params, device, drift
        # results carry the joint test's lists of the locations whose rho* reaches this (None: none)
        self.joint_threshold: float | None = None
        self.resolution = resolution or Resolution()
        self.height, self.width = geometry.rays.shape[:2]
        self.n_pixels = self.height * self.width
        self.n_locations = len(geometry.rect)
        self.batch = batch
        self._device_policy(device, graph)
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
        pair_loc, pair_tile = self._index_and_capacity(geometry, table, memory_gb, entries_per_pixel,
                                                       max_entries, P, L, tiles_x)
        self.grown: list[int] = []
        self._allocate_arrays(geometry, params, P, L, start, nbrs)
        self._fill_behind_table(behind_points)
        self.tiles = self._tile_index(pair_loc, pair_tile, tiles_x)
        self.table = self._pixel_table(self.use_table)
        self._allocate_lists(int(entries_per_pixel * P))
        self.set_floor_background()

    def _device_policy(self, device: str, graph: bool | None) -> None:
        """What differs between the CPU and a GPU: the captured graph, the passes' scratch, how
        frames are reduced and how the joint test's lists and the top band are gathered."""
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

    def _index_and_capacity(self, geometry: Geometry, table: bool | None, memory_gb: float | None,
                            entries_per_pixel: float, max_entries: int | None, P: int, L: int, tiles_x: int):
        """The static mask index (the pixel table, or the tiles' (location, tile) pairs, returned)
        and the lists' capacity cap within the memory budget; MemoryBudgetError where the first
        buffers already exceed it."""
        tile, batch = self.tile, self.batch
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
        return pair_loc, pair_tile

    def _allocate_arrays(self, geometry: Geometry, params: ModelParams, P: int, L: int, start, nbrs) -> None:
        """Every per-pixel and per-location array of a batch, allocated once (the lists apart:
        _allocate_lists)."""
        batch = self.batch
        with wp.ScopedDevice(self.device):
            self.area = wp.array(geometry.area.astype(np.float64), dtype=wp.float64)
            self.bounds = wp.array(geometry.bounds, dtype=wp.float64)
            self.centre = wp.vec3d(*(float(c) for c in geometry.centre))
            self.depth = wp.zeros((batch, self.height, self.width), dtype=wp.float32)
            # the per-pixel lists (kernels.PixelLists: their entries' arrays by _allocate_lists)
            self.lists, self.compact_lists = K.PixelLists(), K.PixelLists()
            self.lists.counts = wp.zeros(P, dtype=wp.int32)
            self.lists.offsets = wp.zeros(P, dtype=wp.int32)
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
            self.compact_lists.counts = wp.zeros(P, dtype=wp.int32)  # the lists compacted (kernels.sparse)
            self.compact_lists.offsets = wp.zeros(P, dtype=wp.int32)
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

    def infer(self, depth_m: np.ndarray, start: np.ndarray | None = None) -> FrameResult:
        """Occupancy probabilities of one depth frame (metres, 0 = no reading); `start`:
        the rho to start from (a previous frame's, for warm starts) instead of the prior."""
        return self.infer_batch(np.asarray(depth_m)[None], start)[0]

    def infer_batch(self, depths_m: np.ndarray, start: np.ndarray | None = None) -> list[FrameResult]:
        """Occupancy of up to `batch` frames (n, H, W) at once; one result per frame, each
        equal to what `infer` gives that frame alone. Timings are the batch's. `start`
        (locations,): the rho every frame starts from instead of the prior."""
        dev = self.device
        n = len(depths_m)
        t0 = time.perf_counter()
        depths_m, drift = self._correct_drift(depths_m)
        self.build_lists(depths_m)
        self.tallies.zero_()  # (the entries counted now: the bound's pruning changes the counts)
        self._launch(K.frame_tally, self.batch * self.n_pixels,
                     [self.lists.counts, self.n_pixels, K.TALLY_SUM, self.tallies, 0])
        wp.synchronize_device(dev)
        t1 = time.perf_counter()
        logit_prior, bound = self._start(n, start)
        self._run_loop(logit_prior)
        wp.synchronize_device(dev)
        t2 = time.perf_counter()
        self._threshold()
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
                            joint=joint[f], drift=drift[f])
                for f in range(n)]



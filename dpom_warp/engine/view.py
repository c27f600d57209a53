"""One camera of an engine: what is per pixel (the frames, the background, the per-pixel lists,
the static mask index) over the grid's locations, which the engine holds once (engine.core); the
prior's part for the camera (people.Prior.add_camera) beside it. An engine takes a list of cameras over one grid; a kernel that takes
a camera's arrays is launched through that camera's Launcher."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..drift import DriftOptions
from ..geometry import Geometry
from ..model import ModelParams
from ..resolution import Resolution
from .backgrounds import BackgroundMixin
from .base import ENTRY_BYTES, TABLE_BUDGET, MemoryBudgetError, memory_estimate, tile_pairs
from .drift import DriftMixin
from .launch import Launcher
from .lists import ListsMixin
from .statics import StaticsMixin

INT32_MAX = 2**31 - 1  # list offsets are int32


class CameraView(StaticsMixin, BackgroundMixin, DriftMixin, ListsMixin):
    """A camera's pixels over the engine's locations, allocated once for `batch` frames.

    Args:
        geometry: the camera's silhouettes, facing planes and rays over the grid's locations.
        params, pm: the model's parameters and the kernels' pixel model (the engine's).
        device, batch: the engine's Warp device and frames per launch.
        grown: the engine's record of list growth, shared by its cameras.
        prior: the engine's prior (people.Prior), given the camera once it is built.
        shared_bytes: the bytes the engine holds besides this camera (in the memory budget).
        The rest as Engine's arguments of the same names.
    """

    def __init__(self, geometry: Geometry, params: ModelParams, pm: K.PixelModel, device: str, batch: int,
                 grown: list[int], resolution: Resolution, entries_per_pixel: float, max_entries: int | None,
                 memory_gb: float | None, tile: int, table: bool | None, state_bytes: int,
                 drift: DriftOptions | None, shared_bytes: int, one_pass_lists: bool, reduce_on_device: bool,
                 prior):
        self.geometry, self.params, self.pm, self.device, self.batch = geometry, params, pm, device, batch
        self.grown, self.resolution, self.drift = grown, resolution, drift
        self.one_pass_lists, self.reduce_on_device = one_pass_lists, reduce_on_device
        self.launch = Launcher(device)
        self.height, self.width = geometry.rays.shape[:2]
        self.n_pixels = self.height * self.width
        self.n_locations = len(geometry.rect)
        self.n_active = None  # pixels with live entries, for the sparse evidence passes (None: every one)
        self.n_listed = None  # pixels with entries after the pruning, for the passes over the lists
        self._full = None  # full-resolution frames' buffer on a GPU, made at the first such frame
        self.tile, tiles_x = tile, -(-self.width // tile)
        self.n_tiles = tiles_x * -(-self.height // tile)
        P, L = batch * self.n_pixels, batch * self.n_locations
        # the optical axis: every ray's parameter is its z-depth, d . forward = 1
        rays = geometry.rays.reshape(-1, 3)
        self.forward = wp.vec3d(*(float(x) for x in np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)[0]))
        self.extra_bytes = state_bytes
        with wp.ScopedDevice(device):
            self.geo = self._geometry_arrays(geometry)
        self.extra_bytes += prior.camera_bytes(self)  # counted first: it is in the budget
        pair_loc, pair_tile = self._index_and_capacity(table, memory_gb, entries_per_pixel, max_entries, P, L,
                                                       tiles_x, shared_bytes)
        self._allocate_arrays(P)
        prior.add_camera(self)
        self.tiles = self._tile_index(pair_loc, pair_tile, tiles_x)
        self.table = self._pixel_table(self.use_table)
        self._allocate_lists(int(entries_per_pixel * P))
        self.set_floor_background()

    def _index_and_capacity(self, table: bool | None, memory_gb: float | None, entries_per_pixel: float,
                            max_entries: int | None, P: int, L: int, tiles_x: int, shared_bytes: int):
        """The static mask index (the pixel table, or the tiles' (location, tile) pairs, returned)
        and the lists' capacity cap within the memory budget; MemoryBudgetError where the first
        buffers already exceed it."""
        geometry, tile, batch = self.geometry, self.tile, self.batch
        most = int(geometry.rect_area.sum())  # the pixel table's pairs at most
        table_bytes = memory_estimate(0, 0, 0, table_pairs=most, table_pixels=self.n_pixels)
        extra = self.extra_bytes + shared_bytes
        if table is None:
            table = geometry.shape.costly_depth and table_bytes <= TABLE_BUDGET and (
                memory_gb is None or memory_estimate(P, L, max(1024, int(entries_per_pixel * P)))
                + extra + table_bytes <= memory_gb * 2**30)
        self.use_table = bool(table)
        pair_loc, pair_tile = (np.zeros(0, np.int32),) * 2 if table else tile_pairs(geometry.rect, tile, tiles_x)
        index_bytes = table_bytes if table else memory_estimate(0, 0, 0, len(pair_loc))
        cap = INT32_MAX if max_entries is None else min(max_entries, INT32_MAX)
        if memory_gb is not None:
            fixed = memory_estimate(P, L, 0) + index_bytes + extra
            cap = min(cap, max(0, int((memory_gb * 2**30 - fixed) // ENTRY_BYTES)))
            first = memory_estimate(P, L, max(1024, int(entries_per_pixel * P))) + index_bytes + extra
            if first > memory_gb * 2**30:
                raise MemoryBudgetError(
                    f"the engine needs at least {first / 2**30:.2f} GiB for {self.n_locations} "
                    f"locations and {self.width}x{self.height} pixels "
                    f"({entries_per_pixel:g} list entries per pixel"
                    f"{f', {batch} frames a batch' if batch > 1 else ''}), above the budget of "
                    f"{memory_gb:g} GiB")
        self.max_entries = cap
        return pair_loc, pair_tile

    def _allocate_arrays(self, P: int) -> None:
        """Every per-pixel array of a batch and the camera's per-location geometry, allocated
        once (the lists' entries apart: _allocate_lists)."""
        geometry = self.geometry
        with wp.ScopedDevice(self.device):
            self.area = wp.array(geometry.area.astype(np.float64), dtype=wp.float64)
            self.bounds = wp.array(geometry.bounds, dtype=wp.float64)
            self.centre = wp.vec3d(*(float(c) for c in geometry.centre))
            self.depth = wp.zeros((self.batch, self.height, self.width), dtype=wp.float32)
            # the per-pixel lists (kernels.PixelLists: their entries' arrays by _allocate_lists)
            self.lists, self.compact_lists = K.PixelLists(), K.PixelLists()
            self.lists.counts = wp.zeros(P, dtype=wp.int32)
            self.lists.offsets = wp.zeros(P, dtype=wp.int32)
            self.delta_bg = wp.zeros(P, dtype=wp.float64)
            self.bg = wp.zeros((P, 4), dtype=wp.float64)
            self.bg_logs = wp.zeros(P, dtype=wp.vec4d)  # its logarithms (kernels.background_delta)
            self.bg_fresh = True  # bg changed since bg_logs were written
            self.floor_pixels = wp.ones(self.n_pixels, dtype=wp.int32)  # floor-only model here
            self.top_rows = int((geometry.rect[:, 3] - geometry.rect[:, 1]).max(initial=-1)) + 1
            self.compact_lists.counts = wp.zeros(P, dtype=wp.int32)  # the lists compacted (kernels.sparse)
            self.compact_lists.offsets = wp.zeros(P, dtype=wp.int32)
            self.listed = wp.zeros(P, dtype=wp.int32)  # pixels whose list keeps an entry (prune_lists)
            self.n_listed_out = wp.zeros(1, dtype=wp.int32)
            self.live_count = wp.zeros(3, dtype=wp.int32)  # (unused), compact entries, active pixels
            self.active = wp.zeros(P, dtype=wp.int32)  # pixels with live entries (kernels.sparse.compact_once)
            self.active_next = wp.zeros(P, dtype=wp.int32)  # kernels.sparse.compact_again's output
            self.reserved = wp.zeros(2, dtype=wp.int32)  # kernels.masks.pixel_entries_once
            self.no_reserved = wp.zeros(0, dtype=wp.int32)

    def memory_bytes(self) -> int:
        """Bytes this camera's buffers hold now (memory_estimate of its sizes, with the auto
        background's state), its share of the locations' counted once by the engine."""
        return memory_estimate(self.batch * self.n_pixels, 0, self.capacity, self.n_pairs, self.n_table,
                               self.n_pixels if self.use_table else 0) + self.extra_bytes

"""A camera's per-pixel lists (engine.view): its frames reduced and uploaded, the masks M_k and
Delta_ki (eq. 12) listed per pixel in depth order, grown when a frame needs more, and compacted
to the live locations (sparse iterations; the engine's sparse step drives that)."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..resolution import min_readings
from .base import ENTRY_BYTES, ListOverflow


class ListsMixin:
    """CameraView: the per-pixel lists of its frames in flight."""

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
            self.launch(K.reduce_frames, self.depth.shape, [self._full, r.stride, K.frames.HOW[r.reduce],
                                                             float(r.z_max), min_readings(r.stride), self.depth])

    def build_lists(self, depth_m: np.ndarray) -> int:
        """Masks, Delta and depth-sorted per-pixel lists of a frame (H, W) or of up to `batch`
        frames (n, H, W), at the engine's resolution or the camera's full resolution (see
        _set_depth); returns the number of entries."""
        self._set_depth(depth_m)
        if self.floor_mode and self.params.background_outside_grid:
            self._floor_background(1)
        self.launch(K.background_delta, self.depth.shape, [self.depth, self.pm, self.bg, int(self.bg_fresh),
                                                            self.bg_logs, self.delta_bg])
        self.bg_fresh = False
        lists = [self.lists, self.capacity]
        inputs = [self.depth, self.geo, self.pm, self.bg, self.tiles, self.table, self.n_locations]
        if self.one_pass_lists:  # CPU: each mask test once (kernels.masks.pixel_entries_once)
            def one_pass():
                self.reserved.zero_()
                self.launch(K.pixel_entries_once, self.depth.shape, inputs + lists + [self.reserved])
                return (int(x) for x in self.reserved.numpy())

            total, long_lists = one_pass()
            if total > self.capacity:
                self._grow(total)
                lists = [self.lists, self.capacity]
                total, long_lists = one_pass()
            if long_lists:  # lists longer than its stack buffer: filled as on a GPU, alone
                self.launch(K.pixel_entries, self.depth.shape, inputs + [1] + lists + [self.reserved])
            return total
        self.launch(K.pixel_entries, self.depth.shape, inputs + [0] + lists + [self.no_reserved])
        wp.utils.array_scan(self.lists.counts, self.lists.offsets, inclusive=False)
        total = int(self.lists.offsets[-1:].numpy()[0]) + int(self.lists.counts[-1:].numpy()[0])
        if total > self.capacity:
            self._grow(total)
            lists = [self.lists, self.capacity]
        self.launch(K.pixel_entries, self.depth.shape, inputs + [1] + lists + [self.no_reserved])
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

    def compact(self, live, done):
        """Copy each pixel's list, in order, keeping the live locations (count, scan, fill): those
        of `live` of the frames not `done`."""
        dim = self.batch * self.n_pixels
        self.launch(K.count_live, dim, [self.lists, live, self.n_pixels, done, self.compact_lists])
        wp.utils.array_scan(self.compact_lists.counts, self.compact_lists.offsets, inclusive=False)
        self.launch(K.fill_live, dim, [self.lists, live, self.compact_lists])

"""A frame's per-pixel lists: the frames reduced and uploaded, the masks M_k and Delta_ki
(eq. 12) listed per pixel in depth order, grown when a frame needs more, pruned by the bound
and compacted to the live locations (sparse iterations)."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..resolution import min_readings
from .base import ENTRY_BYTES, ListOverflow


class ListsMixin:
    """Engine: the per-pixel lists of the frames in flight."""

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
        lists = [self.lists, self.capacity]
        inputs = [self.depth, self.geo, self.pm, self.bg, self.tiles, self.table, self.n_locations]
        if self.one_pass_lists:  # CPU: each mask test once (kernels.masks.pixel_entries_once)
            def one_pass():
                self.reserved.zero_()
                self._launch(K.pixel_entries_once, self.depth.shape, inputs + lists + [self.reserved])
                return (int(x) for x in self.reserved.numpy())

            total, long_lists = one_pass()
            if total > self.capacity:
                self._grow(total)
                lists = [self.lists, self.capacity]
                total, long_lists = one_pass()
            if long_lists:  # lists longer than its stack buffer: filled as on a GPU, alone
                self._launch(K.pixel_entries, self.depth.shape, inputs + [1] + lists + [self.reserved])
            return total
        self._launch(K.pixel_entries, self.depth.shape, inputs + [0] + lists + [self.no_reserved])
        wp.utils.array_scan(self.lists.counts, self.lists.offsets, inclusive=False)
        total = int(self.lists.offsets[-1:].numpy()[0]) + int(self.lists.counts[-1:].numpy()[0])
        if total > self.capacity:
            self._grow(total)
            lists = [self.lists, self.capacity]
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

    def compact(self, live=None, done=None):
        """Copy each pixel's list, in order, keeping the live locations (count, scan, fill):
        those of self.live of the frames not self.done, or of `live` of the frames not `done`."""
        dim = self.batch * self.n_pixels
        live = self.live if live is None else live
        self._launch(K.count_live, dim, [self.lists, live, self.n_pixels, self.done if done is None else done,
                                         self.compact_lists])
        wp.utils.array_scan(self.compact_lists.counts, self.compact_lists.offsets, inclusive=False)
        self._launch(K.fill_live, dim, [self.lists, live, self.compact_lists])

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
                self._launch(K.bound_pass, dim, [self.lists, self.delta_bg, self.rho, self.upper, self.behind,
                                                 self.evidence, self.n_pixels, self.done, self.local_scratch,
                                                 p.sparse_epsilon])
                self._launch(K.update_bound, len(self.upper),
                             [logit_prior, p.behind_cost, self.n_behind, self.evidence, self.upper,
                              p.sparse_epsilon, self.rho])
            self._launch(K.prune, len(self.upper), [p.sparse_epsilon, self.upper, self.rho, self.live])
        self.per_location.zero_()
        self.n_listed_out.zero_()
        self._launch(K.prune_lists, dim, [self.lists, self.live, self.per_location, self.listed, self.n_listed_out])
        self._launch(K.mark_idle, len(self.live), [self.per_location, self.live])

    def _count_behind(self):
        """n_behind: what the lists leave out, the readings behind each listed location's
        object (kernels.behind_count), after counting each location's entries in the lists
        (before the pruning, or after it: the pruned ones are in no list)."""
        self.per_location.zero_()
        self._launch(K.count_entries, self.batch * self.n_pixels,
                     [self.lists, self.per_location])
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
                         [self.lists, self.live, self.n_pixels, self.done, self.compact_lists, self.active,
                          self.live_count])
        elif compact == "again" and self.n_active:
            self._launch(K.compact_again, self.n_active, [self.active, self.compact_lists, self.live,
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

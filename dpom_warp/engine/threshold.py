"""After the iterations: the joint test's lists copied out for the frames' candidates."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..joint import JointLists


class ThresholdMixin:
    """Engine: what the threshold step hands over."""

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

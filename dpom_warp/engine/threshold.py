"""After the iterations: the joint test's lists copied out for the frames' candidates."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..joint import JointLists
from ..model import BAND_ALL, MISSING_READ, TOP_MIN_RHO


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
            self._launch(K.has_entries, dim, [self.compact_lists.counts, self.active_next])
            wp.utils.array_scan(self.active_next, self.listed, inclusive=True)
            self._launch(K.place_active, dim, [self.compact_lists.counts, self.listed, self.active, self.active_next])
            pixels = int(self.listed[-1:].numpy()[0])
            index = self.active[:pixels]
            active, count = index.numpy(), self.active_next[:pixels].numpy()
            entries = int(count.sum())
            loc, delta = self.compact_lists.loc[:entries].numpy(), self.compact_lists.delta[:entries].numpy()
            dbg = self.delta_bg[index].numpy()
        else:
            self.live_count.zero_()
            self._launch(K.compact_once, self.batch * self.n_pixels,
                         [self.lists, self.candidate, self.n_pixels, self.not_done, self.compact_lists,
                          self.active, self.live_count])
            _, entries, pixels = (int(x) for x in self.live_count.numpy())
            active = np.sort(self.active[:pixels].numpy())
            compact = self.compact_lists
            first, count, dbg = (a.numpy()[active] for a in (compact.offsets, compact.counts, self.delta_bg))
            at = np.repeat(first, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
            loc, delta = compact.loc[:entries].numpy()[at], compact.delta[:entries].numpy()[at]
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

    def _threshold(self) -> None:
        """After the iterations: what each location's pixels show of it (transparency pass), the
        top-band counts (with shorter people's bands) and rho* (README, How it works)."""
        p = self.params
        self.visible.zero_()
        self._launch(K.transparency_pass, self.batch * self.n_pixels,
                     [self.lists, self.rho, self.visible])
        top = p.top_support if self.geometry.height > 0 else 0.0
        unhidden = int(p.share_of == "unhidden")
        if unhidden:
            self._top_band(-BAND_ALL, BAND_ALL, self.rho,
                           (self.all_support, self.all_against, self.all_hidden, self.all_missing, self.all_seen))
        if top > 0:
            # counted only where rho* before the test (a factor <= 1) reaches TOP_MIN_RHO: the
            # silhouette walk is the threshold's whole cost, and most locations are far below
            if not unhidden:
                self._soft_threshold(0.0, unhidden)
            h, gate = self.geometry.height, self.rho if unhidden else self.rho_star
            counts = (self.top_support, self.top_against, self.top_hidden, self.top_missing, self.top_seen)
            self._top_band(p.top_band * h, h, gate, counts, p.top_sigmas)
            for short, geo in self.shorter_top:  # shorter people: the band whose factor is larger
                self._top_band(p.top_band * short, short, gate, self.other_top, p.top_sigmas, geo)
                self._launch(K.keep_better_top, self.batch * self.n_locations,
                             [*counts, *self.other_top, p.top_hidden, p.top_missing, top, p.top_slope,
                              p.top_min_pixels, p.top_unseen, self.area, p.top_unseen_part])
        self._soft_threshold(top, unhidden)

    def _soft_threshold(self, top_share: float, unhidden: int) -> None:
        """rho* = sigmoid(alpha e + beta) rho, times the top-band factor (kernels.soft_threshold)."""
        p = self.params
        self._launch(K.soft_threshold, self.batch * self.n_locations,
                     [p.alpha, p.beta, self.area, self.visible, self.rho, self.top_support, self.top_against,
                      self.top_hidden, self.top_missing, self.top_seen, p.top_hidden, p.top_missing,
                      top_share, p.top_slope, p.top_min_pixels, p.top_unseen, p.top_unseen_share,
                      p.top_unseen_part, unhidden, self.all_support, self.all_against, self.share,
                      self.rho_star])

    def _top_band(self, lo, hi, gate, counts, sigmas=0.0, geo=None) -> None:
        """The band's counts between heights lo and hi of the locations whose `gate` reaches
        TOP_MIN_RHO: a thread a row of each rectangle on a GPU, a thread a location elsewhere."""
        args = [self.depth, self.geo if geo is None else geo, self.pm, float(self.geometry.centre[2]), lo, hi,
                TOP_MIN_RHO, sigmas, self.bg, MISSING_READ, gate]
        # (a thread a row while the launch's thread indices fit Warp's 32-bit tid)
        if self.top_band_by_row and self.batch * self.n_locations * self.top_rows < 2 ** 31:
            self._launch(K.top_band_clear, self.batch * self.n_locations, [gate, TOP_MIN_RHO, *counts])
            self._launch(K.top_band_rows, self.batch * self.n_locations * self.top_rows,
                         [*args, self.top_rows, *counts, self.forward])
        else:
            self._launch(K.top_band, self.batch * self.n_locations, [*args, *counts, self.forward])

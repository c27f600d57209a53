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
        (v,) = self.views  # the joint test reads one camera's lists (one camera today)
        n, locations = len(rho_star), self.n_locations
        marked = np.zeros((self.batch, locations), np.int32)
        marked[:n] = np.asarray(rho_star, np.float32) >= self.joint_threshold
        self.candidate.assign(marked.ravel())
        if self.ordered_joint_lists:
            v.compact(self.candidate, self.not_done)
            # the pixels with entries in order: a flag each (into active_next), its inclusive
            # scan (into listed), then each such pixel and its count placed at its rank (into
            # active and active_next: the flags are spent), arrays the iterations are done with
            dim = self.batch * v.n_pixels
            v.launch(K.has_entries, dim, [v.compact_lists.counts, v.active_next])
            wp.utils.array_scan(v.active_next, v.listed, inclusive=True)
            v.launch(K.place_active, dim, [v.compact_lists.counts, v.listed, v.active, v.active_next])
            pixels = int(v.listed[-1:].numpy()[0])
            index = v.active[:pixels]
            active, count = index.numpy(), v.active_next[:pixels].numpy()
            entries = int(count.sum())
            loc, delta = v.compact_lists.loc[:entries].numpy(), v.compact_lists.delta[:entries].numpy()
            dbg = v.delta_bg[index].numpy()
        else:
            v.live_count.zero_()
            v.launch(K.compact_once, self.batch * v.n_pixels,
                     [v.lists, self.candidate, v.n_pixels, self.not_done, v.compact_lists, v.active, v.live_count])
            _, entries, pixels = (int(x) for x in v.live_count.numpy())
            active = np.sort(v.active[:pixels].numpy())
            compact = v.compact_lists
            first, count, dbg = (a.numpy()[active] for a in (compact.offsets, compact.counts, v.delta_bg))
            at = np.repeat(first, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
            loc, delta = compact.loc[:entries].numpy()[at], compact.delta[:entries].numpy()[at]
        p = self.params
        if p.behind_cost > 0:  # counted for every candidate (n_behind leaves out locations in no list)
            v.launch(K.behind_count, len(self.candidate),
                     [v.depth, self.pm, v.behind_first, v.behind_pixel, v.behind_mu, v.behind_var, v.behind_half,
                      p.behind_step, self.candidate, self.candidate_behind])
            behind = p.behind_cost * self.candidate_behind.numpy().reshape(self.batch, locations).astype(np.float64)
        else:
            behind = np.zeros((self.batch, locations))
        return JointLists.of_batch(np.flatnonzero(marked[:n]), active, count, loc, delta, dbg, behind[:n],
                                   v.geometry.locations, p, locations, v.n_pixels)

    def _threshold(self) -> None:
        """After the iterations: what each location's pixels show of it (transparency pass), the
        top-band counts (with shorter people's bands) and rho* (README, How it works)."""
        p = self.params
        self.visible.zero_()
        for v in self.views:
            v.launch(K.transparency_pass, self.batch * v.n_pixels, [v.lists, self.rho, self.visible])
        height = self.views[0].geometry.height  # the object's, the same seen from every camera
        top = p.top_support if height > 0 else 0.0
        unhidden = int(p.share_of == "unhidden")
        if unhidden:
            self._top_bands(-BAND_ALL, BAND_ALL, self.rho,
                            (self.all_support, self.all_against, self.all_hidden, self.all_missing, self.all_seen))
        if top > 0:
            # counted only where rho* before the test (a factor <= 1) reaches TOP_MIN_RHO: the
            # silhouette walk is the threshold's whole cost, and most locations are far below
            if not unhidden:
                self._soft_threshold(0.0, unhidden)
            gate = self.rho if unhidden else self.rho_star
            counts = (self.top_support, self.top_against, self.top_hidden, self.top_missing, self.top_seen)
            self._top_bands(p.top_band * height, height, gate, counts, p.top_sigmas)
            for i, short in enumerate(p.top_heights):  # shorter people: the band whose factor is larger
                self._top_bands(p.top_band * short, short, gate, self.other_top, p.top_sigmas, i)
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

    def _top_bands(self, lo, hi, gate, counts, sigmas=0.0, shorter: int | None = None) -> None:
        """The band's counts between heights lo and hi of the locations whose `gate` reaches
        TOP_MIN_RHO, seen by each camera (with `shorter`, the solid of params.top_heights[shorter]):
        a thread a row of each rectangle on a GPU, a thread a location elsewhere."""
        L = self.batch * self.n_locations
        # (a thread a row while the launch's thread indices fit Warp's 32-bit tid)
        by_row = self.top_band_by_row and all(L * v.top_rows < 2 ** 31 for v in self.views)
        if by_row:
            self._launch(K.top_band_clear, L, [gate, TOP_MIN_RHO, *counts])
        for v in self.views:
            geo = v.geo if shorter is None else v.shorter_top[shorter][1]
            args = [v.depth, geo, self.pm, float(v.geometry.centre[2]), lo, hi, TOP_MIN_RHO, sigmas, v.bg,
                    MISSING_READ, gate]
            if by_row:
                v.launch(K.top_band_rows, L * v.top_rows, [*args, v.top_rows, *counts, v.forward])
            else:
                v.launch(K.top_band, L, [*args, *counts, v.forward])

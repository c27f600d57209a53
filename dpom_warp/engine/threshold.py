"""After the iterations: what each location's pixels show of it (the transparency pass), the
bands the soft threshold reads (the whole silhouette's with share_of 'unhidden'; the prior's
top band through its hook) and rho* (README, How it works)."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..model import BAND_ALL, MISSING_READ, TOP_MIN_RHO


class ThresholdMixin:
    """Engine: the threshold step."""

    @staticmethod
    def _host(a: wp.array) -> np.ndarray:
        """A host array of `a`'s values that the engine's next call leaves alone."""
        return a.numpy() if a.device.is_cuda else a.numpy().copy()

    def _threshold(self) -> None:
        """The transparency pass over every camera's lists, the whole silhouettes' counts (share_of
        'unhidden'), the prior's counts (people.PeoplePrior.threshold: the top band), then rho*."""
        self.visible.zero_()
        for v in self.views:
            v.launch(K.transparency_pass, self.batch * v.n_pixels, [v.lists, self.rho, self.visible])
        unhidden = int(self.params.share_of == "unhidden")
        if unhidden:
            self._bands(-BAND_ALL, BAND_ALL, self.rho, self.whole)
        self.prior.threshold(self, unhidden)
        self._soft_threshold(self.prior.top_share, unhidden)

    def _soft_threshold(self, top_share: float, unhidden: int) -> None:
        """rho* = sigmoid(alpha e + beta) rho, times the prior's top-band factor where `top_share`
        > 0 (kernels.soft_threshold)."""
        p = self.params
        self._launch(K.soft_threshold, self.batch * self.n_locations,
                     [p.alpha, p.beta, self.area, self.visible, self.rho, *self.prior.top_terms(top_share), unhidden,
                      self.whole, self.share, self.rho_star])

    def _bands(self, lo, hi, gate, counts, sigmas=0.0, geos: list | None = None) -> None:
        """The counts (a kernels.Bands: support, against, hidden, missing, seen) of the band between heights lo and
        hi of the locations whose `gate` reaches TOP_MIN_RHO, seen by each camera (with `geos`,
        each camera's GeometryArrays of another solid): a thread a row of each rectangle on a
        GPU, a thread a location elsewhere (kernels.top_band)."""
        L = self.batch * self.n_locations
        # (a thread a row while the launch's thread indices fit Warp's 32-bit tid); a rig's cameras
        # add to each location's counts, which the rows' launch does (top_band writes them)
        fits = all(L * v.top_rows < 2 ** 31 for v in self.views)
        by_row = (self.top_band_by_row or len(self.views) > 1) and fits
        if len(self.views) > 1 and not fits:
            raise ValueError(f"a rig's top band: {L} locations x {max(v.top_rows for v in self.views)} rows "
                             f"exceed Warp's 2^31 threads; coarsen grid.x/grid.y")
        if by_row:
            self._launch(K.top_band_clear, L, [gate, TOP_MIN_RHO, counts])
        for i, v in enumerate(self.views):
            query = K.band_query(float(v.geometry.centre[2]), lo, hi, TOP_MIN_RHO, sigmas, MISSING_READ)
            args = [v.depth, v.geo if geos is None else geos[i], self.pm, v.bg, query, gate]
            if by_row:
                v.launch(K.top_band_rows, L * v.top_rows, [*args, v.top_rows, counts, v.forward])
            else:
                v.launch(K.top_band, L, [*args, counts, v.forward])

"""A camera's drift correction (drift.py, engine.view): a fixed sample of the background's pixels taken
whenever a background is set, and each frame's depth scale estimated on it and divided out
before the frame's lists are built."""

from __future__ import annotations

import numpy as np

from ..drift import DriftEstimate, DriftOptions, background_sample, estimate_scale


class DriftMixin:
    """CameraView: each frame's depth scale against its background (drift; None: off)."""

    drift: DriftOptions | None = None
    _drift_at = None  # the sampled pixels (flat, this engine's resolution) and their depths
    _drift_mu = None

    def _sample_background(self) -> None:
        """After a background is set: the pixels whose background depth is known (not broad)."""
        if self.drift is None or not self.drift.correct:
            self._drift_at = None
            return
        b = self.bg.numpy()[:self.n_pixels]
        self._drift_at = background_sample(b[:, 0], (b[:, 3] < 1.0) & (b[:, 2] < 0.5))
        self._drift_mu = b[self._drift_at, 0]

    def correct_drift(self, depths_m) -> tuple:
        """The frames (n, H', W') with each one's drift divided out where it is trusted and beyond
        the dead band, and each frame's DriftEstimate (None each without drift correction)."""
        d = np.asarray(depths_m, dtype=np.float32)
        d = d[None] if d.ndim == 2 else d
        if self._drift_at is None:
            return d, [None] * len(d)
        v, u = np.divmod(self._drift_at, self.width)
        s = self.resolution.stride
        if d.shape[1:] != (self.height, self.width):  # full resolution: the block's centre pixel
            v, u = v * s + s // 2, u * s + s // 2
        estimates: list[DriftEstimate] = []
        copied = False
        for f in range(len(d)):
            e = estimate_scale(d[f][v, u], self._drift_mu, self.drift)
            if e.applied:
                if not copied:
                    d, copied = d.copy(), True
                d[f] = d[f] / np.float32(e.scale)
            estimates.append(e)
        return d, estimates

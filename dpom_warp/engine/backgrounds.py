"""A camera's background model (engine.view): from the floor plane, from background frames, or the estimate
`input.background: auto` keeps (background.BackgroundEstimator); per frame of a batch."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..model import (
    Background,
)


class BackgroundMixin:
    """CameraView: the background distributions its pixels are judged against."""

    # -- background ----------------------------------------------------------------------
    def set_floor_background(self):
        """Use the floor-only background of MODEL.md (no background frames); with
        params.background_outside_grid it is completed from each frame (see reference)."""
        self.floor_pixels.fill_(1)
        self.floor_mode, self.fallback_pixels = True, self.n_pixels
        self._floor_background(0)
        self._sample_background()

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
        self._sample_background()

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
        self._sample_background()
        return self.fallback_pixels

    def background_state(self) -> tuple | None:
        """What another engine of this camera and grid needs to hold this camera's background
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

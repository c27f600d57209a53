"""`input.background: auto`: each pixel's background estimated from the run's own frames.

The estimate is streamed (kernels.background.cluster_frames): frames go in a few at a time
and the state is a fixed number of clusters per pixel (model.AutoBackground.state_bytes), so
a long sequence is never held in memory. reference.background_clusters is its NumPy twin.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import kernels as K
from .model import AutoBackground, Background, ModelParams
from .warp_setup import init_warp


def sample_frames(n: int, max_frames: int) -> list[int]:
    """Indices of at most `max_frames` of n frames, evenly spread, first and last included."""
    if n <= max_frames:
        return list(range(n))
    return sorted({int(round(x)) for x in np.linspace(0, n - 1, max_frames)})


class BackgroundEstimator:
    """Streaming estimate of model.AutoBackground for (H, W) frames on one Warp device."""

    def __init__(self, height: int, width: int, params: ModelParams, auto: AutoBackground,
                 device: str = "cpu"):
        from .engine import pixel_model

        init_warp()
        self.height, self.width = height, width
        self.params, self.auto, self.device = params, auto, device
        self.pm = pixel_model(params)
        self.frames = 0
        n = height * width
        with wp.ScopedDevice(device):
            self.count = wp.zeros((n, auto.slots), dtype=wp.int32)
            self.mean = wp.zeros((n, auto.slots), dtype=wp.float64)
            self.m2 = wp.zeros((n, auto.slots), dtype=wp.float64)
            self.n_read = wp.zeros(n, dtype=wp.int32)

    def memory_bytes(self) -> int:
        return self.auto.state_bytes(self.height * self.width)

    def add(self, frames_m: np.ndarray):
        """Stream (n, H, W) or (H, W) frames in metres (0 = no reading), in sequence order."""
        f = np.asarray(frames_m, dtype=np.float32)
        f = f[None] if f.ndim == 2 else f
        if f.shape[1:] != (self.height, self.width):
            raise ValueError(f"frames: expected (n, {self.height}, {self.width}), found {f.shape}")
        with wp.ScopedDevice(self.device):
            wp.launch(K.cluster_frames, dim=(self.height, self.width),
                      inputs=[wp.array(np.ascontiguousarray(f), dtype=wp.float32), self.pm,
                              self.auto.cluster_sigmas, self.auto.cluster_floor, self.count,
                              self.mean, self.m2, self.n_read])
        self.frames += len(f)

    def result(self) -> tuple[Background, np.ndarray]:
        """(Background of arrays (H, W), fallback (H, W) bool: the pixels left to the
        floor-only model), as reference.background_clusters."""
        a, n = self.auto, self.height * self.width
        with wp.ScopedDevice(self.device):
            bg = wp.zeros((n, 4), dtype=wp.float64)
            fallback = wp.zeros(n, dtype=wp.int32)
            wp.launch(K.cluster_background, dim=n,
                      inputs=[self.count, self.mean, self.m2, self.n_read, self.frames, a.min_frames,
                              a.min_share, self.pm, bg, fallback])
        b = bg.numpy().reshape(self.height, self.width, 4)
        return (Background(mu=b[..., 0], sigma=b[..., 1], missing=b[..., 2], outlier=b[..., 3]),
                fallback.numpy().reshape(self.height, self.width).astype(bool))

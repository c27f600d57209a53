"""dpom-warp: people (and other objects) in depth images with DPOM on Warp kernels.

    from dpom_warp import Detector
    det = Detector.from_config("configs/demo_people.yaml")
    result = det.detect(depth)      # result.detections, result.rho_star, result.timings
    zones = Zones.from_config(det.config)   # counts and crossings of committed tracks (zones:, lines:)
"""

from __future__ import annotations

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("dpom-warp")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = ["Detector", "Result", "Zones", "__version__"]


def __getattr__(name):  # Warp and Open3D load only when the API is used, not for `--help`
    if name in ("Detector", "Result"):
        from . import api

        return getattr(api, name)
    if name == "Zones":
        from .zones import Zones

        return Zones
    raise AttributeError(f"module 'dpom_warp' has no attribute {name!r}")

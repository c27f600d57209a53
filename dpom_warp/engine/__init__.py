"""The Warp inference engine (see core.Engine) over a list of cameras (view.CameraView), one
file per step."""

from .base import (
                   BEHIND_POINT_BYTES,
                   ENTRY_BYTES,
                   LOCATION_BYTES,
                   PAIR_BYTES,
                   PIXEL_BYTES,
                   TABLE_BUDGET,
                   TABLE_BYTES,
                   TABLE_PIXEL_BYTES,
                   FrameResult,
                   ListOverflow,
                   MemoryBudgetError,
                   memory_estimate,
                   pixel_model,
                   resolve_device,
                   tile_pairs,
)
from .core import Engine
from .people import PeoplePrior, Prior
from .view import CameraView

__all__ = ["BEHIND_POINT_BYTES", "CameraView", "ENTRY_BYTES", "LOCATION_BYTES", "PAIR_BYTES", "PIXEL_BYTES", "TABLE_BUDGET",
           "TABLE_BYTES", "TABLE_PIXEL_BYTES", "Engine", "FrameResult", "ListOverflow", "MemoryBudgetError",
           "memory_estimate", "PeoplePrior", "pixel_model", "Prior", "resolve_device", "tile_pairs"]

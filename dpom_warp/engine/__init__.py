"""The Warp inference engine (see core.Engine), one file per step."""

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

__all__ = ["BEHIND_POINT_BYTES", "ENTRY_BYTES", "LOCATION_BYTES", "PAIR_BYTES", "PIXEL_BYTES", "TABLE_BUDGET",
           "TABLE_BYTES", "TABLE_PIXEL_BYTES", "Engine", "FrameResult", "ListOverflow", "MemoryBudgetError",
           "memory_estimate", "pixel_model", "resolve_device", "tile_pairs"]

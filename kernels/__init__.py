"""Warp kernels of DPOM, one file per step (installed as `dpom_warp.kernels`).

- `pixel_model`: the pixel distributions of eq. 11 as `@wp.func`s and the parameter structs.
- `masks`: masks M_k and Delta_ki (eq. 12) through a static index (the pixel table, or image
  tiles where it would not fit), counted then filled into per-pixel lists kept in depth order
  (location id breaking ties).
- `mean_field`: the exclusive-form mean-field evidence pass, the exclusion prior's pass, damped
  update, on-device convergence check (batches, graphs).
- `people`: what a location's pixels say beyond the lists: readings behind its object (the behind
  cost), the top-band test, and eq. 13's soft threshold with it.
- `sparse`: the pruning bound, and the per-pixel lists compacted to the live locations
  (sparse iterations).
- `frames`: full-resolution frames reduced to the engine's pixels (median, min or nearest of
  each stride x stride block), on the device.
- `background`: background distributions from background frames, from the run's own frames
  (streamed clusters, `input.background: auto`) or from the floor plane.
"""

from .background import (background_delta, background_from_frames, cluster_background, cluster_frames,
                         floor_background)
from .frames import reduce_frames
from .masks import (PixelTable, TablePair, TileIndex, pair_depth_bounds, pixel_entries, pixel_entries_once, table_pairs,
                    table_window)
from .mean_field import ONE_STACK, SIZED_STACK, check_converged, evidence_pass, exclusion_pass, transparency_pass, update_rho
from .people import (Bands, BandQuery, band_query, bands_of, behind_count, behind_points, keep_better_top, soft_threshold, top_band,
                     top_band_clear, top_band_rows)
from .pixel_model import SHAPE_FIELDS, SHAPE_PLANE, SHAPE_SOLID, GeometryArrays, PixelLists, PixelModel
from .sparse import (IDLE, PRUNED, TALLY_SUM, bound_pass, compact_again, compact_once, count_entries, count_iteration,
                     count_live, fill_live, frame_tally, gather_live, has_entries, mark_idle, place_active, prune,
                     prune_lists, update_bound)

__all__ = [
    "BandQuery", "Bands", "GeometryArrays", "IDLE", "SHAPE_FIELDS", "SHAPE_PLANE", "SHAPE_SOLID", "ONE_STACK", "PRUNED", "SIZED_STACK", "TALLY_SUM", "PixelLists", "PixelModel", "PixelTable",
    "TablePair", "TileIndex",
    "background_delta", "background_from_frames", "band_query", "bands_of", "behind_count", "behind_points", "bound_pass", "check_converged",
    "cluster_background", "cluster_frames", "compact_again", "compact_once", "count_entries", "count_iteration",
    "count_live", "evidence_pass", "exclusion_pass", "fill_live", "floor_background", "frame_tally", "gather_live",
    "has_entries",
    "keep_better_top", "mark_idle", "pair_depth_bounds", "pixel_entries", "pixel_entries_once", "place_active", "prune",
    "prune_lists", "reduce_frames", "soft_threshold", "table_pairs", "table_window", "top_band", "top_band_clear",
    "top_band_rows", "transparency_pass",
    "update_bound", "update_rho",
]

"""What an engine builds once for each of its cameras over the grid: the geometry's arrays, the static mask
index (image tiles or the pixel table) and the list buffers."""

from __future__ import annotations

import numpy as np
import warp as wp

from .. import kernels as K
from ..geometry import Geometry


class StaticsMixin:
    """CameraView: the static arrays and the list buffers (allocated up front)."""

    @staticmethod
    def _geometry_arrays(geometry: Geometry, first: K.GeometryArrays | None = None) -> K.GeometryArrays:
        """The kernels' view of `geometry`; with `first`, the view of a geometry that differs
        from it only in the shape (Geometry.shorter), sharing its arrays."""
        g = K.GeometryArrays()
        if first is None:
            g.rays = wp.array(geometry.rays, dtype=wp.vec3d)
            g.rect = wp.array(geometry.rect, dtype=wp.vec4i)
            g.normal = wp.array(geometry.normal, dtype=wp.vec3d)
            g.plane = wp.array(geometry.plane, dtype=wp.float64)
            g.location = wp.array(geometry.locations, dtype=wp.vec3d)
        else:
            g.rays, g.rect, g.normal, g.plane, g.location = (first.rays, first.rect, first.normal, first.plane,
                                                             first.location)
        g.centre = wp.vec3d(*(float(c) for c in geometry.centre))
        g.shape = geometry.shape.code  # its Warp function (kernels.pixel_model.object_depth)
        fields = geometry.shape.kernel_fields()
        for name in K.SHAPE_FIELDS:  # (0 where the shape has none)
            setattr(g, name, fields.get(name, 0.0))
        return g

    def _tile_index(self, pair_loc, pair_tile, tiles_x) -> K.TileIndex:
        """Depth bounds of every (location, tile) pair, sorted by tile then lo (kernels.masks)."""
        with wp.ScopedDevice(self.device):
            lo = wp.zeros(len(pair_loc), dtype=wp.float64)
            hi = wp.zeros(len(pair_loc), dtype=wp.float64)
            if len(pair_loc):
                wp.launch(K.pair_depth_bounds, dim=len(pair_loc),
                          inputs=[self.geo, self.pm, self.tile, tiles_x, wp.array(pair_loc),
                                  wp.array(pair_tile), lo, hi])
            lo, hi = lo.numpy(), hi.numpy()
            keep = hi >= lo
            order = np.lexsort((lo[keep], pair_tile[keep]))
            tile_of, lo, hi = pair_tile[keep][order], lo[keep][order], hi[keep][order]
            span = np.zeros(self.n_tiles)
            np.maximum.at(span, tile_of, hi - lo)
            t = K.TileIndex()
            t.size, t.tiles_x = self.tile, tiles_x
            t.start = wp.array(np.searchsorted(tile_of, np.arange(self.n_tiles + 1)).astype(np.int32))
            t.loc = wp.array(pair_loc[keep][order], dtype=wp.int32)
            t.lo = wp.array(lo, dtype=wp.float64)
            t.hi = wp.array(hi, dtype=wp.float64)
            t.span = wp.array(span, dtype=wp.float64)
        self.n_pairs = len(lo)
        return t

    def _pixel_table(self, use: bool) -> K.PixelTable:
        """The pixel table (kernels.masks; empty unless `use`): each location's pairs written
        by table_pairs into room for its rectangle's area, gathered, then sorted per pixel by
        (float32 mu, location)."""
        t = K.PixelTable()
        t.use, t.width = int(use), self.width
        n = 0
        with wp.ScopedDevice(self.device):
            if use and self.n_locations:
                room = self.geometry.rect_area.astype(np.int64)  # at most a pair per pixel
                first = np.concatenate([[0], np.cumsum(room)[:-1]])
                counts = wp.zeros(self.n_locations, dtype=wp.int32)
                out = [wp.zeros(int(room.sum()), dtype=d)
                       for d in (wp.int32, wp.int32, wp.float64, wp.float64, wp.float64, wp.float32)]
                wp.launch(K.table_pairs, dim=self.n_locations,
                          inputs=[self.geo, self.pm, self.width, wp.array(first.astype(np.int32)), counts] + out)
                c = counts.numpy()
                n = int(c.sum())
                written = np.repeat(first, c) + (np.arange(n) - np.repeat(np.cumsum(c) - c, c))
                pixel, loc, mu, sigma, log_sigma, half = (a.numpy()[written] for a in out)
                mu32 = mu.astype(np.float32)
                # sorted by (pixel, mu32, loc): the pairs come location by location, so a stable
                # sort on (pixel, mu32) keeps loc ascending among ties; a positive float32's bits
                # sort as its value (mu > 0 here). np.lexsort of the three: ~2x slower
                key = (pixel.astype(np.int64) << 32) | mu32.view(np.int32).astype(np.int64)
                order = np.argsort(key, kind="stable")
                start = np.searchsorted(pixel[order], np.arange(self.n_pixels + 1)).astype(np.int32)
                pairs = np.empty(n, dtype=K.TablePair.numpy_dtype())
                for name, a in (("mu", mu), ("sigma", sigma), ("log_sigma", log_sigma), ("loc", loc), ("half", half)):
                    pairs[name] = a[order]
                t.start, t.pair = wp.array(start), wp.array(pairs, dtype=K.TablePair)
                t.key = wp.zeros(n, dtype=wp.vec2f)  # the walk's window (kernels.masks)
                wp.launch(K.table_window, dim=self.n_pixels, inputs=[t.start, t.pair, t.key])
            else:
                t.start, t.key, t.pair = wp.zeros(1, dtype=wp.int32), wp.zeros(0, dtype=wp.vec2f), wp.zeros(
                    0, dtype=K.TablePair)
        self.n_table = n
        return t

    def _allocate_lists(self, capacity: int):
        self.launch.reset()  # the launches recorded with the old lists
        capacity = min(max(1024, capacity), self.max_entries)
        # new structs (not the old ones' fields rewritten): a Launcher knows a changed
        # argument by its identity
        lists, compact = K.PixelLists(), K.PixelLists()
        lists.offsets, lists.counts = self.lists.offsets, self.lists.counts
        compact.offsets, compact.counts = self.compact_lists.offsets, self.compact_lists.counts
        with wp.ScopedDevice(self.device):
            lists.loc = wp.zeros(capacity, dtype=wp.int32)
            lists.mu = wp.zeros(capacity, dtype=wp.float32)
            lists.delta = wp.zeros(capacity, dtype=wp.float32)
            self.behind = wp.zeros(capacity, dtype=wp.float64)
            compact.loc = wp.zeros(capacity, dtype=wp.int32)
            compact.mu = wp.zeros(0, dtype=wp.float32)  # (the compact lists carry no depths)
            compact.delta = wp.zeros(capacity, dtype=wp.float32)
        self.lists, self.compact_lists = lists, compact
        self.capacity = capacity

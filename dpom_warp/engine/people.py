"""The people-only tests as a prior the engine is given (Engine(..., prior=)): the generic mean
field (the lists, the iterations, the soft threshold) knows them only through the hooks below.

- The behind cost (model.behind_cost): the readings behind each location's object, where a
  person standing there would hide them, counted once a frame on a lattice of its silhouette's
  core (kernels.behind_points, built once per camera; kernels.behind_count), enter the mean
  field's update and the pruning bound as a fixed per-location term, cost x count.
- The top band (model.top_support, top_heights): after the iterations, what the band of the
  object's top shows (kernels.top_band), for the object and for shorter people, scales rho*
  (kernels.soft_threshold's top factor).
- The joint test's lists (joint.JointLists, detect.joint_detections): the candidates' entries
  copied out after a frame, with their readings behind, one camera's after another (a rig's:
  joint.RigJointLists, whose log odds add every camera's terms to the prior's once).

`Prior` is the interface and a prior that adds nothing: every location judged by its pixels
alone (a drone's, or a run that turns the people tests off); `PeoplePrior` reads the tests'
parameters from model.ModelParams (each off where its parameter is 0)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .. import kernels as K
from ..joint import JointLists, RigJointLists
from ..model import BAND_ALL, ModelParams
from .base import BEHIND_POINT_BYTES


@dataclass
class CameraPrior:
    """A camera's static part of the prior: the lattice of its silhouettes' cores (behind_points'
    table: from first[k] to first[k + 1] for location k, each point's pixel, the object's depth
    and variance there and the mask test's half-width) and the shorter solids' GeometryArrays of
    the top band (params.top_heights)."""

    first: wp.array
    pixel: wp.array
    mu: wp.array
    var: wp.array
    half: wp.array
    shorter: list

    @property
    def points(self) -> int:
        return len(self.mu)


class Prior:
    """What the engine asks of a prior; this one adds nothing to the mean field. Hooks, in a
    frame's order: `camera_bytes` and `add_camera` while each camera (view.CameraView) is built,
    `allocate` once the locations' arrays are, `count` before the pruning bound or the
    iterations, `cost` and `n_behind` in every update, `threshold` before the soft threshold
    (whose top-band arguments are `top_terms` of `top_share`), and `joint` after it."""

    def __init__(self, params: ModelParams):
        self.params = params
        self.cameras: list[CameraPrior] = []
        self.cost = 0.0  # the fixed term's weight per reading behind (model.behind_cost)
        self.top_share = 0.0  # the top band's threshold (model.top_support; 0: no factor)
        self.joint_threshold: float | None = None  # results carry the joint test's lists where rho* reaches it

    def camera_bytes(self, view) -> int:
        """Bytes this prior will hold for camera `view` (in the engine's memory budget)."""
        return 0

    def add_camera(self, view) -> None:
        """The prior's static part for camera `view`, once its arrays are made."""

    def allocate(self, engine, L: int) -> None:
        """The per-location arrays the hooks hand the kernels (zeros here: no term, no band)."""
        with wp.ScopedDevice(engine.device):
            self.n_behind = wp.zeros(L, dtype=wp.int32)  # silhouette pixels read behind (behind_count)
            # the top band's support, against, hidden, missing and seen pixels (kernels.top_band)
            self.top = K.bands_of([wp.zeros(L, dtype=wp.int32) for _ in range(5)])

    @property
    def top_counts(self) -> tuple:
        """The top band's count arrays (support, against, hidden, missing, seen)."""
        t = self.top
        return t.support, t.against, t.hidden, t.missing, t.seen

    def top_terms(self, top_share: float) -> list:
        """kernels.soft_threshold's top-band arguments: the counts, then the factor's parameters
        (`top_share` 0: no factor, the others unread)."""
        p = self.params
        return [self.top, p.top_hidden, p.top_missing, top_share, p.top_slope, p.top_min_pixels,
                p.top_unseen, p.top_unseen_share, p.top_unseen_part]

    def count(self, engine) -> None:
        """The fixed per-location term of the frames in flight (n_behind), before it is used."""

    def threshold(self, engine, unhidden: int) -> None:
        """The counts the soft threshold's factor needs, after the transparency pass."""

    def joint(self, engine, rho_star: np.ndarray) -> list:
        """Each frame's JointLists (joint_threshold set), after the threshold."""
        return [None] * len(rho_star)


class PeoplePrior(Prior):
    """The people-only tests of model.ModelParams: the behind cost, the top band (with shorter
    people's bands) and the joint test's lists (module docstring)."""

    def __init__(self, params: ModelParams):
        super().__init__(params)
        self.cost = params.behind_cost
        self._counts = None  # a camera's lattice points counted, until add_camera fills them

    # -- per camera ----------------------------------------------------------------------
    def _behind_statics(self, view) -> list:
        """behind_points' inputs that describe the core: geometry, band, side share, lattice
        (the band: behind_low to behind_high x the height on ground grids)."""
        p, h = self.params, view.geometry.height
        low, high = (p.behind_low * h, p.behind_high * h) if h > 0 else (-BAND_ALL, BAND_ALL)
        return [view.geo, view.pm, float(view.geometry.centre[2]), p.behind_side, low, high, p.behind_step,
                view.forward]

    def camera_bytes(self, view) -> int:
        """The lattice points of each location's silhouette core counted (behind_points, fill 0;
        none without behind_cost), counted first: the table is in the budget."""
        L = view.n_locations
        counts = np.zeros(0, np.int64)
        if self.params.behind_cost > 0 and L > 0:
            with wp.ScopedDevice(view.device):
                c = wp.zeros(L, dtype=wp.int32)
                none_i, none_f = wp.zeros(0, dtype=wp.int32), wp.zeros(0, dtype=wp.float64)
                wp.launch(K.behind_points, dim=L, inputs=self._behind_statics(view) + [0, none_i, c, none_i, none_f,
                                                                                   none_f, none_f])
            counts = c.numpy().astype(np.int64)
        self._counts = counts
        return BEHIND_POINT_BYTES * int(counts.sum()) + 4 * (L + 1)  # the points and their starts

    def add_camera(self, view) -> None:
        """The lattice's table (behind_points, fill 1: static, so built once and only classed
        against each frame's readings by behind_count) and the shorter solids' arrays."""
        counts, self._counts = self._counts, None
        g = view.geometry
        with wp.ScopedDevice(view.device):
            first = np.zeros(view.n_locations + 1, np.int32)  # all 0: no points (no behind_cost)
            first[1:len(counts) + 1] = np.cumsum(counts)
            n = int(first[-1])
            cam = CameraPrior(wp.array(first, dtype=wp.int32), wp.zeros(n, dtype=wp.int32),
                              *(wp.zeros(n, dtype=wp.float64) for _ in range(3)), [])
            if n:
                none_i = wp.zeros(0, dtype=wp.int32)
                wp.launch(K.behind_points, dim=len(counts),
                          inputs=self._behind_statics(view) + [1, cam.first, none_i, cam.pixel, cam.mu, cam.var,
                                                               cam.half])
            # a shorter solid's band (params.top_heights): its GeometryArrays, sharing the camera's
            cam.shorter = [(h, view._geometry_arrays(g.shorter(h), view.geo)) for h in self.params.top_heights
                           if g.height > 0]
        self.cameras.append(cam)

    def allocate(self, engine, L: int) -> None:
        super().allocate(engine, L)
        self.top_share = self.params.top_support if engine.views[0].geometry.height > 0 else 0.0
        with wp.ScopedDevice(engine.device):
            # a shorter solid's band counts (params.top_heights)
            self.other_top = (K.bands_of([wp.zeros(L, dtype=wp.int32) for _ in range(5)])
                              if self.cameras[0].shorter else None)
            self.candidate = wp.zeros(L, dtype=wp.int32)  # the joint test's locations (joint)
            self.candidate_behind = wp.zeros(L, dtype=wp.int32)  # and their readings behind

    # -- a frame -------------------------------------------------------------------------
    def count(self, engine) -> None:
        """n_behind: what the lists leave out, the readings behind each listed location's
        object (kernels.behind_count), after counting each location's entries in the lists
        (before the pruning, or after it: the pruned ones are in no list)."""
        if self.params.behind_cost <= 0:
            return
        engine.per_location.zero_()
        for v in engine.views:
            v.launch(K.count_entries, engine.batch * v.n_pixels, [v.lists, engine.per_location])
        p = self.params
        for c, (v, cam) in enumerate(zip(engine.views, self.cameras)):  # summed over the cameras
            v.launch(K.behind_count, engine.batch * engine.n_locations,
                     [v.depth, engine.pm, cam.first, cam.pixel, cam.mu, cam.var, cam.half, p.behind_step,
                      engine.per_location, self.n_behind, int(c > 0)])

    def threshold(self, engine, unhidden: int) -> None:
        """The top band's counts, counted only where rho* before the test (a factor <= 1) reaches
        TOP_MIN_RHO (with share_of 'unhidden', where rho does): the silhouette walk is the
        threshold's whole cost, and most locations are far below; each shorter person's band
        keeps the counts whose factor is larger (kernels.keep_better_top)."""
        p, top = self.params, self.top_share
        if top <= 0:
            return
        if not unhidden:
            engine._soft_threshold(0.0, unhidden)
        height = engine.views[0].geometry.height  # the object's, the same seen from every camera
        gate = engine.rho if unhidden else engine.rho_star
        engine._bands(p.top_band * height, height, gate, self.top, p.top_sigmas)
        for i, short in enumerate(p.top_heights):
            engine._bands(p.top_band * short, short, gate, self.other_top, p.top_sigmas,
                          [cam.shorter[i][1] for cam in self.cameras])
            engine._launch(K.keep_better_top, engine.batch * engine.n_locations,
                           [self.top, self.other_top, p.top_hidden, p.top_missing, top, p.top_slope,
                            p.top_min_pixels, p.top_unseen, engine.area, p.top_unseen_part])

    def joint(self, engine, rho_star: np.ndarray) -> list:
        """After a batch's inference, each frame's JointLists for the locations whose rho*
        (float32, as detect reads the maps) reaches joint_threshold: their entries copied out of
        the lists in order (every frame taken) with each pixel's Delta_bg, and their readings
        behind (kernels.behind_count). A few launches and reads for the batch: on a GPU
        count, scan and fill (`compact`), whose slices come in pixel order, and the pixels
        with entries placed in that order (kernels.sparse.place_active); on the CPU
        kernels.sparse.compact_once in one pass, its slices placed by atomic adds (in pixel
        order on one thread, sorted to be sure) and read through NumPy views of the arrays."""
        if self.joint_threshold is None:
            return [None] * len(rho_star)
        n, locations, batch = len(rho_star), engine.n_locations, engine.batch
        marked = np.zeros((batch, locations), np.int32)
        marked[:n] = np.asarray(rho_star, np.float32) >= self.joint_threshold
        self.candidate.assign(marked.ravel())
        cells = np.flatnonzero(marked[:n])
        per_camera = [self._camera_joint(engine, v, cam, cells, n) for v, cam in zip(engine.views, self.cameras)]
        if len(per_camera) == 1:
            return per_camera[0]
        return [RigJointLists(list(frame)) for frame in zip(*per_camera)]  # a rig: every camera's sums add

    def _camera_joint(self, engine, v, cam, cells: np.ndarray, n: int) -> list:
        """One camera's JointLists of each of the batch's `n` frames for the candidates marked in
        self.candidate (`cells`, ascending over the batch)."""
        locations, batch = engine.n_locations, engine.batch
        if engine.ordered_joint_lists:
            v.compact(self.candidate, engine.not_done)
            # the pixels with entries in order: a flag each (into active_next), its inclusive
            # scan (into listed), then each such pixel and its count placed at its rank (into
            # active and active_next: the flags are spent), arrays the iterations are done with
            dim = batch * v.n_pixels
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
            v.launch(K.compact_once, batch * v.n_pixels,
                     [v.lists, self.candidate, v.n_pixels, engine.not_done, v.compact_lists, v.active, v.live_count])
            _, entries, pixels = (int(x) for x in v.live_count.numpy())
            active = np.sort(v.active[:pixels].numpy())
            compact = v.compact_lists
            first, count, dbg = (a.numpy()[active] for a in (compact.offsets, compact.counts, v.delta_bg))
            at = np.repeat(first, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
            loc, delta = compact.loc[:entries].numpy()[at], compact.delta[:entries].numpy()[at]
        p = self.params
        if p.behind_cost > 0:  # counted for every candidate (n_behind leaves out locations in no list)
            v.launch(K.behind_count, len(self.candidate),
                     [v.depth, engine.pm, cam.first, cam.pixel, cam.mu, cam.var, cam.half, p.behind_step,
                      self.candidate, self.candidate_behind, 0])
            behind = p.behind_cost * self.candidate_behind.numpy().reshape(batch, locations).astype(np.float64)
        else:
            behind = np.zeros((batch, locations))
        return JointLists.of_batch(cells, active, count, loc, delta, dbg, behind[:n],
                                   v.geometry.locations, p, locations, v.n_pixels)

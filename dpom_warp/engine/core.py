"""The Warp inference engine: buffers allocated once per grid and camera, one call per frame
(or per batch of frames). The class is put together from one part per step, each in its own
file of this package: the cameras (view: each one's static arrays, background, drift and
per-pixel lists), the sparse bookkeeping, the iterations (the mean field) and the threshold,
with the people-only tests a prior it is given (people)."""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import warp as wp

from .. import kernels as K
from ..drift import DriftOptions
from ..geometry import Geometry, neighbour_lists
from ..model import (
    AutoBackground,
    Background,
    ModelParams,
)
from ..resolution import Resolution
from ..warp_setup import init_warp
from .base import (
    LOCATION_BYTES,
    FrameResult,
    pixel_model,
)
from .iterations import IterationsMixin
from .launch import Launcher
from .people import PeoplePrior, Prior
from .sparse import SparseMixin
from .threshold import ThresholdMixin
from .view import CameraView


class Engine(SparseMixin, IterationsMixin, ThresholdMixin):
    """DPOM inference over one grid seen by a list of cameras (one today), on one Warp device.

    Buffers (per-pixel lists, accumulators) are allocated up front; the list capacity grows
    (and says so in `grown`) only when a frame needs more entries than it holds, up to
    `max_entries` and to what `memory_gb` allows; a frame that needs more is refused with
    ListOverflow, and an engine whose first buffers already exceed the budget is refused
    with MemoryBudgetError, before anything is allocated.

    With `batch` > 1, `infer_batch` runs up to `batch` frames through every launch (their
    pixels and locations side by side); each frame stops at its own iteration, so every
    frame's result is the one `infer` gives it alone. With `graph`, the iteration loop is
    captured once as a graph (a CUDA graph on a GPU; Warp replays CPU graphs too) and replayed
    for every frame or batch: max_iterations launches, no host sync, converged frames skipped.

    Args:
        geometry: silhouettes, facing planes and rays (geometry.build_geometry), or a list of
            them, one a camera of a rig, over the same locations (`views`: each camera's
            CameraView). A rig's frames are a list, one a camera (infer, infer_batch): every
            camera's pixels add to each location's evidence in one mean field (README, How it
            works: several cameras).
        params: model and inference parameters.
        device: Warp device name ('cpu', 'cuda:0').
        entries_per_pixel: initial list capacity per pixel.
        max_entries: hard cap on the list capacity (None: no cap).
        memory_gb: memory budget of the engine's buffers, GiB (None: no budget).
        tile: edge in pixels of the image tiles of the static mask index (kernels.masks).
        table: the pixel table as the static mask index instead of the tiles (kernels.masks:
            the same lists, built without the object depths, ~1.5x faster with a solid);
            None: with a solid (a facing plane's depth costs little more than reading the
            table), where its pairs (at most the silhouette rectangles' area) take at most
            TABLE_BUDGET and fit memory_gb.
        batch: frames per launch.
        graph: capture the iteration loop as a graph (None: on CUDA devices only).
        resolution: how full-resolution frames are reduced to this engine's pixels (kept for
            the caller: the engine's own arrays are at the geometry's resolution).
        background_auto: the run estimates its background (background.BackgroundEstimator at
            this resolution): its state counts in the memory budget and memory_bytes.
        drift: each frame's depth scale estimated against the background and divided out
            before inference (drift.py; None: frames as given).
        prior: what the mean field adds to each location's pixels (people.Prior: nothing;
            people.PeoplePrior, the default: the people-only tests `params` describes, the
            behind cost, the top band and the joint test's lists).
    """

    def __init__(self, geometry: Geometry | Sequence[Geometry], params: ModelParams, device: str = "cpu",
                 entries_per_pixel: float = 8.0, max_entries: int | None = None,
                 memory_gb: float | None = None, tile: int = 8, batch: int = 1,
                 graph: bool | None = None, resolution: Resolution | None = None,
                 background_auto: AutoBackground | None = None, table: bool | None = None,
                 drift: DriftOptions | None = None, prior: Prior | None = None):
        init_warp()
        geometries = [geometry] if isinstance(geometry, Geometry) else list(geometry)
        check_rig(geometries)
        if min(params.sensor_noise) < 0:
            raise ValueError(f"sensor_noise: expected [a, b] >= 0, found {list(params.sensor_noise)}")
        if batch < 1 or tile < 1:
            raise ValueError(f"batch and tile: expected integers >= 1, found {batch} and {tile}")
        self.params, self.device = params, device
        self.prior = PeoplePrior(params) if prior is None else prior
        self.resolution = resolution or Resolution()
        self.n_locations = len(geometries[0].rect)
        self.batch = batch
        self.grown: list[int] = []  # every camera's list growth, in order
        self._launch = Launcher(device)  # the kernels over the locations alone
        self.views: list[CameraView] = []
        self._device_policy(device, graph)
        self.n_live = None  # live locations gathered for the sparse updates (None: every one)
        self.sparse_on_lists = False  # the sparse passes walk the lists (nothing has died yet)
        self.n_kept = None  # locations neither pruned nor idle, for the full passes' updates
        self.pm = pixel_model(params)
        start, nbrs = neighbour_lists(geometries[0].locations,
                                      params.exclusion_radius if params.exclusion > 0 else 0.0)
        self.extra_bytes = 4 * (len(start) + len(nbrs))  # model.exclusion's neighbour lists
        state = background_auto.state_bytes if background_auto else (lambda pixels: 0)
        for g in geometries:
            self.views.append(CameraView(
                g, params, self.pm, device, batch, self.grown, self.resolution, entries_per_pixel, max_entries,
                memory_gb, tile, table, state(g.rays.shape[0] * g.rays.shape[1]), drift,
                self.extra_bytes + sum(v.memory_bytes() for v in self.views), self.one_pass_lists,
                self.reduce_on_device, self.prior))
        self.graph = self._graph_on  # every camera's launches follow the policy
        self._allocate_arrays(geometries, params, batch * self.n_locations, start, nbrs)
        self.prior.allocate(self, batch * self.n_locations)

    def _device_policy(self, device: str, graph: bool | None) -> None:
        """What differs between the CPU and a GPU: the captured graph, the passes' scratch, how
        frames are reduced and how the joint test's lists and the top band are gathered."""
        self.graph = wp.get_device(device).is_cuda if graph is None else graph
        # the passes' scratch (kernels.evidence_pass): global on a GPU, on the stack on the CPU
        self.local_scratch = 0 if wp.get_device(device).is_cuda else K.SIZED_STACK
        self.one_pass_lists = not wp.get_device(device).is_cuda  # a big stack spills on a GPU
        self._graph, self._graph_lists = None, None
        self._marks = None  # a GPU's timing events between the cameras' lists (_camera_marks)
        self._last_rho = None  # the last frame's rho, for params.warm_start
        # full-resolution frames are reduced on a GPU (kernels.frames), by NumPy on the CPU
        self.reduce_on_device = wp.get_device(device).is_cuda
        # the joint test's lists copied out in pixel order by count, scan and fill on a GPU
        # (compact_once's atomics leave them in any order, which the host then sorted: with
        # the per-frame work since batched, half a batched frame's time on an H200), in one
        # pass on the CPU (in order there)
        self.ordered_joint_lists = wp.get_device(device).is_cuda
        # the top band counted a thread per row of each rectangle on a GPU (kernels.top_band_rows:
        # a thread per location, walking its whole rectangle, was the threshold step's longest
        # kernel there), a thread per location on the CPU (one thread: the rows' launch would be
        # the tallest rectangle's rows times longer for nothing)
        self.top_band_by_row = wp.get_device(device).is_cuda

    def _allocate_arrays(self, geometries: list[Geometry], params: ModelParams, L: int, start, nbrs) -> None:
        """Every per-location array of a batch, allocated once (the cameras' per-pixel arrays:
        engine.view)."""
        batch = self.batch
        with wp.ScopedDevice(self.device):
            # each location's silhouette area, in pixels, over the cameras
            self.area = wp.array(sum(g.area.astype(np.float64) for g in geometries), dtype=wp.float64)
            self.rho = wp.zeros(L, dtype=wp.float64)
            self.upper = wp.zeros(L, dtype=wp.float64)  # the pruning bound (kernels.sparse)
            self.evidence = wp.zeros(L, dtype=wp.float64)
            self.visible = wp.zeros(L, dtype=wp.float64)
            self.share = wp.zeros(L, dtype=wp.float64)
            # the whole silhouette's support, against, hidden, missing and seen pixels (share_of unhidden)
            self.whole = K.bands_of([wp.zeros(L, dtype=wp.int32) for _ in range(5)])
            self.rho_star = wp.zeros(L, dtype=wp.float64)
            self.max_change = wp.zeros((batch, max(1, params.max_iterations)), dtype=wp.float64)
            self.done = wp.zeros(batch, dtype=wp.int32)
            self.iterations = wp.zeros(batch, dtype=wp.int32)
            self.live = wp.ones(L, dtype=wp.int32)
            self.streak = wp.zeros(L, dtype=wp.int32)  # per-location damping runs (update_rho)
            self.live_index = wp.zeros(L, dtype=wp.int32)  # kernels.sparse.gather_live
            self.kept_index = wp.zeros(L, dtype=wp.int32)
            self.per_location = wp.zeros(L, dtype=wp.int32)  # kernels.sparse.prune_lists
            # each frame's entries, live, pruned and kept entries (kernels.sparse.frame_tally)
            self.tallies = wp.zeros((4, batch), dtype=wp.int32)
            self.live_count = wp.zeros(1, dtype=wp.int32)  # live locations (gather_live)
            self.live_changed = wp.zeros(2, dtype=wp.int32)  # live set changed, a location revived
            self.no_index = wp.zeros(0, dtype=wp.int32)
            self.not_done = wp.zeros(batch, dtype=wp.int32)
            self.neighbour_start = wp.array(start, dtype=wp.int32)
            self.neighbours = wp.array(nbrs, dtype=wp.int32)

    # -- buffers -------------------------------------------------------------------------
    @property
    def graph(self) -> bool:
        """Whether the iteration loop is captured once and replayed as a graph (engine.graph)."""
        return self._graph_on

    @graph.setter
    def graph(self, on: bool):
        # a Launcher calls the CPU kernels' entry points itself, which a capture would not
        # record: with a graph every launch is Warp's, and the launches recorded before are dropped
        self._graph_on = bool(on)
        for launcher in self.launchers():
            launcher.reset(direct=not self._graph_on)

    @property
    def joint_threshold(self) -> float | None:
        """Results carry the joint test's lists of the locations whose rho* reaches this (None:
        none; the prior's, people.PeoplePrior.joint)."""
        return self.prior.joint_threshold

    @joint_threshold.setter
    def joint_threshold(self, value: float | None):
        self.prior.joint_threshold = value

    def launchers(self) -> list[Launcher]:
        """The engine's launcher (kernels over the locations alone), then each camera's."""
        return [self._launch] + [v.launch for v in self.views]

    @property
    def direct_launch(self) -> bool:
        """Whether CPU replays call the kernels' entry points (launch.Launcher.direct)."""
        return self._launch.direct

    @direct_launch.setter
    def direct_launch(self, on: bool):
        for launcher in self.launchers():
            launcher.reset(direct=bool(on))

    def infer(self, depth_m, start: np.ndarray | None = None) -> FrameResult:
        """Occupancy probabilities of one depth frame (metres, 0 = no reading; a rig: a list of
        frames, one a camera); `start`: the rho to start from (a previous frame's, for warm
        starts) instead of the prior."""
        if len(self.views) == 1:
            return self.infer_batch(np.asarray(depth_m)[None], start)[0]
        return self.infer_batch([np.asarray(d)[None] for d in self._per_camera(depth_m, "depth")], start)[0]

    def _per_camera(self, frames, what: str) -> list:
        """A rig's frames as a list, one entry a camera (ValueError otherwise)."""
        if isinstance(frames, np.ndarray) or not hasattr(frames, "__len__") or len(frames) != len(self.views):
            found = f"an array of shape {np.shape(frames)}" if isinstance(frames, np.ndarray) else (
                f"{len(frames)} entries" if hasattr(frames, "__len__") else type(frames).__name__)
            raise ValueError(f"{what}: expected a list of {len(self.views)} frames, one a camera of the rig, "
                             f"found {found}")
        return list(frames)

    def infer_batch(self, depths_m: np.ndarray, start: np.ndarray | None = None) -> list[FrameResult]:
        """Occupancy of up to `batch` frames (n, H, W) at once (a rig: a list of such, one a
        camera); one result per frame, each equal to what `infer` gives that frame alone.
        Timings are the batch's. `start` (locations,): the rho every frame starts from instead
        of the prior."""
        dev = self.device
        per_camera = [depths_m] if len(self.views) == 1 else self._per_camera(depths_m, "depths")
        n = len(per_camera[0])
        if any(len(f) != n for f in per_camera):
            raise ValueError(f"depths: expected as many frames from every camera, found {[len(f) for f in per_camera]}")
        t0 = time.perf_counter()
        self.tallies.zero_()  # (the entries counted now: the bound's pruning changes the counts)
        drift, camera_lists = [], []
        marks = self._camera_marks()  # a GPU's events between the cameras' lists (None: the CPU's clock)
        for i, (v, frames) in enumerate(zip(self.views, per_camera)):
            tc = time.perf_counter()
            if marks:  # (on the engine's device's stream, whichever device is current)
                wp.get_stream(dev).record_event(marks[i])
            frames, estimates = v.correct_drift(frames)
            drift.append(estimates)
            v.build_lists(frames)
            v.launch(K.frame_tally, self.batch * v.n_pixels,
                     [v.lists.counts, v.n_pixels, K.TALLY_SUM, self.tallies, 0])
            camera_lists.append(time.perf_counter() - tc)  # (the CPU's launches return when done)
        if marks:
            wp.get_stream(dev).record_event(marks[-1])
        wp.synchronize_device(dev)
        if marks:
            camera_lists = [wp.get_event_elapsed_time(a, b, synchronize=False) / 1000.0 for a, b in zip(marks, marks[1:])]
        t1 = time.perf_counter()
        logit_prior, bound = self._start(n, start)
        before = [v.launch.seconds for v in self.views]
        self._run_loop(logit_prior)
        wp.synchronize_device(dev)
        t2 = time.perf_counter()
        # each camera's launches in the loop (its top band's, in _threshold, come after)
        loop_s = [v.launch.seconds - b for v, b in zip(self.views, before)]
        self._threshold()
        # each frame's live and pruned locations and the entries prune_lists kept, counted by
        # location, tallied where they are (a GPU copies back a few integers, not the arrays)
        dim = self.batch * self.n_locations
        self._launch(K.frame_tally, dim, [self.live, self.n_locations, 1, self.tallies, 1])
        self._launch(K.frame_tally, dim, [self.live, self.n_locations, K.PRUNED, self.tallies, 2])
        if bound:
            self._launch(K.frame_tally, dim, [self.per_location, self.n_locations, K.TALLY_SUM, self.tallies, 3])
        entries, live, pruned, kept = self.tallies.numpy()
        kept = kept if bound else [None] * self.batch
        # the maps: a GPU's copies are the host's own (each frame's a row of them), the CPU's are
        # views of the engine's arrays (copied, as the next call rewrites them)
        rho, rho_star, share = (self._host(a).reshape(self.batch, self.n_locations)
                                for a in (self.rho, self.rho_star, self.share))
        iterations, max_change, done = self.iterations.numpy(), self.max_change.numpy(), self.done.numpy()
        self._last_rho = rho[n - 1].copy()
        tj = time.perf_counter()
        joint = self.prior.joint(self, rho_star[:n])
        t3 = time.perf_counter()
        # (joint_lists_s: the part of threshold_s that copies the joint test's lists out)
        timings = {"lists_s": t1 - t0, "iterations_s": t2 - t1, "threshold_s": t3 - t2, "joint_lists_s": t3 - tj,
                   "total_s": t3 - t0}
        if self.batch > 1:
            timings["batch"] = n
        # each camera's lists, and its pixels' launches in the loop (the CPU's: a GPU's return at once)
        timings["lists_s_cameras"] = camera_lists
        timings["iterations_s_cameras"] = loop_s if self.views[0].launch.timed else None
        return [FrameResult(rho=rho[f], rho_star=rho_star[f], evidence_share=share[f],
                            iterations=int(iterations[f]), entries=int(entries[f]),
                            max_change=max_change[f, :iterations[f]].copy(), timings=dict(timings),
                            live=int(live[f]), converged=bool(done[f]),
                            kept_entries=None if kept[f] is None else int(kept[f]), pruned=int(pruned[f]),
                            joint=joint[f], drift=drift[0][f] if len(drift) == 1 else [d[f] for d in drift])
                for f in range(n)]

    def _camera_marks(self) -> list | None:
        """Timing events, one a camera and one after the last, on a GPU (made once); None on the CPU."""
        if wp.get_device(self.device).is_cpu:
            return None
        if self._marks is None:
            self._marks = [wp.Event(self.device, enable_timing=True) for _ in range(len(self.views) + 1)]
        return self._marks

    # -- the cameras' backgrounds and lists (engine.view), camera 0 unless told ------------
    def build_lists(self, depth_m: np.ndarray, camera: int = 0) -> int:
        """A camera's lists of a frame or batch (CameraView.build_lists); its entries."""
        return self.views[camera].build_lists(depth_m)

    def set_floor_background(self, camera: int = 0):
        """The floor-only background for a camera (CameraView.set_floor_background)."""
        self.views[camera].set_floor_background()

    def set_background_frames(self, frames_m: np.ndarray, camera: int = 0):
        """A camera's background from (N, H, W) frames in metres (CameraView.set_background_frames)."""
        self.views[camera].set_background_frames(frames_m)

    def set_background(self, bg: Background, fallback: np.ndarray | None = None, camera: int = 0) -> int:
        """A camera's given background (CameraView.set_background); the pixels left to the floor."""
        return self.views[camera].set_background(bg, fallback)

    def set_background_estimate(self, estimator, camera: int = 0) -> int:
        """A camera's auto background (CameraView.set_background_estimate)."""
        return self.views[camera].set_background_estimate(estimator)

    def background_state(self, camera: int = 0) -> tuple | None:
        """What another engine needs to hold a camera's background (CameraView.background_state)."""
        return self.views[camera].background_state()

    def background(self, frame: int = 0, camera: int = 0) -> Background:
        """A camera's background distribution of frame `frame` of the last batch (arrays (H, W))."""
        return self.views[camera].background(frame)

    def memory_bytes(self) -> int:
        """Bytes the engine's buffers hold now: the cameras' and the locations' (base.memory_estimate)."""
        return (sum(v.memory_bytes() for v in self.views) + self.batch * self.n_locations * LOCATION_BYTES
                + self.extra_bytes)


def check_rig(geometries: list[Geometry]) -> None:
    """The cameras of a rig see one grid: ValueError naming the first camera whose locations are
    not the first camera's (or none given)."""
    if not geometries:
        raise ValueError("cameras: expected at least one camera's geometry, found none")
    first = geometries[0]
    for i, g in enumerate(geometries[1:], 1):
        if g.locations.shape != first.locations.shape or not np.array_equal(g.locations, first.locations):
            raise ValueError(f"cameras[{i}]: expected the grid's {len(first.locations)} locations of cameras[0], "
                             f"found {len(g.locations)} others")
        if g.height != first.height:
            raise ValueError(f"cameras[{i}]: expected the object of cameras[0] ({first.height:g} m tall), "
                             f"found one {g.height:g} m tall")


"""Tracks with identities from a run's occupancy maps.

K-shortest paths (Berclaz, Fleuret, Turetken, Fua, PAMI 2011) as one min-cost flow: a node per
(frame, cell) that matters, holding at most one object, costs -log(rho* / (1 - rho*)); arcs
join a cell to the cells of the next frame within reach of `max_speed`; a unit of flow from
the source to the sink is one track. Tracks enter and leave at entry cells (the grid's border,
the edge of the camera's view, configured regions) for `entry_cost`, anywhere else for
`appear_cost`; a track hidden for up to `max_gap` frames is bridged by an arc between two
peaks of the maps, which pays `gap cost` = -log(min_rho / (1 - min_rho)) for every frame it
skips. The flow that sends as many tracks as lowers the total cost is the global optimum over
the maps (OR-Tools' min-cost flow; a bypass arc lets it send fewer than its supply).

The graph holds only the maps' peaks (local maxima of rho* >= `prune`, one per detection
radius, as the detections but below their threshold too); long runs are solved in windows of `window`
frames overlapping by `overlap`, stitched by the positions they agree on. `online` solves,
at every frame, the frames since the last committed one and commits the frame `delay` behind
the newest: causal, its identities fixed once written.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
from pydantic import Field

from .track_files import Track, frame_steps
from .values import Int, Node, Num, Switch, _numbers

if TYPE_CHECKING:
    from .detect import CameraViews

SCALE = 1000.0  # costs are integers for the solver: thousandths


class TrackingOptions(Node):  # the config's `tracking` section: each field declared here, once
    """Tracks with identities over the run's maps (K-shortest paths as a min-cost flow)."""

    method: Annotated[Literal["auto", "ksp", "online", "off"], Switch] = Field(
        "auto", description="auto: ksp for runs of two frames or more; ksp: offline, globally "
                            "optimal; online: causal, committed `delay` frames behind; off: no tracks")
    max_speed: Num = Field(2.0, gt=0, description="fastest move between frames, m/s")
    prune: Num = Field(0.02, gt=0, lt=1, description="cells below this rho* are left out of the graph")
    peak: Num = Field(0.3, gt=0, lt=1, description="map peaks at least this high may be bridged "
                                                   "across hidden frames")
    min_rho: Num = Field(0.02, gt=0, lt=0.5, description="rho* floor of a node's cost: a "
                                                         "bridged frame costs -log(min_rho / (1 - min_rho))")
    max_rho: Num = Field(0.999, gt=0.5, lt=1, description="rho* ceiling of a node's cost")
    jitter: Num = Field(0.2, ge=0, description="how far a map's peak may wander from the "
                                               "person between frames, metres (reach = "
                                               "max_speed / fps + jitter)")
    entry_cost: Num = Field(7.0, ge=0, description="starting or ending a track at an entry "
                                                   "cell (grid border, edge of the view, regions)")
    appear_cost: Num = Field(20.0, ge=0, description="starting or ending one anywhere else")
    max_gap: Int = Field(15, ge=0, description="most frames a track is bridged across")
    window: Int = Field(300, ge=2, description="ksp: frames per solved window")
    overlap: Int = Field(60, ge=0, description="ksp: frames two windows share (stitched there)")
    delay: Int = Field(10, ge=0, description="online: frames between the newest and the committed one")
    regions: tuple[Annotated[tuple[float, float, float, float], _numbers(4)], ...] = Field(
        (), description="more entry areas [x_min, x_max, y_min, y_max], metres (doors)")
    trail: Int = Field(30, ge=0, description="frames of trail drawn behind a track in the pictures")
    positions: Annotated[Literal["head", "cell"], Switch] = Field(
        "head", description="head: a track's position where its detection's head is seen is the head's centre "
                            "(solid objects with a head on ground grids; heads.py); cell: the map cell's centre")

    def resolved_method(self, frames: int) -> str:
        """auto: ksp for two frames or more, else off."""
        if self.method == "auto":
            return "ksp" if frames >= 2 else "off"
        return self.method


@dataclass
class Cells:
    """What the tracker knows of the grid: cell centres (K, 3), the step between
    neighbouring cells (metres), and which cells tracks may enter and leave by cheaply."""

    positions: np.ndarray
    step: float
    entry: np.ndarray  # (K,) bool
    nms_radius: float = 0.4  # a map's peaks closer than this are one object (detection.nms_radius)
    view_part: CameraViews | np.ndarray | None = None  # each camera's (or one's) share in view: detection.edge_radius
    edge_radius: float = 0.0
    edge_view: float = 0.5
    give_way: float = 0.0  # a rig's suppression between two certain cells (detection.give_way)

    @classmethod
    def of(cls, geometry, grid, image_size, regions=(), nms_radius: float = 0.4, edge_radius: float = 0.0,
           edge_view: float = 0.5, give_way: float = 0.0) -> "Cells":
        """From a run's full-resolution geometry: entry cells are the cells the camera sees on
        the grid's border, beside a cell it does not see, whose silhouette leaves the image
        (`image_size` = (width, height)), or inside a configured region [x0, x1, y0, y1]. A rig's
        (geometry.RigGeometry, `image_size` a list, one a camera): the cells any camera sees, on the
        border, beside a cell none sees, or cut by the image's edge in every camera that sees them."""
        shape = grid.shape
        rig = getattr(geometry, "parts", None) or [geometry]  # a rig (geometry.RigGeometry): what any camera sees
        sizes = image_size if len(rig) > 1 or isinstance(image_size, list) else [image_size]
        seen = np.any([g.rect_area > 0 for g in rig], axis=0).reshape(shape)
        border = np.zeros(shape, bool)
        for axis in range(len(shape)):
            idx = [slice(None)] * len(shape)
            idx[axis] = 0
            border[tuple(idx)] = True
            idx[axis] = -1
            border[tuple(idx)] = True
        beside = np.zeros(shape, bool)
        padded = np.pad(~seen, 1, constant_values=False)
        for off in np.ndindex(*(3,) * len(shape)):
            beside |= padded[tuple(slice(o, o + n) for o, n in zip(off, shape))]
        leaves = np.ones(shape, bool)  # in every camera that sees it, the silhouette leaves the image
        for g, (w, h) in zip(rig, sizes):
            r = g.rect
            cut = (r[:, 0] <= 0) | (r[:, 1] <= 0) | (r[:, 2] >= w - 1) | (r[:, 3] >= h - 1)
            leaves &= (cut | (g.rect_area <= 0)).reshape(shape)
        p = rig[0].locations
        inside = np.zeros(len(p), bool)
        for x0, x1, y0, y1 in regions:
            inside |= (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        entry = (seen & (border | beside | leaves)).ravel() | inside
        steps = [grid.x[2], grid.y[2]] + ([grid.z[2]] if grid.mode == "voxel" else [])
        from .detect import CameraViews

        return cls(np.asarray(p, float), float(max(steps)), entry, nms_radius, CameraViews.of(geometry), edge_radius,
                   edge_view, give_way)

    @classmethod
    def for_run(cls, geometry, cfg) -> "Cells":
        """`of` with a run config's grid, image size, tracking.regions and detection's
        nms_radius, edge_radius, edge_view and give_way."""
        d = cfg.detection
        sizes = [(m.camera.width, m.camera.height) for _, m in cfg.members()]
        return cls.of(geometry, cfg.grid, sizes if cfg.is_rig else sizes[0], cfg.tracking.regions,
                      d.nms_radius, d.edge_radius, d.edge_view, d.give_way)

    def nearest(self, xyz) -> int:
        """The cell nearest to a point."""
        if not hasattr(self, "_tree"):
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.positions)
        return int(self._tree.query(np.asarray(xyz, float))[1])


class FrameMaps:
    """A run's maps (maps/<stem>.npy, in frame order) read as the windows need them, flat,
    the last `keep` kept: a long run's maps are never all in memory. `maps[s:e]` is the
    (e - s, K) array of frames s..e-1, `maps[t]` one frame. Safe to read from several threads
    (the pictures are drawn on two)."""

    def __init__(self, paths, keep: int = 512):
        import threading

        self.paths, self.keep, self._cache = list(paths), keep, {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.paths)

    def _one(self, t: int) -> np.ndarray:
        with self._lock:
            m = self._cache.get(t)
        if m is None:
            m = np.load(self.paths[t]).astype(np.float32).ravel()
            with self._lock:
                if t not in self._cache and len(self._cache) >= self.keep:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[t] = m
        return m

    def __getitem__(self, index):
        if isinstance(index, slice):
            return np.stack([self._one(t) for t in range(*index.indices(len(self)))])
        return self._one(int(index))


# -- the flow over a window of frames --------------------------------------------------------
def _costs(rho, opt: TrackingOptions):
    r = np.clip(rho, opt.min_rho, opt.max_rho)
    return -np.log(r / (1.0 - r))


def peaks(rho_map: np.ndarray, cells: Cells, threshold: float) -> np.ndarray:
    """The cells that matter in a map: its local maxima of at least `threshold`, one per
    cells.nms_radius as the detections (the solid model often explains one person by two
    neighbouring cells; each would carry a track of its own; in a rig, a cell between two
    people gives way to them: detect.suppress), less a person's edge beside them
    (detect.edge_drop). Sorted cell indices."""
    from .detect import edge_drop, local_maxima, suppress

    flat = rho_map.ravel()
    cand = np.flatnonzero(local_maxima(rho_map).ravel() & (flat >= threshold))
    cand = cand[np.lexsort((cand, -flat[cand]))]
    kept = suppress(cand, flat, cells.positions, cells.nms_radius, cells.view_part, cells.give_way)
    kept = edge_drop(kept, flat, cells.positions, cells.view_part, cells.edge_radius, cells.edge_view)
    return np.array(sorted(kept), dtype=np.int64)


class PeakCache:
    """Each frame's peaks (the graph's nodes), found once however many windows hold it."""

    def __init__(self, cells: Cells, shape: tuple, prune: float, keep: int = 1024):
        self.cells, self.shape, self.prune, self.keep, self.found = cells, shape, prune, keep, {}

    def window(self, start: int, maps: np.ndarray) -> list[np.ndarray]:
        out = []
        for i in range(len(maps)):
            ks = self.found.get(start + i)
            if ks is None:
                ks = peaks(maps[i].reshape(self.shape), self.cells, self.prune)
                if len(self.found) >= self.keep:
                    self.found.pop(next(iter(self.found)))
                self.found[start + i] = ks
            out.append(ks)
        return out


def solve_window(maps: np.ndarray, cells: Cells, shape: tuple, opt: TrackingOptions, dt: float,
                 anchors: dict | None = None, nodes: list | None = None, steps: np.ndarray | None = None,
                 run_start: bool = False, run_end: bool = False) -> tuple[list[list[tuple[int, int]]], dict]:
    """The optimal tracks over `maps` (T, K) rho*: a list of paths, each a list of (t, k)
    in frame order (frames a path skips are bridged). `anchors` (online): cell k -> the
    only cells where a path may start at t = 0 (the tracks committed there); without it a
    path may start anywhere at t = 0 and end anywhere at the last frame. `nodes`: each
    frame's peaks when the caller has them (PeakCache). `steps` (T,): each map's time in
    camera frames of dt (frame_steps; frames dropped or skipped lie between the maps): a
    move from map a to map b reaches max_speed (steps[b] - steps[a]) dt + jitter instead of
    max_speed (b - a) dt + jitter (the same where the steps are a, a + 1, ...). `run_start`
    (`run_end`): the window's first (last) frame is the run's: a path may begin (end) at a
    peak away from the entry cells up to max_gap frames after it (before it) as hidden there
    until then (from then), for the gap cost a frame, as a bridge pays: its path then begins
    (ends) with the same cell at the window's first (last) frame."""
    from scipy.spatial import cKDTree

    T = maps.shape[0]
    node_t, node_k = [], []
    peak_of = []
    for t in range(T):
        if t == 0 and anchors is not None:
            ks = np.array(sorted(anchors), dtype=np.int64)
        elif nodes is not None:
            ks = nodes[t]
        else:
            ks = peaks(maps[t].reshape(shape), cells, opt.prune)
        node_t.append(np.full(len(ks), t))
        node_k.append(ks)
        peak_of.append(maps[t, ks] >= opt.peak)
    offsets = np.cumsum([0] + [len(k) for k in node_k])
    n = int(offsets[-1])
    stats = {"nodes": n, "arcs": 0}
    if n == 0:
        return [], stats
    all_t, all_k = np.concatenate(node_t), np.concatenate(node_k)
    rho = maps[all_t, all_k]
    cost = _costs(rho, opt)
    first, last = all_t == 0, all_t == T - 1
    if anchors is not None:  # committed already: their cost is paid, and they may be bridged from
        cost[first] = 0.0
        peak_of[0][:] = True
    gap = float(_costs(np.array([opt.min_rho]), opt)[0])
    src, snk = 2 * n, 2 * n + 1
    tails, heads, costs = [np.arange(n) * 2], [np.arange(n) * 2 + 1], [cost]  # in -> out
    base = max(opt.jitter, cells.step)
    if steps is None:
        reach = [opt.max_speed * s * dt + base for s in range(opt.max_gap + 2)]
    else:  # the longest time s maps apart in this window sets the query's radius (s < T)
        steps = np.asarray(steps, np.float64)
        reach = [base] + [opt.max_speed * float(np.max(steps[s:] - steps[:-s])) * dt + base
                          for s in range(1, min(opt.max_gap + 1, T - 1) + 1)]
    # moves to the next frame from every node, bridges of s frames between peaks: for each s
    # one KD-tree query over the window, frames kept apart by a time axis far larger than
    # any reach (a node of frame t, shifted by s, meets only the nodes of frame t + s)
    pos = cells.positions[all_k]
    apart = 1e4 + 10 * max(reach)
    is_peak = np.concatenate(peak_of)
    for s in range(1, min(opt.max_gap + 1, T - 1) + 1):
        src_nodes = np.flatnonzero((all_t + s < T) & (is_peak if s > 1 else True))
        dst_nodes = np.flatnonzero((all_t >= s) & (is_peak if s > 1 else True))
        if not len(src_nodes) or not len(dst_nodes):
            continue
        a = cKDTree(np.c_[pos[src_nodes], (all_t[src_nodes] + s) * apart])
        b = cKDTree(np.c_[pos[dst_nodes], all_t[dst_nodes] * apart])
        pairs = a.sparse_distance_matrix(b, reach[s], output_type="ndarray")
        if steps is not None:  # each pair within its own maps' time apart
            t_i = all_t[src_nodes[pairs["i"]]]
            pairs = pairs[pairs["v"] <= opt.max_speed * (steps[t_i + s] - steps[t_i]) * dt + base]
        i, j = src_nodes[pairs["i"]], dst_nodes[pairs["j"]]
        tails.append(i * 2 + 1)
        heads.append(j * 2)
        costs.append(np.full(len(i), (s - 1) * gap))
    entry = cells.entry[all_k]
    enter = np.where(first, 0.0, np.where(entry, opt.entry_cost, opt.appear_cost))
    leave = np.where(last, 0.0, np.where(entry, opt.entry_cost, opt.appear_cost))
    if anchors is not None:  # a committed track pays its end as offline: dropping it is not free
        enter[first] = -leave[first]
    hid_in, hid_out = _hidden_ends(all_t, T, is_peak & ~entry, enter, leave, gap, opt.max_gap,
                                   run_start and anchors is None, run_end)
    enter = np.where(hid_in, all_t * gap, enter)
    leave = np.where(hid_out, (T - 1 - all_t) * gap, leave)
    tails += [np.full(n, src), np.arange(n) * 2 + 1, [src]]
    heads += [np.arange(n) * 2, np.full(n, snk), [snk]]
    supply = max(1, int(np.sum(cost < 0)) + (len(anchors) if anchors is not None else 0))
    costs += [enter, leave, [0.0]]
    paths, stats = _min_cost_paths(tails, heads, costs, supply, all_t, all_k, stats)
    if hid_in.any() or hid_out.any():
        node = {(int(t), int(k)): i for i, (t, k) in enumerate(zip(all_t, all_k))}
        for p in paths:  # a hidden start (end): the same cell at the window's first (last) frame, bridged
            if hid_in[node[p[0]]]:
                p.insert(0, (0, p[0][1]))
            if hid_out[node[p[-1]]]:
                p.append((T - 1, p[-1][1]))
    return paths, stats


def _hidden_ends(all_t, T: int, inner_peak, enter, leave, gap: float, max_gap: int, run_start: bool,
                 run_end: bool) -> tuple[np.ndarray, np.ndarray]:
    """Which nodes of a window may begin (end) a path hidden since the run's first frame (until
    its last): a track first seen in the middle of the floor a few frames in was there, hidden,
    as one unseen for a few frames mid-run is bridged. A peak away from the entry cells
    (`inner_peak`), at most `max_gap` frames from that end, where the gap cost of those frames
    is under its `enter` (`leave`) cost; none where the window's end is not the run's."""
    none = np.zeros(len(all_t), bool)
    hid_in = inner_peak & (all_t >= 1) & (all_t <= max_gap) & (all_t * gap < enter) if run_start else none
    after = T - 1 - all_t
    hid_out = inner_peak & (after >= 1) & (after <= max_gap) & (after * gap < leave) if run_end else none
    return hid_in, hid_out


def _min_cost_paths(tails: list, heads: list, costs: list, supply: int, all_t, all_k, stats: dict):
    """The min-cost flow of `supply` units over the window's arcs (lists of arrays: tails, heads,
    costs in cost units; the source and sink are the last two nodes), solved by OR-Tools; the
    paths it takes as (t, location) lists, each from its start, and `stats` with the arcs and
    the optimal cost."""
    from ortools.graph.python import min_cost_flow

    n = len(all_t)
    src, snk = 2 * n, 2 * n + 1
    tails, heads = np.concatenate(tails).astype(np.int64), np.concatenate(heads).astype(np.int64)
    costs = np.round(np.concatenate(costs) * SCALE).astype(np.int64)
    caps = np.ones(len(tails), np.int64)
    caps[-1] = supply
    flow = min_cost_flow.SimpleMinCostFlow()
    arcs = flow.add_arcs_with_capacity_and_unit_cost(tails, heads, caps, costs)
    flow.set_nodes_supplies(np.array([src, snk]), np.array([supply, -supply]))
    status = flow.solve()
    if status != flow.OPTIMAL:
        raise RuntimeError(f"tracking: the min-cost flow solver returned status {status}")
    used = flow.flows(arcs) > 0
    stats["arcs"] = int(len(tails))
    stats["cost"] = flow.optimal_cost() / SCALE
    moves = used & (tails < 2 * n) & (heads < 2 * n) & (tails % 2 == 1)
    succ = dict(zip((tails[moves] // 2).tolist(), (heads[moves] // 2).tolist()))
    starts = heads[used & (tails == src) & (heads < 2 * n)] // 2
    paths = []
    for i in sorted(starts.tolist()):
        path = []
        while i is not None:
            path.append((int(all_t[i]), int(all_k[i])))
            i = succ.get(i)
        paths.append(path)
    return paths, stats


def _expand(path, t0, maps, cells, threshold):
    """(t, xyz, rho, bridged) of every frame of a path, t counted from t0 (`maps` starts
    there); skipped frames are interpolated between the peaks they join, with the rho* of
    the cell nearest to where they put the track."""
    out = []
    for (ta, ka), nxt in zip(path, path[1:] + [None]):
        pa = cells.positions[ka]
        out.append((t0 + ta, pa, float(maps[ta, ka]), float(maps[ta, ka]) < threshold))
        if nxt is not None and nxt[0] > ta + 1:
            pb = cells.positions[nxt[1]]
            for t in range(ta + 1, nxt[0]):
                p = pa + (t - ta) / (nxt[0] - ta) * (pb - pa)
                out.append((t0 + t, p, float(maps[t, cells.nearest(p)]), True))
    return out


def _first_key(rows: list) -> tuple:
    """A track's place in the numbering: its first frame, then its position there."""
    return rows[0][0], round(float(rows[0][1][0]), 4), round(float(rows[0][1][1]), 4)


def _tracks_from(rows_by_id: dict) -> list[Track]:
    """Tracks numbered 1, 2, ... by first frame then position (deterministic)."""
    items = []
    for rows in rows_by_id.values():
        rows = sorted(rows, key=lambda r: r[0])
        if rows:
            items.append(rows)
    items.sort(key=_first_key)
    tracks = []
    for i, rows in enumerate(items, 1):
        frames = [r[0] for r in rows]
        xyz = np.array([r[1] for r in rows], float)
        rho = np.array([r[2] for r in rows])
        tracks.append(Track(i, frames, xyz, rho, np.array([r[3] for r in rows], bool)))
    return tracks


def track_offline(maps: np.ndarray, cells: Cells, shape: tuple, opt: TrackingOptions, dt: float,
                  threshold: float = 0.5, times: list | None = None) -> tuple[list[Track], dict]:
    """KSP over the whole run in windows of opt.window frames overlapping by opt.overlap; a
    path of a later window takes the identity of the earlier window's path it agrees with
    most in the overlap (the same cell within one step, at least a quarter of the frames),
    and the windows meet in the overlap's middle. `times`: each map's time in seconds (a
    recording's timestamps), where frames were dropped or skipped between the maps
    (frame_steps); without them the maps lie dt apart."""
    T = len(maps)
    steps = frame_steps(times, dt)
    win = max(2, opt.window)
    lap = min(max(0, opt.overlap), win - 1)
    starts = [0]
    while starts[-1] + win < T:
        starts.append(starts[-1] + win - lap)
    ids: dict[int, list] = {}
    prev: dict[int, dict] = {}  # id -> {t: xyz} of the previous window
    next_id, stats = 0, {"windows": len(starts), "nodes": 0, "arcs": 0, "max_nodes": 0, "max_arcs": 0}
    cache = PeakCache(cells, shape, opt.prune, keep=2 * win)
    for w, s in enumerate(starts):
        e = min(T, s + win)
        window = maps[s:e]
        paths, st = solve_window(window, cells, shape, opt, dt, nodes=cache.window(s, window),
                                 steps=None if steps is None else steps[s:e], run_start=s == 0, run_end=e == T)
        for key in ("nodes", "arcs"):
            stats[key] += st[key]
            stats[f"max_{key}"] = max(stats[f"max_{key}"], st[key])
        cut = s + lap // 2 if w > 0 else s  # frames before `cut` come from the earlier window
        rows_now = [_expand(p, s, window, cells, threshold) for p in paths]
        assign = _stitch(prev, rows_now, s, min(e, s + lap), cells.step) if w > 0 else {}
        current: dict[int, dict] = {}
        for j, rows in enumerate(rows_now):
            if j in assign:
                tid = assign[j]
                ids[tid] = [r for r in ids[tid] if r[0] < cut]
            else:
                next_id += 1
                tid = next_id
                ids[tid] = []
            ids[tid] += [r for r in rows if r[0] >= cut]
            current[tid] = {r[0]: r[1] for r in rows}
        for tid in set(prev) - set(assign.values()):
            ids[tid] = [r for r in ids[tid] if r[0] < cut]  # the later window decides after the cut
        prev = current
    return _tracks_from({k: v for k, v in ids.items() if v}), stats


def _stitch(prev: dict, rows_now: list, a: int, b: int, step: float) -> dict:
    """Path index of the new window -> identity of the earlier window, by the frames in
    [a, b) where both are at the same place (within 1.5 steps): Hungarian on the counts."""
    from scipy.optimize import linear_sum_assignment

    if not prev or not rows_now or b <= a:
        return {}
    old = list(prev)
    agree = np.zeros((len(rows_now), len(old)))
    for j, rows in enumerate(rows_now):
        here = {r[0]: r[1] for r in rows if a <= r[0] < b}
        for i, tid in enumerate(old):
            there = prev[tid]
            agree[j, i] = sum(1 for t, p in here.items()
                              if t in there and np.linalg.norm(there[t] - p) <= 1.5 * step)
    rj, ri = linear_sum_assignment(-agree)
    need = max(1, (b - a) // 4)
    return {int(j): old[i] for j, i in zip(rj, ri) if agree[j, i] >= need}


class OnlineTracker:
    """The causal tracker, fed one map at a time (`push`): when frame t arrives the flow is
    solved over the frames from the last committed one (whose tracks are the only starts
    there) to t, and frame t - delay is committed; `finish` commits the rest. Identities,
    once committed, never change, and are those `finish` returns (new tracks are numbered
    as _tracks_from numbers them: by first frame, then position); `take_committed` gives
    each committed frame's tracks as they are committed (a live run's pictures and view).
    Holds at most delay + 1 maps."""

    def __init__(self, cells: Cells, shape: tuple, opt: TrackingOptions, dt: float, threshold: float = 0.5):
        self.cells, self.shape, self.opt, self.dt, self.threshold = cells, shape, opt, dt, threshold
        self.delay = max(0, opt.delay)
        self.ids: dict[int, list] = {}
        self.at: dict[int, tuple] = {}  # cell k of the last committed frame -> (id, xyz)
        self.next_id, self.committed, self.t = 0, -1, -1
        self.window: list[np.ndarray] = []  # maps from frame max(committed, 0) on
        self.times: list = []  # their times (push), None where not given
        self.stats = {"solves": 0, "max_nodes": 0, "max_arcs": 0, "delay_frames": self.delay}
        self.cache = PeakCache(cells, shape, opt.prune, keep=2 * self.delay + 8)
        self.newly: list[tuple[int, list]] = []  # committed frames not yet taken (take_committed)

    def push(self, rho_map: np.ndarray, time_s: float | None = None) -> None:
        """The next map; `time_s`: when its frame was taken (seconds, a camera's timestamp),
        where frames were dropped between the maps (frame_steps)."""
        self.t += 1
        self.window.append(np.asarray(rho_map, np.float32).ravel())
        self.times.append(time_s)
        c = self.t - self.delay
        if c >= 0 and c > self.committed:
            self._commit(c)

    def finish(self) -> tuple[list[Track], dict]:
        if self.t > self.committed:
            self._commit(self.t, run_end=True)
        return _tracks_from({k: v for k, v in self.ids.items() if v}), self.stats

    def take_committed(self) -> list[tuple[int, list]]:
        """The frames committed since the last call, in order: (frame index, [(id, xyz,
        bridged)] by id), what per_frame of the final tracks gives for those frames."""
        out, self.newly = self.newly, []
        return out

    def _commit(self, c: int, run_end: bool = False) -> None:
        committed, cells = self.committed, self.cells
        a = committed if committed >= 0 else 0
        anchors = dict(self.at) if committed >= 0 else None
        window = np.stack(self.window)
        paths, st = solve_window(window, cells, self.shape, self.opt, self.dt, anchors, self.cache.window(a, window),
                                 frame_steps(self.times, self.dt), run_start=committed < 0, run_end=run_end)
        self.stats["solves"] += 1
        self.stats["max_nodes"] = max(self.stats["max_nodes"], st["nodes"])
        self.stats["max_arcs"] = max(self.stats["max_arcs"], st["arcs"])
        new_at, fresh, added = {}, {}, []  # fresh: the new tracks' rows by a placeholder id (< 0)
        for p in paths:
            rows = _expand(p, a, window, cells, self.threshold)
            tid = None
            if committed >= 0 and p[0][0] == 0:
                tid = self.at[p[0][1]][0]
                rows = [r for r in rows if r[0] > committed]
            rows = [r for r in rows if r[0] <= c]
            if not rows:
                continue
            if tid is None:
                tid = -1 - len(fresh)
                fresh[tid] = rows
            else:
                self.ids[tid] += rows
            added.append((tid, rows))
            last = rows[-1]
            if last[0] == c:
                new_at.setdefault(cells.nearest(last[1]), (tid, last[1]))
        # every track starting in these frames starts here: numbered by first frame, then
        # position, they get the numbers the run's tracks will have (_tracks_from)
        number = {}
        for tmp in sorted(fresh, key=lambda i: _first_key(fresh[i])):
            self.next_id += 1
            number[tmp] = self.next_id
            self.ids[self.next_id] = fresh[tmp]
        new_at = {k: (number.get(tid, tid), xyz) for k, (tid, xyz) in new_at.items()}
        now: dict[int, list] = {}
        for tid, rows in added:
            for r in rows:
                now.setdefault(r[0], []).append((number.get(tid, tid), r[1], bool(r[3])))
        self.newly += [(f, sorted(now.get(f, []), key=lambda v: v[0])) for f in range(committed + 1, c + 1)]
        self.at, self.committed = new_at, c
        self.window = self.window[c - a:]  # frame c is the next window's first
        self.times = self.times[c - a:]


def frames_without_map(times: list | None, dt: float) -> int:
    """The camera frames between maps that have none (dropped, lost or skipped), by the
    maps' timestamps (frame_steps); 0 without them."""
    steps = frame_steps(times, dt)
    return 0 if steps is None else int(np.sum(np.diff(steps) - 1))


def track_online(maps: np.ndarray, cells: Cells, shape: tuple, opt: TrackingOptions, dt: float,
                 threshold: float = 0.5, times: list | None = None) -> tuple[list[Track], dict]:
    """OnlineTracker over `maps` frame by frame (what a live run does as frames arrive), each
    with its time in seconds where `times` are given."""
    tracker = OnlineTracker(cells, shape, opt, dt, threshold)
    for t in range(len(maps)):
        tracker.push(maps[t], None if times is None else times[t])
        tracker.take_committed()  # (the frames as committed are the final tracks': not kept twice)
    return tracker.finish()


def run_tracker(maps: np.ndarray, cells: Cells, shape: tuple, opt: TrackingOptions, fps: float,
                threshold: float = 0.5, method: str | None = None, times: list | None = None
                ) -> tuple[list[Track], dict]:
    """Tracks of `maps` ((T, K) array or FrameMaps) by `method` (default opt's, resolved for
    T frames) and a report for summary.json (method, tracks, time, graph size). `times`: each
    map's timestamp in seconds (None where unknown): moves are judged by the camera frames
    between two maps, dropped ones included (frame_steps)."""
    method = method or opt.resolved_method(len(maps))
    t = time.perf_counter()
    if method == "off":
        return [], {"method": "off"}
    dt = 1.0 / fps
    fn = track_offline if method == "ksp" else track_online
    tracks, stats = fn(maps, cells, shape, opt, dt, threshold, times)
    stats["frames_without_map"] = frames_without_map(times, dt)
    spent = time.perf_counter() - t
    return tracks, {"method": method, "tracks": len(tracks), "time_s": spent,
                    "ms_per_frame": 1000 * spent / max(1, len(maps)), "fps": fps, **stats}



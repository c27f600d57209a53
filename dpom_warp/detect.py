"""Detections from an occupancy map: local maxima above a threshold, then greedy
non-maximum suppression within a radius (MODEL.md, Detections and scores); a cell mostly
outside the image beside a detection in view is that person's edge (detection.edge_radius);
a detection the model gives too little log posterior odds with the others present leaves the
map (the joint test, detection.min_log_odds)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .geometry import closer


EDGE_RADIUS = 0.45  # detection.edge_radius's default on ground grids (config; README, How it works)
MIN_LOG_ODDS = 10.0  # detection.min_log_odds's default, nats (README, How it works)
GIVE_WAY = 0.99  # detection.give_way's default: a rig's suppression between two certain cells (docs/rig.md)


@dataclass(frozen=True)
class Detected:
    """One detection: location index k, world position (metres), rho* and image box; with
    the joint test, its log posterior odds with the other detections present (nats; None
    where not computed: the test off, or detections re-detected from a map)."""

    k: int
    x: float
    y: float
    z: float
    rho: float
    box: tuple[int, int, int, int]
    log_odds: float | None = None


@dataclass(frozen=True)
class CameraViews:
    """What the edge rule reads of each camera (one, or a rig's): each location's share in view
    (C, K), and, where known, its silhouette rectangle (C, K, 4) with its area in the image
    (C, K) and the camera's centre (C, 3)."""

    view_part: np.ndarray
    rect: np.ndarray | None = None
    rect_area: np.ndarray | None = None
    centre: np.ndarray | None = None

    @classmethod
    def of(cls, geometry) -> "CameraViews | None":
        """From a Geometry or a geometry.RigGeometry (its `parts`); None without view parts."""
        parts = getattr(geometry, "parts", None) or [geometry]
        if any(g.view_part is None for g in parts):
            return None
        return cls(np.stack([g.view_part for g in parts]), np.stack([g.rect for g in parts]),
                   np.stack([g.rect_area for g in parts]), np.stack([g.centre for g in parts]))

    @classmethod
    def single(cls, view_part: np.ndarray) -> "CameraViews":
        return cls(np.asarray(view_part)[None])

    @property
    def best(self) -> np.ndarray:
        """(K,) the largest share in view over the cameras."""
        return self.view_part.max(axis=0)

    def at_edge(self, k: int, edge_view: float) -> bool:
        """Whether location k is mostly outside every image, or cut by some image's edge."""
        vp = self.view_part[:, k]
        return bool(vp.max() < edge_view or np.any((vp > 0) & (vp < edge_view)))

    def hidden(self, k: int, j: int, c: int, edge_view: float, locations: np.ndarray) -> bool:
        """Whether, in camera c, location k lies behind j, j's rectangle covering at least
        `edge_view` of k's (unknown rectangles: never)."""
        if self.rect is None or self.rect_area[c, k] <= 0:
            return False
        centre = self.centre[c]
        if np.linalg.norm(locations[k] - centre) <= np.linalg.norm(locations[j] - centre):
            return False
        a, b = self.rect[c, k], self.rect[c, j]
        w, h = min(a[2], b[2]) - max(a[0], b[0]) + 1, min(a[3], b[3]) - max(a[1], b[1]) + 1
        return max(w, 0) * max(h, 0) >= edge_view * self.rect_area[c, k]

    def beside(self, k: int, j: int, edge_view: float, locations: np.ndarray) -> float:
        """k's largest share in view over the cameras in which it is not hidden behind j (0
        where it is hidden in every one)."""
        return max((float(self.view_part[c, k]) for c in range(len(self.view_part))
                    if not self.hidden(k, j, c, edge_view, locations)), default=0.0)


def local_maxima(rho_map: np.ndarray) -> np.ndarray:
    """Boolean map of cells not smaller than any of their neighbours (8- or 26-connected)."""
    padded = np.pad(rho_map, 1, mode="constant", constant_values=-np.inf)
    best = np.full(rho_map.shape, -np.inf)
    for off in np.ndindex(*(3,) * rho_map.ndim):
        if all(o == 1 for o in off):
            continue
        sl = tuple(slice(o, o + n) for o, n in zip(off, rho_map.shape))
        best = np.maximum(best, padded[sl])
    return rho_map >= best


def detect(rho_star: np.ndarray, locations: np.ndarray, rect: np.ndarray, threshold: float,
           nms_radius: float, view_part: np.ndarray | CameraViews | None = None, edge_radius: float = 0.0,
           edge_view: float = 0.5, give_way: float = 0.0) -> list[Detected]:
    """Detections of one frame, strongest first.

    Args:
        rho_star: occupancy map (grid shape), soft-thresholded; taken as float32, as the maps
            are written, so that the detections re-detected from a run's maps are the run's
            (cells saturated near 1 were ordered by digits the maps drop; ties now go to the
            cell with the most occupancy around it).
        locations: (K, 3) location centres, metres, in map order.
        rect: (K, 4) silhouette rectangles u0, v0, u1, v1.
        threshold: minimum rho*.
        nms_radius: a detection suppresses weaker ones closer than this, metres.
        view_part: (K,) the share of each location's silhouette rectangle inside the image
            (Geometry.view_part), or each camera's (CameraViews: a rig's); None: every
            location in view.
        edge_radius, edge_view: after the suppression, edge_drop.
        give_way: in a rig, the suppression's give-way level (suppress).
    """
    from scipy.ndimage import uniform_filter

    rho_star = np.asarray(rho_star, dtype=np.float32)
    flat = rho_star.ravel()
    cand = np.flatnonzero(local_maxima(rho_star).ravel() & (flat >= threshold))
    # strongest first; among equals (cells saturated at 1) the one whose 3 x 3 (x 3)
    # neighbourhood holds the most, the middle of its blob; then by index
    mass = uniform_filter(rho_star.astype(np.float64), 3, mode="constant").ravel()
    cand = cand[np.lexsort((cand, -mass[cand], -flat[cand]))]
    kept = suppress(cand, flat, locations, nms_radius, view_part, give_way)
    kept = edge_drop(kept, flat, locations, view_part, edge_radius, edge_view)
    return [Detected(k, *(float(c) for c in locations[k]), float(flat[k]),
                     tuple(int(b) for b in rect[k])) for k in kept]


def suppress(cand: np.ndarray, flat: np.ndarray, locations: np.ndarray, radius: float,
             views: np.ndarray | CameraViews | None = None, give_way: float = 0.0) -> list[int]:
    """Greedy non-maximum suppression of `cand` (cells, in the order they are taken): each kept
    unless closer than `radius` to one kept before it. In a rig of several cameras (`views` a
    CameraViews of more than one), a kept cell of rho* (`flat`) at least `give_way` (0: never)
    that suppresses two such cells not closer than `radius` to each other stands between two
    people, one object explaining neither (the cameras see people from several sides, which pins
    each one's cell): it gives way, and the suppression is made again without it (docs/rig.md).
    One camera sees a person's front only and spreads it over certain cells along its rays and
    across its width, so there the rule would split people in two: it is a rig's alone."""
    def greedy(cells) -> list[int]:
        kept: list[int] = []
        for k in cells:
            if not any(closer(np.linalg.norm(locations[k] - locations[j]), radius) for j in kept):
                kept.append(int(k))
        return kept

    kept = greedy(cand)
    if give_way <= 0 or not isinstance(views, CameraViews) or len(views.view_part) < 2:
        return kept

    def between(k: int) -> bool:
        if flat[k] < give_way:
            return False
        near = [j for j in cand if j != k and flat[j] >= give_way
                and closer(np.linalg.norm(locations[k] - locations[j]), radius)]
        return any(not closer(np.linalg.norm(locations[a] - locations[b]), radius)
                   for i, a in enumerate(near) for b in near[i + 1:])

    while (middle := next((k for k in kept if between(k)), None)) is not None:
        cand = cand[cand != middle]
        kept = greedy(cand)
    return kept


def edge_drop(kept: list[int], flat: np.ndarray, locations: np.ndarray,
              view_part: np.ndarray | CameraViews | None, edge_radius: float, edge_view: float) -> list[int]:
    """`kept` (cells of one map) less those with view_part < edge_view (their silhouette
    rectangle mostly outside the image: the axis out of view) that lie closer than
    `edge_radius` (metres; 0: off) to another kept cell with view_part >= edge_view and at
    least their value in `flat`: what is in view of such a cell is the edge of the person found
    beside it, its core (where a second cell meets the readings behind it) outside the image.
    A rig's cell (CameraViews of several cameras) is such an edge when some image cuts it (or
    every image leaves it mostly out) and every camera that has it mostly in view sees it
    behind that neighbour, which hides it there: no camera sees more of it than an edge
    (docs/rig.md). With one camera the two rules are the same."""
    if view_part is None or edge_radius <= 0:
        return kept
    views = view_part if isinstance(view_part, CameraViews) else CameraViews.single(view_part)
    best = views.best
    seen = [j for j in kept if best[j] >= edge_view]

    def edge_of(k: int, j: int) -> bool:
        return (j != k and flat[j] >= flat[k] and closer(np.linalg.norm(locations[k] - locations[j]), edge_radius)
                and views.beside(k, j, edge_view, locations) < edge_view)

    return [k for k in kept if not views.at_edge(k, edge_view) or not any(edge_of(k, j) for j in seen)]


def detect_map(rho_star: np.ndarray, geometry, detection, threshold: float | None = None) -> list[Detected]:
    """detect() with a run config's detection section (`threshold` overrides its threshold)
    on a geometry's locations, rectangles and view parts."""
    return detect(rho_star, geometry.locations, geometry.rect,
                  detection.threshold if threshold is None else threshold, detection.nms_radius,
                  CameraViews.of(geometry), detection.edge_radius, detection.edge_view, detection.give_way)


def joint_detections(rho_map: np.ndarray, geometry, detection, log_odds=None) -> tuple[np.ndarray, list[Detected]]:
    """detect_map, then the joint test: while the weakest detection's log posterior odds with
    the other detections present and every other location empty (`log_odds(cells)` -> (n,),
    a frame's joint.JointLists.log_odds) is under detection.min_log_odds, its cell leaves
    the map (rho* 0) and the map is detected again. Returns the map (a copy where a cell left
    it) and its detections, which detect_map finds again in that map, each with its log odds;
    `log_odds` None or min_log_odds 0: the map and detect_map's."""
    dets = detect_map(rho_map, geometry, detection)
    if log_odds is None or detection.min_log_odds <= 0:
        return rho_map, dets
    out = rho_map
    while dets:
        odds = log_odds([d.k for d in dets])
        weakest = int(np.argmin(odds))
        if odds[weakest] >= detection.min_log_odds:
            return out, [replace(d, log_odds=float(o)) for d, o in zip(dets, odds)]
        if out is rho_map:
            out = np.array(rho_map)
        out.flat[dets[weakest].k] = 0.0
        dets = detect_map(out, geometry, detection)
    return out, dets

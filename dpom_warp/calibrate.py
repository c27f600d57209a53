"""`dpom-warp calibrate CONFIG --output OUT.yaml`: a rig's cameras placed in one world without a
tape measure (issue 61, item 3).

Each camera's floor fit (ground.py, on the median of its background frames, else of frames
spread over its sequence) gives its height, pitch and roll, and a frame whose floor is z = 0
(the camera above its origin, looking along +y). What the fit cannot give, the turn about z
(yaw) and the position on the floor, comes from what the cameras see at once:

- people walking through the overlap: each camera alone finds them (the single-camera
  Detector, in its floor frame, on a grid over the floor it sees), frame by frame; the same
  person seen by two cameras in one rig frame is one point in two frames of reference, and a
  planar turn and shift maps one set onto the other. Every pair of detections in a frame of
  one camera against every pair as far apart in the same frame of the other is a hypothesis
  (two points fix a turn and a shift); of the hypotheses most agree on (coarse bins of turn
  and shift, the most voted, up to MAX_SCORED of them: a crowd gives hundreds of thousands),
  the one that lays the most detections of the camera within MATCH of another camera's over
  all frames wins (deterministic), and its matches give the least-squares turn and shift
  (Procrustes on the floor). Once every camera has its first guess, the cameras placed so are
  refined together (`joint_people`): every pair of cameras' detections of the same people at
  once, in robust least squares (soft L1 at NEAR, a detection's own noise), so that a camera
  placed early also learns from those placed after it and each camera's error is shared
  among all the pairs that see its people, not left to the one placed last;
- the static scene (walls, furniture) above the floor, as points: Open3D's point-to-plane ICP
  refines the turn and shift from there (kept when it moves them little), and gives the
  residual; with no frames of people seen by two cameras, the scene alone is registered (its
  footprints correlated on the floor for every degree of turn, then ICP): a room whose walls
  look alike from several places can fool that, so the people are the better cue.

The first camera fixes the world: its given pose where it has one, else its floor frame. Each
other camera is first placed against those placed before it. A camera with fewer than MIN_MATCHES
people matched and too little of its scene within NEAR of theirs (MIN_OVERLAP) shares too
little with the others: a one-line error naming it."""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig, read_config, resolve_paths
from .io import InputError, write_text_atomic

CELL = 0.1  # metres: the top view's cells (the scene's coarse search)
ABOVE_FLOOR = (0.15, 2.5)  # metres: the static scene registered (the floor itself carries no yaw or shift)
NEAR = 0.05  # metres: a point's neighbour in the residual and the overlap
MIN_OVERLAP = 0.5  # the static scene alone: the share of a camera's points that must lie within NEAR of the others'
MEDIAN_FRAMES = 30  # frames spread over a sequence whose median is the static scene (no background frames)
PEOPLE_FRAMES = 40  # rig frames spread over the sequence whose people are matched across cameras
MATCH = 0.3  # metres: a camera's detection matches another's within this
MIN_MATCHES = 8  # people matched across cameras that place a camera
SPAN = 0.6  # metres: the least distance between the two detections of a hypothesis
ALIKE = 0.8  # the scene alone: a second best this close to the best is ambiguous
MAX_SCORED = 8192  # two-point hypotheses scored by their matches: those most agreed on (most_voted)
VOTE_BIN = (0.25, 5.0)  # metres, degrees: the bins in which hypotheses vote for a turn and a shift
REFINE_MOVE = (0.15, 3.0)  # the scene's ICP is kept where it moves the people's estimate less than this (m, deg)


@dataclass
class Placed:
    """A camera placed: its pose in the world, its static points there, how well they meet
    the cameras placed before (None for the first), and its people matched with the other
    cameras' under the poses placed, with their RMS distance."""

    name: str
    T_world_from_camera: np.ndarray
    points: np.ndarray
    residual_m: float | None = None
    overlap: float | None = None
    people: int | None = None  # people matched across cameras
    people_rms_m: float | None = None

    def report(self) -> dict:
        h, pitch, roll, yaw = pose_angles(self.T_world_from_camera)
        return {"camera": self.name, "height_m": round(h, 4), "pitch_deg": round(pitch, 3), "roll_deg": round(roll, 3),
                "yaw_deg": round(yaw, 3), "x_m": round(float(self.T_world_from_camera[0, 3]), 4),
                "y_m": round(float(self.T_world_from_camera[1, 3]), 4),
                "residual_m": None if self.residual_m is None else round(self.residual_m, 4),
                "overlap": None if self.overlap is None else round(self.overlap, 3),
                "people_matched": self.people,
                "people_rms_m": None if self.people_rms_m is None or not self.people else round(self.people_rms_m, 4)}


def pose_angles(T: np.ndarray) -> tuple[float, float, float, float]:
    """(height m, pitch, roll, yaw degrees) of a pose as geometry.pose_from_angles takes them."""
    R = np.asarray(T, float)[:3, :3]
    right, forward = R[:, 0], R[:, 2]
    pitch = np.arcsin(np.clip(-forward[2], -1.0, 1.0))
    yaw = np.arctan2(-forward[0], forward[1])
    roll = np.arcsin(np.clip(-right[2] / max(np.cos(pitch), 1e-9), -1.0, 1.0))
    return float(T[2][3]), float(np.rad2deg(pitch)), float(np.rad2deg(roll)), float(np.rad2deg(yaw))


def static_frame(m: RunConfig, log=print) -> tuple[np.ndarray, str]:
    """A camera's static scene in metres: the median of its background frames, else of up to
    MEDIAN_FRAMES frames spread over its sequence; and what it was made of (for messages)."""
    from .sources import expand, source_frames
    from .structure import median_frame
    from .worker import read_frame

    if m.inputs.background and m.inputs.background != "auto":
        files = expand(m.inputs.background, "input.background", m.inputs.topic, log)
        what = f"{len(files)} background frames"
    else:
        if m.inputs.frames is None:
            raise ConfigError("input.frames: required key is missing (calibrate needs frames or background frames)")
        files, _ = source_frames(m.inputs.frames, "input.frames", m.inputs.topic, log)
        files = [files[i] for i in np.unique(np.linspace(0, len(files) - 1, min(MEDIAN_FRAMES, len(files))).astype(int))]
        what = f"the median of {len(files)} frames"
    return median_frame([read_frame(m, f) for f in files]), what


def floor_frame(m: RunConfig, depth: np.ndarray, where: str):
    """The camera's floor fit: its pose in its own floor frame (floor z = 0, under it, looking
    along +y) and where the floor it sees lies."""
    from .ground import GroundFitError, fit_ground_frames

    try:
        return fit_ground_frames([depth], m.camera, m.ground)
    except GroundFitError as e:
        raise InputError(f"{where}: {e}") from None


def people_seen(m: RunConfig, fit, files: list, device: str | None, log=print) -> list[np.ndarray]:
    """Where the camera alone finds people in each of `files` (None: no frame), on the floor of
    its own floor frame ((n, 2) a frame): the single-camera engine of its config (its background,
    model and detection) over a grid on the floor it sees; each at its head where the camera
    sees it and the config places tracks there (heads.py), else at its cell."""
    from .config import parse_config
    from .session import set_up
    from .worker import FrameWorker, read_frame

    x0, x1, y0, y1 = fit.floor_xy or (-3.0, 3.0, 0.5, 6.0)
    step = 0.1
    raw = {k: v for k, v in m.resolved.items() if k not in ("synthetic",)}
    raw["camera"] = {**raw["camera"], "extrinsics": {"T_world_from_camera": fit.T_world_from_camera.tolist()}}
    raw["grid"] = {"mode": "ground", "x": [max(x0, -5.0), min(x1, 5.0), step], "y": [max(y0, 0.3), min(y1, 8.0), step]}
    raw["evaluation"] = {**raw["evaluation"], "ground_truth": None}
    cfg = parse_config(raw)
    setup = set_up(cfg, [f for f in files if f is not None], device, lambda *_: None)
    worker = FrameWorker(setup.spec, engine=setup.engine)
    out = []
    for f in files:
        if f is None:
            out.append(np.zeros((0, 2)))
            continue
        depth = read_frame(cfg, f)
        res = worker.engine.infer(depth)
        _, dets = worker.detections(res)
        heads = worker.heads(dets, depth, res) or [None] * len(dets)  # (tracking.positions)
        out.append(np.array([h if h is not None else (d.x, d.y) for d, h in zip(dets, heads)]).reshape(-1, 2))
    return out


def procrustes(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The planar turn and shift (4x4) that lays the points `src` (n, 2) on `dst` in least squares."""
    a, b = src - src.mean(0), dst - dst.mean(0)
    yaw = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
    c, s = np.cos(yaw), np.sin(yaw)
    t = dst.mean(0) - src.mean(0) @ np.array([[c, s], [-s, c]])
    return planar(yaw, *t)


def _moved(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Floor points (n, 2) moved by the planar transform T (4x4: its turn and shift on the floor)."""
    return points @ T[:2, :2].T + T[:2, 3]


def _matches(T: np.ndarray, src: list, dst: list) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (src point, its nearest dst point of the same frame) closer than MATCH under T."""
    a, b = [], []
    for s_f, d_f in zip(src, dst):
        if not len(s_f) or not len(d_f):
            continue
        dist = np.linalg.norm(_moved(s_f, T)[:, None] - d_f[None], axis=-1)
        near = dist.argmin(1)
        ok = dist[np.arange(len(s_f)), near] < MATCH
        a.append(s_f[ok])
        b.append(d_f[near[ok]])
    return (np.concatenate(a), np.concatenate(b)) if a else (np.zeros((0, 2)), np.zeros((0, 2)))


def hypotheses(src: list, dst: list) -> tuple[np.ndarray, np.ndarray]:
    """Every two-point hypothesis (module doc), in the order: frame, the placed cameras' pair
    (i < j, at least SPAN apart), the camera's ordered pair (k != m, as far apart within MATCH):
    the turn (radians, (h,)) and shift ((h, 2)) laying s_k, s_m on d_i, d_j in least squares
    (procrustes of the two, in closed form: the turn between the pairs' vectors, the shift
    between their middles)."""
    yaws, shifts = [np.zeros(0)], [np.zeros((0, 2))]
    for f in range(len(src)):
        d, s_ = np.asarray(dst[f], float), np.asarray(src[f], float)
        if len(d) < 2 or len(s_) < 2:
            continue
        i, j = np.triu_indices(len(d), 1)
        dv = d[j] - d[i]
        span = np.linalg.norm(dv, axis=1)
        far = span >= SPAN
        i, j, dv, span = i[far], j[far], dv[far], span[far]
        k, m = np.nonzero(~np.eye(len(s_), dtype=bool))
        sv = s_[m] - s_[k]
        a, b = np.nonzero(np.abs(np.linalg.norm(sv, axis=1)[None, :] - span[:, None]) < MATCH)
        if not len(a):
            continue
        u, w = sv[b], dv[a]
        yaw = np.arctan2(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0], np.sum(u * w, axis=1))
        c, sn = np.cos(yaw), np.sin(yaw)
        mid_s, mid_d = (s_[k[b]] + s_[m[b]]) / 2, (d[i[a]] + d[j[a]]) / 2
        yaws.append(yaw)
        shifts.append(mid_d - np.stack([c * mid_s[:, 0] - sn * mid_s[:, 1], sn * mid_s[:, 0] + c * mid_s[:, 1]], 1))
    return np.concatenate(yaws), np.concatenate(shifts)


def most_voted(yaw: np.ndarray, shift: np.ndarray, limit: int = MAX_SCORED) -> np.ndarray:
    """Indices (in order) of at most `limit` hypotheses to score: those of the coarse bins
    (VOTE_BIN: a turn and a shift) that hold the most hypotheses, whole bins, most first. The
    right turn and shift is the one most pairs of pairs agree on: a crowd's hundreds of thousands of
    hypotheses (26 people: 740 000 in ten frames) need not all be scored, only those near it."""
    if len(yaw) <= limit:
        return np.arange(len(yaw))
    keys = np.stack([np.floor((yaw + np.pi) / np.deg2rad(VOTE_BIN[1])),
                     np.floor(shift[:, 0] / VOTE_BIN[0]), np.floor(shift[:, 1] / VOTE_BIN[0])], 1).astype(np.int64)
    bins, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    order = np.lexsort((np.arange(len(bins)), -counts))  # most voted first; ties by the bin
    taken = order[:max(1, int(np.searchsorted(np.cumsum(counts[order]), limit, side="right")))]
    chosen = np.flatnonzero(np.isin(inverse.ravel(), taken))
    return chosen[np.linspace(0, len(chosen) - 1, min(limit, len(chosen))).astype(np.int64)]


def match_people(src: list, dst: list) -> tuple[np.ndarray | None, int, float]:
    """The planar turn and shift laying the camera's people `src` (its floor frame, (n, 2) a
    frame) on those of the cameras placed `dst` (the world), the number matched and their RMS
    distance (module doc: the two-point hypotheses most agreed on, the most matches, then least
    squares)."""
    yaw, shift = hypotheses(src, dst)
    if not len(yaw):
        return None, 0, float("nan")
    hyps = [planar(yaw[h], *shift[h]) for h in most_voted(yaw, shift)]
    flat = [(f, p) for f in range(len(src)) for p in src[f]]  # (not empty: a hypothesis took two of them)
    pts = np.array([p for _, p in flat])
    at = np.array([f for f, _ in flat])
    width = max(len(d) for d in dst) or 1
    padded = np.full((len(dst), width, 2), np.inf)
    for f, d in enumerate(dst):
        padded[f, :len(d)] = d
    best, count = None, -1
    for start in range(0, len(hyps), 1024):  # each hypothesis's matches, 1024 at a time
        H = np.stack(hyps[start:start + 1024])
        moved = np.einsum("hij,nj->hni", H[:, :2, :2], pts) + H[:, None, :2, 3]
        dist = np.linalg.norm(moved[:, :, None] - padded[at][None], axis=-1).min(-1)
        counts = (dist < MATCH).sum(1)
        k = int(np.argmax(counts))
        if counts[k] > count:
            best, count = H[k], int(counts[k])
    T = best
    for _ in range(5):  # least squares on the matches, matched again
        a, b = _matches(T, src, dst)
        if len(a) < 2:
            break
        T = procrustes(a, b)
    return _matched(T, src, dst)


def scene_points(m: RunConfig, T: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """The static scene's points above the floor (ABOVE_FLOOR), in the frame T puts the camera in."""
    import dataclasses

    camera = dataclasses.replace(m.camera, T_world_from_camera=T)
    ok = (depth > 0) & (depth <= m.model.z_max)
    pts = camera.centre + depth[ok][:, None].astype(np.float64) * camera.rays()[ok]
    return pts[(pts[:, 2] >= ABOVE_FLOOR[0]) & (pts[:, 2] <= ABOVE_FLOOR[1])]


def planar(yaw: float, x: float, y: float) -> np.ndarray:
    """The 4x4 turn by `yaw` radians about z followed by a shift (x, y) on the floor."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x, y
    return T


def top_view(xy: np.ndarray, origin: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Occupancy of the floor cells (CELL) under `xy`, a grid of `shape` from `origin`, spread to
    the cells beside (a wall seen from two places is read a few centimetres apart)."""
    from scipy.ndimage import binary_dilation

    img = np.zeros(shape, bool)
    ij = np.floor((xy - origin) / CELL).astype(int)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[0])
    img[ij[ok, 1], ij[ok, 0]] = True
    return binary_dilation(img, np.ones((3, 3), bool)).astype(np.float64)


def coarse_turn_and_shift(source: np.ndarray, target: np.ndarray) -> tuple[tuple[float, float, float], bool]:
    """(yaw, x, y) that lays most of `source`'s top view on `target`'s: every whole degree of
    turn about the origin, for each every shift at once (the views' cross-correlation by FFT,
    padded so that shifts do not wrap); and whether a turn farther than 10 degrees, or a
    shift farther than 0.5 m, lays at least ALIKE as much (the scene is ambiguous)."""
    lo = np.minimum(source[:, :2].min(0), target[:, :2].min(0)) - 1.0
    hi = np.maximum(np.abs(source[:, :2]).max(0), np.abs(target[:, :2]).max(0))
    size = int(np.ceil(2 * max(np.max(hi - lo), np.max(np.abs(lo))) / CELL)) + 8
    shape = (size, size)
    origin = np.array([-size * CELL / 2, -size * CELL / 2])
    T_img = np.fft.rfft2(top_view(target[:, :2], origin, shape), s=(2 * size, 2 * size))
    found = []  # each degree's best (score, yaw, x, y)
    for deg in range(360):
        yaw = np.deg2rad(deg)
        c, s = np.cos(yaw), np.sin(yaw)
        turned = source[:, :2] @ np.array([[c, s], [-s, c]])
        S_img = np.fft.rfft2(top_view(turned, origin, shape), s=(2 * size, 2 * size))
        corr = np.fft.irfft2(T_img * np.conj(S_img), s=(2 * size, 2 * size))
        k = int(np.argmax(corr))
        di, dj = np.unravel_index(k, corr.shape)
        di, dj = (di if di < size else di - 2 * size), (dj if dj < size else dj - 2 * size)
        found.append((float(corr.flat[k]), yaw, dj * CELL, di * CELL))
    best = max(found, key=lambda f: f[0])
    others = [f for f in found if _turn_deg(planar(f[1], 0, 0), planar(best[1], 0, 0)) > 10
              or np.hypot(f[2] - best[2], f[3] - best[3]) > 0.5]
    alike = bool(others) and max(f[0] for f in others) >= ALIKE * best[0]
    return best[1:], alike


def _clouds(source: np.ndarray, target: np.ndarray):
    """The two point sets as Open3D clouds, thinned to NEAR / 2."""
    import open3d as o3d

    return (o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p)).voxel_down_sample(NEAR / 2)
            for p in (source, target))


def _turn_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Degrees between the turns about z of two planar poses (4x4), 0 to 180."""
    d = abs(np.rad2deg(np.arctan2(a[1, 0], a[0, 0]) - np.arctan2(b[1, 0], b[0, 0]))) % 360
    return min(d, 360 - d)


def _icp(T: np.ndarray, source: np.ndarray, target: np.ndarray, distances=(0.2, 0.1, NEAR)) -> np.ndarray:
    """Open3D's point-to-plane ICP from T, coarse to fine, each result kept to a turn and a shift."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src, tgt = _clouds(source, target)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.2, max_nn=30))
    for distance in distances:
        R = reg.registration_icp(src, tgt, distance, T, reg.TransformationEstimationPointToPlane(),
                                 reg.ICPConvergenceCriteria(max_iteration=50)).transformation
        T = planar(np.arctan2(R[1, 0], R[0, 0]), R[0, 3], R[1, 3])
    return T


def scene_fit(T: np.ndarray, source: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(residual: RMS distance of the source's points within NEAR of the target's, overlap: their
    share) under T (Open3D's evaluate_registration)."""
    import open3d as o3d

    if not len(source) or not len(target):
        return 0.0, 0.0
    src, tgt = _clouds(source, target)
    check = o3d.pipelines.registration.evaluate_registration(src, tgt, NEAR, T)
    return float(check.inlier_rmse), float(check.fitness)


def refine_on_scene(T: np.ndarray, source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float, float]:
    """T (from the people) refined by ICP on the static scenes, where that moves it less than
    REFINE_MOVE and lays more of the scene within NEAR; else T. Returns the pose kept and its
    scene_fit."""
    fit = scene_fit(T, source, target)
    if len(source) < 100 or len(target) < 100:
        return (T, *fit)
    refined = _icp(T, source, target, (MATCH / 2, NEAR))
    if np.linalg.norm(refined[:2, 3] - T[:2, 3]) < REFINE_MOVE[0] and _turn_deg(refined, T) < REFINE_MOVE[1]:
        better = scene_fit(refined, source, target)
        if better[1] >= fit[1]:
            return (refined, *better)
    return (T, *fit)


def register(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, bool]:
    """The scene alone: the turn and shift (4x4, planar) that lay `source` on `target`, their
    footprints correlated, then ICP; and whether another turn and shift, farther than 0.5 m or
    10 degrees, lays at least ALIKE as much of it (the scene cannot tell them apart)."""
    (yaw, x, y), alike = coarse_turn_and_shift(source, target)
    return _icp(planar(yaw, x, y), source, target), alike


@dataclass
class _View:
    """What a camera alone gives calibration: its config, static scene (metres), pose in its own
    floor frame and the people it finds in each chosen rig frame (that floor frame, (n, 2) each)."""

    name: str
    m: RunConfig
    depth: np.ndarray
    own: np.ndarray
    seen: list


def _flat(seen: list) -> tuple[np.ndarray, np.ndarray]:
    """A camera's detections of every frame (`seen`: (n, 2) a frame) as one (N, 2) array, and
    the frame of each (N,)."""
    pts = [np.reshape(p, (-1, 2)) for p in seen]
    return (np.concatenate(pts or [np.zeros((0, 2))]),
            np.concatenate([np.full(len(p), f) for f, p in enumerate(pts)] or [np.zeros(0, int)]))


def _in_world(seen: list, W: np.ndarray) -> list[np.ndarray]:
    """A camera's detections a frame (its floor frame) moved into the world by the planar W."""
    return [_moved(p, W) for p in seen]


def _pair_matches(world: list) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(a, b, i, j) for every two cameras a < b: the indices i of a's points (flattened over
    frames, `world[c]` = (points (n, 2), frame of each (n,))) and j of b's whose nearest point
    of b in the same frame is closer than MATCH."""
    out = []
    for a in range(len(world)):
        for b in range(a + 1, len(world)):
            (pa, fa), (pb, fb) = world[a], world[b]
            if not len(pa) or not len(pb):
                continue
            d = np.linalg.norm(pa[:, None] - pb[None], axis=-1)
            d[fa[:, None] != fb[None]] = np.inf
            j = d.argmin(1)
            i = np.flatnonzero(d[np.arange(len(pa)), j] < MATCH)
            if len(i):
                out.append((a, b, i, j[i]))
    return out


def joint_people(seen: list, W: list, free: list, rounds: int = 5) -> list[np.ndarray]:
    """The planar poses `W` (each camera's floor frame into the world, 4x4) of the cameras
    `free` refined together on the people every two cameras find in the same frames (`seen[c]`:
    camera c's detections a frame, in its floor frame): each round matches every pair's
    detections under the current poses (nearest within MATCH), then solves for the free
    cameras' turns and shifts at once, in least squares with a soft L1 loss at NEAR (a
    detection's noise: a wrong match weighs little), to tolerances far under a millimetre (the
    few unknowns make that cheap). The others stay as they are."""
    from scipy.optimize import least_squares

    idx = [c for c in range(len(W)) if free[c]]
    if not idx:
        return list(W)
    pts, frame = zip(*(_flat(s) for s in seen))

    def poses(x):
        P = list(W)
        for n, c in enumerate(idx):
            P[c] = planar(*x[3 * n:3 * n + 3])
        return P

    def world(P):
        return [_moved(pts[c], P[c]) for c in range(len(P))]

    x = np.concatenate([[np.arctan2(W[c][1, 0], W[c][0, 0]), W[c][0, 3], W[c][1, 3]] for c in idx])
    for _ in range(rounds):
        pairs = _pair_matches([(w, f) for w, f in zip(world(poses(x)), frame)])
        if not pairs:
            break

        def residuals(x, pairs=pairs):
            w = world(poses(x))
            return np.concatenate([(w[a][i] - w[b][j]).ravel() for a, b, i, j in pairs])

        x = least_squares(residuals, x, loss="soft_l1", f_scale=NEAR, xtol=1e-12, ftol=1e-12, gtol=1e-12).x
    return poses(x)


def _first_guess(views: list, W: list, c: int, where: str, frames: int, log) -> tuple[np.ndarray, bool]:
    """Camera c's floor frame into the world, placed against the cameras before it (module
    doc): by the people where at least MIN_MATCHES are matched (True), else by the static scene
    alone (False); a one-line InputError where neither holds."""
    v = views[c]
    before = [_in_world(views[q].seen, W[q]) for q in range(c)]
    dst = [np.concatenate([p[f] for p in before]) for f in range(frames)]
    T, matched, rms = match_people(v.seen, dst)
    log(f"camera {v.name}: {matched} people matched with the cameras before it in {frames} frames"
        + (f" (rms {1000 * rms:.0f} mm)" if matched else ""))
    if matched >= MIN_MATCHES:
        return T, True
    source = scene_points(v.m, v.own, v.depth)
    target = np.concatenate([scene_points(views[q].m, W[q] @ views[q].own, views[q].depth) for q in range(c)])
    T, alike = register(source, target) if len(source) >= 100 and len(target) >= 100 else (None, True)
    overlap = scene_fit(T, source, target)[1] if T is not None else 0.0
    if alike or overlap < MIN_OVERLAP:
        scene = ("fits several places alike (walls that look the same from each)" if alike and T is not None
                 else f"has {100 * overlap:.0f} % of its points within {NEAR:g} m of theirs (expected at least "
                      f"{100 * MIN_OVERLAP:.0f} %)")
        raise InputError(f"{where}: calibrate: shares too little with the cameras before it: {matched} people "
                         f"matched across cameras (expected at least {MIN_MATCHES}), and its static scene "
                         f"alone {scene}; record people walking where both see, or give "
                         f"cameras[{c}].camera.extrinsics")
    return T, False


def place_cameras(cfg: RunConfig, device: str | None = None, log=print) -> list[Placed]:
    """Every camera of the rig placed in one world (module doc); a one-line InputError naming a
    camera that shares too little with those placed before it."""
    from .frames import rig_frames

    rig = rig_frames(cfg, log=lambda *_: None)
    chosen = rig.frames
    if len(chosen) > PEOPLE_FRAMES:
        chosen = [chosen[i] for i in np.unique(np.linspace(0, len(chosen) - 1, PEOPLE_FRAMES).astype(int))]
    views, W, by_people = [], [], []
    for c, (name, m) in enumerate(cfg.cameras):
        where = f"cameras[{c}] ({name})"
        depth, what = static_frame(m, log)
        fit = floor_frame(m, depth, f"{where}: {what}")
        views.append(_View(name, m, depth, fit.T_world_from_camera,
                           people_seen(m, fit, [f.paths[c] for f in chosen], device, log)))
        if c == 0:
            T = fit.T_world_from_camera if m.pose_auto else m.camera.T_world_from_camera
            W.append(T @ np.linalg.inv(fit.T_world_from_camera))  # the floor frame into the world: a turn and a shift
            by_people.append(False)
            continue
        guess, people = _first_guess(views, W, c, where, len(chosen), log)
        W.append(guess)
        by_people.append(people)
    W = joint_people([v.seen for v in views], W, by_people)
    if any(by_people):
        log(f"cameras {', '.join(v.name for v, free in zip(views, by_people) if free)} refined together on the "
            f"people every two cameras see: {_pairs_fit(views, W)}")
    placed = []
    for c, v in enumerate(views):
        if c == 0:
            placed.append(Placed(v.name, W[0] @ v.own, scene_points(v.m, W[0] @ v.own, v.depth)))
            continue
        source = scene_points(v.m, v.own, v.depth)
        target = np.concatenate([p.points for p in placed])
        if by_people[c]:
            W[c], residual, overlap = refine_on_scene(W[c], source, target)
        else:
            residual, overlap = scene_fit(W[c], source, target)
        others = [_in_world(views[q].seen, W[q]) for q in range(len(views)) if q != c]
        _, matched, rms = _matched(W[c], v.seen, [np.concatenate([o[f] for o in others]) for f in range(len(chosen))])
        T = W[c] @ v.own
        placed.append(Placed(v.name, T, scene_points(v.m, T, v.depth), residual, overlap, matched, rms))
    return placed


def _pairs_fit(views: list, W: list) -> str:
    """How well every two cameras' people meet under the poses W: the matches and their RMS."""
    world = [(_moved(pts, T), frame) for (pts, frame), T in zip((_flat(v.seen) for v in views), W)]
    d = [np.linalg.norm(world[a][0][i] - world[b][0][j], axis=1) for a, b, i, j in _pair_matches(world)]
    d = np.concatenate(d) if d else np.zeros(0)
    return f"{len(d)} matches" + (f", rms {1000 * np.sqrt(np.mean(d ** 2)):.0f} mm" if len(d) else "")


def _matched(T: np.ndarray, src: list, dst: list) -> tuple[np.ndarray, int, float]:
    """T, the number of `src` points (a frame each) within MATCH of a `dst` point of the same
    frame under T, and their RMS distance."""
    a, b = _matches(T, src, dst)
    rms = float(np.sqrt(np.mean(np.sum((_moved(a, T) - b) ** 2, axis=1)))) if len(a) else float("nan")
    return T, len(a), rms


def calibrated_mapping(config_path: str | Path, placed: list[Placed], output: str | Path,
                       overrides: list[str] | None = None) -> dict:
    """The config file's mapping (`overrides` applied) with every camera's extrinsics the placed
    pose, its relative paths made relative to the output's folder (the written file runs as it is)."""
    from .config import apply_overrides

    raw = apply_overrides(read_config(config_path), overrides or [])  # paths relative to the current folder
    out = copy.deepcopy(raw)
    for item, p in zip(out["cameras"], placed):
        cam = item["camera"] = item.get("camera") or {}  # (read_config made `camera: FILE` {file: FILE})
        cam["extrinsics"] = {"T_world_from_camera": [[round(float(v), 9) for v in row] for row in p.T_world_from_camera]}
    here = os.path.relpath(".", Path(output).resolve().parent)
    return resolve_paths(out, here)


def calibrate(config_path: str | Path, output: str | Path, overrides: list[str] | None = None, log=print,
              device: str | None = None) -> list[dict]:
    """Place the rig's cameras and write the config with their poses to `output`; returns each
    camera's report (its pose, residual and overlap), also printed."""
    import yaml

    from .loading import load_config

    cfg = load_config(config_path, overrides)
    if not cfg.is_rig:
        raise ConfigError(f"{config_path}: calibrate places a rig's cameras; expected a cameras: list, found a "
                          f"single camera (its floor fit is dpom-warp fit-ground)")
    placed = place_cameras(cfg, device, log)
    reports = [p.report() for p in placed]
    for r in reports:
        rms = f" (rms {1000 * r['people_rms_m']:.0f} mm)" if r["people_rms_m"] is not None else ""
        fit = "" if r["residual_m"] is None else (f"; {r['people_matched']} people matched with the other cameras'{rms}, "
                                                   f"static scene residual {1000 * r['residual_m']:.1f} mm over "
                                                   f"{100 * r['overlap']:.0f} % of it")
        log(f"camera {r['camera']}: {r['height_m']:.3f} m up, pitch {r['pitch_deg']:.2f} deg, roll {r['roll_deg']:.2f} "
            f"deg, yaw {r['yaw_deg']:.2f} deg, at x {r['x_m']:.3f} m, y {r['y_m']:.3f} m{fit}")
    mapping = calibrated_mapping(config_path, placed, output, overrides)
    text = (f"# written by dpom-warp calibrate from {config_path}: every camera's extrinsics placed in one world\n"
            + yaml.safe_dump(mapping, sort_keys=False, default_flow_style=None))
    write_text_atomic(Path(output), text)
    log(f"calibrated config written to {output}")
    return reports

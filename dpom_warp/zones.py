"""Where people go (issue 62): counts in zones, crossings of lines and dwell times, from the tracks.

Zones are polygons and lines are segments on the floor, in world metres (the config's `zones:`
and `lines:`). `Zones.update(frame_index, tracks)` takes one frame's committed tracks (their
identity and position, a person the tracker holds through a short occlusion included) and
returns that frame's counts and crossings; the recorded run, the live run, `dpom-warp track` and
the Python API's online tracker loop all feed it the same way.

- A track is in a zone when its position is inside the polygon or on its edge.
- A track crosses a line when its step from one frame to the next passes through the segment
  (not the line beyond its ends): `in` when it goes from the right of from->to to its left, `out`
  the other way, reported at the first frame on the new side. A track that jitters on the line
  is counted once: the side it is on changes only once it is more than `hysteresis` metres from
  the line (the step that crossed is remembered until then, and forgotten if it comes back).
- A stay in a zone runs from the first frame a track is inside to the last (`dwell`): its
  seconds are from the time of its first frame to the time of the frame after its last
  (the recording's timestamps where it has them, else frame / fps), at the run's end to the
  last frame's time plus a frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Zone:
    name: str
    polygon: np.ndarray  # (n, 2) metres


@dataclass(frozen=True)
class Line:
    name: str
    start: np.ndarray  # (2,) metres: `from`
    end: np.ndarray  # (2,) `to`


EDGE = 1e-9  # metres: a point this close to a polygon's edge is on it


def on_segment(points: np.ndarray, a: np.ndarray, b: np.ndarray, tol: float = EDGE) -> np.ndarray:
    """(n,) whether each point lies on the segment a-b (within `tol` metres)."""
    d = b - a
    t = np.clip(((points - a) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * d), axis=1) <= tol


def inside(polygon: np.ndarray, points) -> np.ndarray:
    """(n,) whether each point (n, 2) is inside the polygon or on its edge: matplotlib's Path
    (even-odd rule) plus the edges themselves. Regions does the same for many zones at once."""
    from matplotlib.path import Path

    points = np.asarray(points, float).reshape(-1, 2)
    if not len(points):
        return np.zeros(0, bool)
    hit = Path(polygon).contains_points(points)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        hit |= on_segment(points, a, b)
    return hit


class Regions:
    """Many polygons made ready to test points against all at once (the bookkeeping's cost a
    frame: a few array operations whatever the number of zones): every edge of every polygon
    in one array, each point's crossings of the edges to its right counted per polygon (odd:
    inside, the even-odd rule) and its distance to each edge (on one: inside)."""

    def __init__(self, polygons: list[np.ndarray]):
        polys = [np.asarray(p, float) for p in polygons]
        self.n = len(polys)
        self.a = np.concatenate(polys) if polys else np.zeros((0, 2))
        self.d = (np.concatenate([np.roll(p, -1, axis=0) - p for p in polys]) if polys else np.zeros((0, 2)))
        self.dd = np.maximum(np.einsum("ij,ij->i", self.d, self.d), 1e-300)
        self.start = np.cumsum([0] + [len(p) for p in polys])[:-1]  # each polygon's first edge

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(polygons, n) whether each point (n, 2) is inside each polygon or on its edge."""
        if not len(points) or not self.n:
            return np.zeros((self.n, len(points)), bool)
        px, py = points[:, 0, None], points[:, 1, None]  # (n, 1) against (edges,)
        ax, ay, dx, dy = self.a[:, 0], self.a[:, 1], self.d[:, 0], self.d[:, 1]
        spans = (ay > py) != (ay + dy > py)  # the edge spans the point's height
        with np.errstate(divide="ignore", invalid="ignore"):
            right = px < ax + (py - ay) * dx / dy  # where it meets that height lies to the point's right
        crossings = np.add.reduceat((spans & right).astype(np.int64), self.start, axis=1)
        rx, ry = px - ax, py - ay
        t = np.clip((rx * dx + ry * dy) / self.dd, 0.0, 1.0)
        near = ((rx - t * dx) ** 2 + (ry - t * dy) ** 2 <= EDGE * EDGE).astype(np.int64)
        on_edge = np.add.reduceat(near, self.start, axis=1) > 0
        return ((crossings % 2 == 1) | on_edge).T


def side(line: Line, points) -> np.ndarray:
    """(n,) signed distance of each point from the line through from->to: > 0 on its left."""
    d = line.end - line.start
    return sides(line.start[None], d[None], np.array([np.linalg.norm(d)]), points)[0]


def sides(starts: np.ndarray, dirs: np.ndarray, lengths: np.ndarray, points) -> np.ndarray:
    """(lines, n) signed distances of each point from each line (its start, to - from and its
    length: (lines, 2), (lines, 2), (lines,)), as side() gives them one line at a time."""
    p = np.asarray(points, float).reshape(-1, 2)[None, :, :] - starts[:, None, :]
    d = dirs[:, None, :]
    return (d[..., 0] * p[..., 1] - d[..., 1] * p[..., 0]) / lengths[:, None]


def steps_through(line: Line, p: np.ndarray, q: np.ndarray) -> bool:
    """Whether the step p->q meets the segment from->to (ends included)."""
    a, b = line.start, line.end
    r, s = q - p, b - a
    den = r[0] * s[1] - r[1] * s[0]
    if abs(den) < 1e-12:  # parallel: it meets only by touching an end
        return bool(on_segment(np.array([p, q]), a, b).any() or on_segment(np.array([a, b]), p, q).any())
    ap = a - p
    t = (ap[0] * s[1] - ap[1] * s[0]) / den
    u = (ap[0] * r[1] - ap[1] * r[0]) / den
    return -1e-12 <= t <= 1 + 1e-12 and -1e-12 <= u <= 1 + 1e-12


def segments_cross(a, b, c, d) -> bool:
    """Whether the closed segments a-b and c-d share a point."""
    return steps_through(Line("", np.asarray(c, float), np.asarray(d, float)), np.asarray(a, float),
                         np.asarray(b, float))


def self_crossing(polygon: np.ndarray) -> tuple[int, int] | None:
    """The first two edges of a polygon that are not neighbours and share a point, else None."""
    n = len(polygon)
    edges = [(polygon[i], polygon[(i + 1) % n]) for i in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            if segments_cross(*edges[i], *edges[j]):
                return i, j
    return None


def meets_rectangle(points: np.ndarray, rect, closed: bool) -> bool:
    """Whether a polygon (`closed`) or a segment (its two points) has a point in the rectangle
    (x0, x1, y0, y1)."""
    x0, x1, y0, y1 = rect
    pts = np.asarray(points, float)
    if np.any((pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)):
        return True
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    if closed and inside(pts, corners).any():
        return True
    edges = list(zip(pts, np.roll(pts, -1, axis=0))) if closed else [(pts[0], pts[1])]
    return any(segments_cross(a, b, c, d) for a, b in edges for c, d in zip(corners, np.roll(corners, -1, axis=0)))


@dataclass
class Crossing:
    frame: int  # the first frame on the new side
    line: str
    track: int
    direction: str  # in: right of from->to to its left; out: the other way


@dataclass
class Stay:
    track: int
    zone: str
    enter_frame: int
    exit_frame: int
    seconds: float


@dataclass
class FrameEvents:
    """One frame's counts ({zone: tracks inside}) and the crossings confirmed at it (each dated
    by its first frame on the new side, which may be earlier under the hysteresis)."""

    frame: int
    counts: dict
    crossings: list


@dataclass
class _LineState:
    confirmed: int = 0  # the side the track is on, beyond the hysteresis (0: not yet known)
    pending: tuple | None = None  # (first frame on the other side, whether that step passed the segment)


@dataclass
class Zones:
    """The zones and lines of a run, and their bookkeeping over the frames fed to `update`."""

    zones: list[Zone]
    lines: list[Line]
    hysteresis: float = 0.05
    fps: float = 15.0
    stays: list[Stay] = field(default_factory=list)  # closed stays, in the order they closed
    _last: dict = field(default_factory=dict)  # track -> (frame, xy) last seen
    _lines: dict = field(default_factory=dict)  # (track, line) -> _LineState
    _open: dict = field(default_factory=dict)  # (track, zone) -> enter frame
    _times: dict = field(default_factory=dict)  # frame -> seconds
    _frame: int | None = None
    _regions: Regions | None = None

    def __post_init__(self):
        self._regions = Regions([z.polygon for z in self.zones])
        # every line's start, direction and length: sides() of all lines at once, side()'s
        # operations (the same bits: a track on a cell centre sits exactly at some hysteresis
        # from a line on a cell edge)
        self._starts = np.array([x.start for x in self.lines], float).reshape(-1, 2)
        self._dirs = np.array([x.end - x.start for x in self.lines], float).reshape(-1, 2)
        self._lengths = np.array([np.linalg.norm(x.end - x.start) for x in self.lines], float)

    @classmethod
    def from_config(cls, cfg) -> "Zones":
        """From a run config's zones, lines, counting.hysteresis and input.fps."""
        zones = [Zone(z.name, np.asarray(z.polygon, float)) for z in cfg.zones]
        lines = [Line(x.name, np.asarray(x.start, float), np.asarray(x.end, float)) for x in cfg.lines]
        return cls(zones, lines, cfg.counting.hysteresis, cfg.inputs.fps)

    def time(self, frame: int) -> float:
        return self._times.get(frame, frame / self.fps)

    def update(self, frame: int, tracks, timestamp: float | None = None) -> FrameEvents:
        """One frame's committed tracks, [(id, xyz, bridged)] or dicts with id and xyz, frames
        in increasing order; returns the frame's counts and the crossings confirmed now."""
        if self._frame is not None and frame <= self._frame:
            raise ValueError(f"zones: frames must come in increasing order; found {frame} after {self._frame}")
        self._frame = frame
        if timestamp is not None:
            self._times[frame] = float(timestamp)
        rows = [(int(t["id"]), t["xyz"]) if isinstance(t, dict) else (int(t[0]), t[1]) for t in tracks]
        ids = [tid for tid, _ in rows]
        xy = np.array([np.asarray(p, float)[:2] for _, p in rows]).reshape(-1, 2)
        counts, now_in = {}, set()
        hits = self._regions.inside(xy)
        for z, hit, count in zip(self.zones, hits.tolist(), hits.sum(axis=1).tolist()):
            counts[z.name] = count
            for tid in (t for t, h in zip(ids, hit) if h):
                now_in.add((tid, z.name))
                self._open.setdefault((tid, z.name), frame)
        for key in [k for k in self._open if k not in now_in]:  # left the zone, or the track ended
            self._close(key, frame)
        crossings = []
        dists = sides(self._starts, self._dirs, self._lengths, xy).tolist()  # side() of every line at once
        for line, row in zip(self.lines, dists):
            for tid, p, dist in zip(ids, xy, row):
                state = self._lines.get((tid, line.name))
                if state is not None and state.pending is None and state.confirmed == (dist > 0) - (dist < 0):
                    continue  # on its side, nothing pending: nothing can change (most pairs, most frames)
                crossing = self._step(line, tid, p, dist, frame)
                if crossing is not None:
                    crossings.append(crossing)
        self._last = {tid: (frame, p) for tid, p in zip(ids, xy)}
        return FrameEvents(frame, counts, crossings)

    def _step(self, line: Line, tid: int, p: np.ndarray, dist: float, frame: int) -> Crossing | None:
        state = self._lines.setdefault((tid, line.name), _LineState())
        sign = 1 if dist > 0 else -1 if dist < 0 else 0
        beyond = abs(dist) > self.hysteresis
        if state.confirmed == 0:
            if beyond:
                state.confirmed = sign
            return None
        if sign == state.confirmed or sign == 0 and state.pending is None:
            state.pending = None  # back on its side (or on the line, not over it yet)
            return None
        if state.pending is None:  # the first frame on the other side: did the step pass the segment?
            last = self._last.get(tid)
            state.pending = (frame, last is not None and steps_through(line, last[1], p))
        if beyond:
            first, through = state.pending
            state.confirmed, state.pending = sign, None
            if through:
                return Crossing(first, line.name, tid, "in" if sign > 0 else "out")
        return None

    def _close(self, key, frame: int) -> None:
        """A stay that ended: its track is not inside at `frame`."""
        enter = self._open.pop(key)
        self.stays.append(Stay(key[0], key[1], enter, frame - 1, self.time(frame) - self.time(enter)))

    def finish(self) -> list[Stay]:
        """The stays still open closed at the last frame (to its time plus a frame); every stay."""
        last = self._frame
        for key in list(self._open):
            enter = self._open.pop(key)
            self.stays.append(Stay(key[0], key[1], enter, last, self.time(last) + 1.0 / self.fps - self.time(enter)))
        return self.stays

"""Tracks as data: a `Track` (its frames and positions), tracks.csv and track_table.csv written
and read, and the tracks present at each frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TRACKS_HEADER = "frame,track,x,y,z,rho,bridged"


TABLE_HEADER = "track,first_frame,last_frame,frames,bridged,path_m,mean_speed_mps"


@dataclass
class Track:
    """One identity: per frame index t, the position (x, y, z), rho* there and whether the
    tracker bridged the frame (no map peak: hidden or missed)."""

    id: int
    frames: list[int]
    xyz: np.ndarray
    rho: np.ndarray
    bridged: np.ndarray


# -- outputs ---------------------------------------------------------------------------------
def tracks_csv(tracks: list[Track], names: list[str]) -> str:
    """tracks.csv: one row per track per frame, frame order then identity."""
    rows = []
    for tr in tracks:
        for t, p, r, b in zip(tr.frames, tr.xyz, tr.rho, tr.bridged):
            rows.append((t, tr.id, f"{names[t]},{tr.id},{p[0]:.4f},{p[1]:.4f},{p[2]:.4f},{r:.6f},{int(b)}"))
    rows.sort(key=lambda r: (r[0], r[1]))
    return "\n".join([TRACKS_HEADER] + [r[2] for r in rows]) + "\n"


def track_table(tracks: list[Track], names: list[str], fps: float, times: list | None = None) -> str:
    """track_table.csv: per track its first and last frame, frames, bridged frames, path
    length (metres, on the ground plane; in 3D for voxel grids) and mean speed (m/s), over
    the camera frames from its first to its last (`times`, the frames' timestamps, count the
    frames without a map between; frame_steps)."""
    steps = frame_steps(times, 1.0 / fps)
    at = np.arange(len(names), dtype=np.float64) if steps is None else steps
    lines = [TABLE_HEADER]
    for tr in tracks:
        path = float(np.sum(np.linalg.norm(np.diff(tr.xyz, axis=0), axis=1))) if len(tr.xyz) > 1 else 0.0
        span = (at[tr.frames[-1]] - at[tr.frames[0]]) / fps
        speed = path / span if span > 0 else 0.0
        lines.append(f"{tr.id},{names[tr.frames[0]]},{names[tr.frames[-1]]},{len(tr.frames)},"
                     f"{int(tr.bridged.sum())},{path:.3f},{speed:.3f}")
    return "\n".join(lines) + "\n"


def read_tracks_csv(path) -> dict[str, list[tuple]]:
    """frame name -> [(track, x, y, z, rho, bridged)] from a tracks.csv."""
    from pathlib import Path

    out: dict[str, list[tuple]] = {}
    lines = Path(path).read_text().splitlines()
    if not lines or not lines[0].startswith("frame,track,x,y,z,rho"):
        from .io import InputError

        raise InputError(f"{path}: expected a header beginning frame,track,x,y,z,rho, found "
                         f"{lines[0] if lines else 'an empty file'!r}")
    for line in lines[1:]:
        f = line.split(",")
        out.setdefault(f[0], []).append((int(f[1]), float(f[2]), float(f[3]), float(f[4]),
                                         float(f[5]), len(f) > 6 and f[6] == "1"))
    return out


def per_frame(tracks: list[Track], frames: int) -> list[list[tuple]]:
    """For each frame index, the (id, xyz, bridged) of the tracks present."""
    out = [[] for _ in range(frames)]
    for tr in tracks:
        for t, p, b in zip(tr.frames, tr.xyz, tr.bridged):
            out[t].append((tr.id, p, bool(b)))
    return out


def frame_steps(times: list | None, dt: float) -> np.ndarray | None:
    """Maps' times (seconds, a camera's timestamps) as solve_window's steps: each map's time
    from the first in whole camera frames of dt (rounded: the clock's jitter is not motion),
    so that frames dropped or skipped between two maps count. None unless every map has a
    finite time and the steps rise (a clock that jumps back or repeats, or frames closer
    than the rate allows, say nothing of the time between frames)."""
    if not times or any(t is None for t in times):
        return None
    t = np.asarray(times, np.float64)
    if not np.all(np.isfinite(t)):
        return None
    steps = np.round((t - t[0]) / dt)
    return steps if np.all(np.diff(steps) > 0) else None

"""What a frame reads where a detection stands: the connected pieces of readings around it.

A detection supported by a few fragments (a hidden person's head between the people in front,
or a piece of furniture) is easier to judge from what those fragments are than from its rho*.
For each detection of one frame (or each --at location), the readings whose world point lies
within --radius metres of its place on the floor, above input.structure.floor_gap and below
object.height + 0.3 m, joined into 8-connected pieces of the full-resolution image: each
piece's pixels, median depth, world x span and y (its 2nd to 98th percentiles, the median)
and height span, where its outline is its own top (what stands behind shows above it) and how
high that top is, and the share of the detection's box the pieces fill.

    python -m bench.support CONFIG [--set key=value ...] [--frame N] [--radius 0.4]
                            [--at X,Y ...] [--min-pixels 40]

CONFIG: a run config (its floor fit, static planes and model as a run has them; the README's
recipe on the real five-people frame is how docs/results.md's figures were made).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def world_points(depth_m: np.ndarray, camera) -> np.ndarray:
    """(H, W, 3) world point of each pixel's reading (NaN where none)."""
    z = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, np.nan)
    return camera.rays() * z[..., None] + camera.centre


def pieces(depth_m: np.ndarray, camera, at, radius: float, z_range, min_pixels: int = 40) -> list[dict]:
    """The connected pieces (8-connected, `min_pixels` or more) of the readings whose world
    point is within `radius` of `at` = (x, y) on the floor and between `z_range` = (lo, hi)
    high, largest first: {"pixels", "u", "v" (spans), "depth" (median), "x" (2nd, 98th
    percentile), "y" (median), "z" (2nd, 98th percentile), "top" (free_top)}."""
    from scipy import ndimage

    p = world_points(depth_m, camera)
    with np.errstate(invalid="ignore"):
        near = ((np.hypot(p[..., 0] - at[0], p[..., 1] - at[1]) <= radius)
                & (p[..., 2] >= z_range[0]) & (p[..., 2] <= z_range[1]))
    label, n = ndimage.label(near, structure=np.ones((3, 3)))
    out = []
    for k in range(1, n + 1):
        v, u = np.nonzero(label == k)
        if len(v) < min_pixels:
            continue
        q = p[v, u]
        out.append({"pixels": int(len(v)), "u": (int(u.min()), int(u.max())), "v": (int(v.min()), int(v.max())),
                    "depth": float(np.median(depth_m[v, u])),
                    "x": tuple(float(t) for t in np.percentile(q[:, 0], [2, 98])), "y": float(np.median(q[:, 1])),
                    "z": tuple(float(t) for t in np.percentile(q[:, 2], [2, 98])),
                    "top": free_top(depth_m, p, v, u)})
    return sorted(out, key=lambda c: -c["pixels"])


TOP_LOOK = 30  # rows looked up above a piece's top pixel for the next reading
TOP_GAP = 0.3  # metres: that reading this much farther makes the top pixel a free top


def free_top(depth_m: np.ndarray, p: np.ndarray, v: np.ndarray, u: np.ndarray) -> dict | None:
    """Where a piece's outline is its own top: in each column, its topmost pixel whose next
    reading above (within TOP_LOOK rows, no-reading pixels skipped) is TOP_GAP or more farther
    (what stands behind shows above it; a nearer reading there hides the top instead).
    {"columns", "x" (span), "z" (lowest, highest)} of those pixels' world points, or None where
    no column has one. A head's top is round and 0.2 m wide; a partition's, straight."""
    tops = []
    for c in np.unique(u):
        r = int(v[u == c].min())
        above = depth_m[max(r - TOP_LOOK, 0):r, c][::-1]
        seen = above[np.isfinite(above) & (above > 0)]
        if len(seen) and seen[0] >= depth_m[r, c] + TOP_GAP:
            tops.append(p[r, c])
    if not tops:
        return None
    t = np.array(tops)
    return {"columns": len(t), "x": (float(t[:, 0].min()), float(t[:, 0].max())),
            "z": (float(t[:, 2].min()), float(t[:, 2].max()))}


def box_share(found: list[dict], box) -> float:
    """The share of the (inclusive) box (u0, v0, u1, v1) the pieces' pixels fill (pieces are
    found within the radius, so a piece may lie partly outside the box: an upper bound)."""
    u0, v0, u1, v1 = box
    return sum(c["pixels"] for c in found) / max((u1 - u0 + 1) * (v1 - v0 + 1), 1)


def piece_line(c: dict) -> str:
    t = c["top"]
    top = (f"; its own top in {t['columns']} columns, x {t['x'][0]:.2f} to {t['x'][1]:.2f}, {t['z'][0]:.2f} to "
           f"{t['z'][1]:.2f} m high" if t else "; no top of its own in view")
    return (f"  {c['pixels']:5d} px  u {c['u'][0]}-{c['u'][1]}  v {c['v'][0]}-{c['v'][1]}  depth {c['depth']:.2f} m  "
            f"x {c['x'][0]:.2f} to {c['x'][1]:.2f}  y {c['y']:.2f}  z {c['z'][0]:.2f} to {c['z'][1]:.2f} m{top}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--frame", type=int, default=0, help="which of input.frames' frames (0: the first)")
    ap.add_argument("--radius", type=float, default=0.4, help="metres around the detection's place")
    ap.add_argument("--at", action="append", default=[], metavar="X,Y", help="a place instead of the detections")
    ap.add_argument("--min-pixels", type=int, default=40)
    a = ap.parse_args()
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
    from dpom_warp.api import Detector
    from dpom_warp.config import ConfigError
    from dpom_warp.io import InputError
    from dpom_warp.sources import expand
    from dpom_warp.worker import read_frame

    try:
        det = Detector.from_config(a.config, a.set, log=print)
    except (ConfigError, InputError) as e:
        raise SystemExit(f"error: {e}") from None
    cfg = det.config
    if cfg.is_rig:
        raise SystemExit(f"{a.config}: expected a one-camera config, found a rig")
    files = expand(cfg.inputs.frames, "input.frames", cfg.inputs.topic, lambda *_: None)
    if not 0 <= a.frame < len(files):
        raise SystemExit(f"error: --frame: expected 0 to {len(files) - 1} ({cfg.inputs.frames}), found {a.frame}")
    depth = read_frame(cfg, files[a.frame])
    result = det.detect(depth)
    z_range = (cfg.inputs.structure.floor_gap, cfg.obj.height + 0.3)
    places = [(tuple(float(t) for t in s.split(",")), None, None) for s in a.at] or \
        [((d.x, d.y), d.rho, d.box) for d in result.detections]
    print(f"{files[a.frame].name}: {len(result.detections)} detections; readings within {a.radius:g} m of each "
          f"place, {z_range[0]:g} to {z_range[1]:g} m high, in connected pieces")
    for xy, rho, box in places:
        found = pieces(depth, det.camera, xy, a.radius, z_range, a.min_pixels)
        share = f", {100 * box_share(found, box):.0f} % of its box" if box is not None else ""
        head = f"rho* {rho:.2f}, box {box}" if rho is not None else "given"
        print(f"({xy[0]:.2f}, {xy[1]:.2f}): {head}; {len(found)} pieces{share}")
        for c in found:
            print(piece_line(c))


if __name__ == "__main__":
    main()

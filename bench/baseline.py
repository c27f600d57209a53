"""The simple alternative: a ground-plane clustering people detector, as a bench comparator.

What a user would write first, after PCL's ground-based people detector without its RGB stage
(Munaro and Menegatti's design, written here from its description, no code copied):

1. back-project the depth frame to world points with the posed camera (floor z = 0);
2. drop the floor (keep z > `floor_margin`) and what lies outside the area searched (the
   config's grid, the same area DPOM searches);
3. voxel-downsample (`voxel`), then cluster in 3D with DBSCAN (Open3D; `eps`, `min_points`);
4. split each cluster at its heads: the local maxima of a height map of the cluster on the
   ground plane (`head_cell` cells, maximum height per cell; no higher cell within
   `head_distance`), each `head_distance` from a taller head; every point goes to its nearest
   head in the plane;
5. keep the person-sized parts: top in [`min_height`, `max_height`] (walls and shelves reach
   higher and their heads win), at most `max_width` across on the ground plane, at least
   `min_points` points; a detection is the part's centroid on the ground plane, and of two
   detections closer than `head_distance` (an arm clustered apart from its body) the lower
   one is dropped, as PCL merges clusters close on the floor.

The parameters were fixed before looking at any result, from a person's size and PCL's own
defaults (voxel 0.06 m, heads at least 0.3 m apart, people 1.3 to 2.3 m tall), and are not
tuned on the scenes they are scored on.

    python -m bench.baseline CONFIG [--set key.path=value ...]    # scores the config's frames
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ClusterParams:
    """The baseline's parameters (metres), fixed a priori (module docstring)."""

    floor_margin: float = 0.15
    max_height: float = 2.3
    min_height: float = 1.3
    voxel: float = 0.06
    eps: float = 0.12  # two voxels: neighbouring voxels of one surface join
    min_points: int = 10
    head_cell: float = 0.1
    head_distance: float = 0.3
    max_width: float = 1.0


def world_points(depth_m: np.ndarray, rays: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(N, 3) world points of the pixels with a reading; `rays` (H, W, 3) with ray parameter
    = z-depth (geometry.Geometry.rays), `centre` the camera centre."""
    ok = depth_m > 0
    return centre + depth_m[ok][:, None].astype(np.float64) * rays[ok]


def heads(points: np.ndarray, p: ClusterParams) -> np.ndarray:
    """(k, 2) ground positions of a cluster's heads, tallest first: cells of its height map
    (the highest point per head_cell cell) at least min_height high with no higher cell within
    head_distance (shoulders are not heads), each head_distance from a taller head."""
    cells = np.floor(points[:, :2] / p.head_cell).astype(np.int64)
    order = np.lexsort((-points[:, 2], cells[:, 1], cells[:, 0]))
    cells, top = cells[order], points[order, 2]
    first = np.ones(len(cells), bool)
    first[1:] = np.any(cells[1:] != cells[:-1], axis=1)
    xy, top = (cells[first] + 0.5) * p.head_cell, top[first]  # one height per cell: its highest
    near = np.linalg.norm(xy[:, None] - xy[None], axis=2) < p.head_distance
    peak = ~np.any(near & (top[None, :] > top[:, None]), axis=1) & (top >= p.min_height)
    kept: list[np.ndarray] = []
    for i in np.argsort(-top, kind="stable"):
        if peak[i] and all(np.linalg.norm(xy[i] - k) >= p.head_distance for k in kept):
            kept.append(xy[i])
    return np.array(kept).reshape(-1, 2)


def detect_people(points: np.ndarray, area=None, p: ClusterParams = ClusterParams()) -> np.ndarray:
    """(n, 2) ground positions of the people among world points (N, 3), tallest first;
    `area` (x_min, x_max, y_min, y_max): where people are looked for (None: everywhere)."""
    import open3d as o3d

    keep = points[:, 2] > p.floor_margin
    if area is not None:
        x0, x1, y0, y1 = area
        keep &= (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    if keep.sum() < p.min_points:
        return np.zeros((0, 2))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[keep]))
    down = np.asarray(cloud.voxel_down_sample(p.voxel).points)
    if len(down) < p.min_points:
        return np.zeros((0, 2))
    down = down[np.lexsort(down.T[::-1])]  # a fixed order: DBSCAN's labels do not depend on the input's
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(down))
    labels = np.asarray(cloud.cluster_dbscan(p.eps, p.min_points, print_progress=False))
    found = []
    for label in range(labels.max(initial=-1) + 1):
        cluster = down[labels == label]
        tops = heads(cluster, p)
        if not len(tops):
            continue
        nearest = np.argmin(np.linalg.norm(cluster[:, None, :2] - tops[None], axis=2), axis=1)
        for h in range(len(tops)):
            part = cluster[nearest == h]
            width = np.ptp(part[:, :2], axis=0).max() if len(part) else 0.0
            if (len(part) >= p.min_points and p.min_height <= part[:, 2].max() <= p.max_height
                    and width <= p.max_width):
                found.append((part[:, 2].max(), *part[:, :2].mean(axis=0)))
    kept: list[np.ndarray] = []
    for _, x, y in sorted(found, key=lambda t: -t[0]):
        xy = np.array([x, y])
        if all(np.linalg.norm(xy - k) >= p.head_distance for k in kept):
            kept.append(xy)
    return np.array(kept).reshape(-1, 2)


def score_config(cfg, params: ClusterParams = ClusterParams()) -> dict:
    """The baseline on a config's frames with its (given) camera pose, scored like a run
    (evaluate.score_frames at evaluation.match_distance)."""
    from dpom_warp.evaluate import load_ground_truth, score_frames
    from dpom_warp.geometry import build_geometry
    from dpom_warp.sources import expand
    from dpom_warp.worker import read_frame

    geometry = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    truth = load_ground_truth(cfg.evaluation.ground_truth)
    (x0, x1, _), (y0, y1, _) = cfg.grid.x, cfg.grid.y
    area = (x0, x1, y0, y1)
    dets = {}
    for f in expand(cfg.inputs.frames, "input.frames"):
        points = world_points(read_frame(cfg, f), geometry.rays, geometry.centre)
        dets[f.name] = detect_people(points, area, params)
    return score_frames(dets, {k: truth[k] for k in dets}, cfg.evaluation.match_distance,
                        cfg.evaluation.hidden_visibility, geometry.centre[:2])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    a = ap.parse_args()
    from dpom_warp.loading import load_config
    from dpom_warp.frames import render_synthetic

    cfg = load_config(a.config, a.set)
    render_synthetic(cfg)
    s = score_config(cfg)
    print(f"clustering baseline: MODA {s['moda']:.3f}  precision {s['precision']:.3f}  recall "
          f"{s['recall']:.3f}  mean error {s['mean_error_m']:.3f} m ({s['n_gt']} in the ground truth)")


if __name__ == "__main__":
    main()

"""RANSAC plane segmentation that gives the same plane for the same points on every run.

Open3D's `PointCloud.segment_plane` does not: its samples are drawn by parallel threads and it
stops early at a probability, so on one cloud (a cabinet's front with a person flush beside it)
20 calls in one process gave two different planes, whatever `o3d.utility.random.seed` and
OMP_NUM_THREADS said (Open3D 0.20; its issue #7270), and a test passed here and failed in CI.
Here the hypotheses are drawn from a seeded NumPy generator and scored in fixed batches, so the
result depends on the points alone; the best hypothesis (most inliers, then the smaller sum of
distances) is refitted by least squares to its inliers where that keeps at least as many.
"""

from __future__ import annotations

import math

import numpy as np


def segment_plane(points: np.ndarray, distance: float | np.ndarray, iterations: int = 1000, seed: int = 0,
                  probability: float = 0.99999999, batch: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """The plane (a, b, c, d), unit (a, b, c), with a x + b y + c z + d = 0 for the most points
    of `points` (n, 3) within `distance` (metres; or (n,) each point's own: a sensor's noise
    grows with range), and the indices of those points (ascending).

    At most `iterations` three-point hypotheses, fewer once `probability` says a better plane
    is unlikely to be missed (the batch in progress is always finished). Raises ValueError for
    fewer than three points."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 3:
        raise ValueError(f"a plane needs at least 3 points, got {len(pts)}")
    tol = np.broadcast_to(np.asarray(distance, dtype=np.float64), (len(pts),))
    rng = np.random.default_rng(seed)
    best = (-1, 0.0, None)  # (inliers, -sum of inlier distances, (n, d))
    done, needed = 0, iterations
    while done < min(iterations, needed):
        k = min(batch, iterations - done)
        idx = rng.integers(0, len(pts), (k, 3))
        p0 = pts[idx[:, 0]]
        normal = np.cross(pts[idx[:, 1]] - p0, pts[idx[:, 2]] - p0)
        norm = np.linalg.norm(normal, axis=1)
        valid = norm > 1e-12
        normal = normal / np.where(valid, norm, 1.0)[:, None]
        d = -np.einsum("ij,ij->i", normal, p0)
        dist = np.abs(pts @ normal.T + d)  # (n, k)
        inside = dist <= tol[:, None]
        counts = np.where(valid, inside.sum(0), -1)
        spread = np.where(inside, dist, 0.0).sum(0)
        j = np.lexsort((spread, -counts))[0]  # most inliers, then the tightest
        if (counts[j], -spread[j]) > best[:2]:
            best = (int(counts[j]), -float(spread[j]), (normal[j], float(d[j])))
        done += k
        share = best[0] / len(pts)
        needed = (iterations if share <= 0 else 0 if share >= 1 else
                  math.ceil(math.log(1 - probability) / math.log(1 - share ** 3)))
    if best[2] is None:  # every sample degenerate (all points on one line or one spot)
        return np.array([0.0, 0.0, 1.0, 0.0]), np.zeros(0, np.int64)
    n, d = best[2]
    inliers = np.flatnonzero(np.abs(pts @ n + d) <= tol)
    if len(inliers) >= 3:  # the least-squares plane of the inliers, where it keeps as many
        fit, fit_d = least_squares_plane(pts[inliers])
        again = np.flatnonzero(np.abs(pts @ fit + fit_d) <= tol)
        if len(again) >= len(inliers):
            n, d, inliers = fit, fit_d, again
    return np.array([*n, d]), inliers


def least_squares_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """(n, d), unit n, of the plane n . X + d = 0 nearest `points` (n >= 3, (n, 3)) in the
    least-squares sense: through their centroid, normal to their direction of least spread."""
    centre = points.mean(0)
    n = np.linalg.svd(points - centre, full_matrices=False)[2][2]
    return n, -float(n @ centre)

"""Detections from an occupancy map: local maxima above a threshold, then greedy
non-maximum suppression within a radius (MODEL.md, Detections and scores)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Detected:
    """One detection: location index k, world position (metres), rho* and image box."""

    k: int
    x: float
    y: float
    z: float
    rho: float
    box: tuple[int, int, int, int]


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
           nms_radius: float) -> list[Detected]:
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
    """
    from scipy.ndimage import uniform_filter

    rho_star = np.asarray(rho_star, dtype=np.float32)
    flat = rho_star.ravel()
    cand = np.flatnonzero(local_maxima(rho_star).ravel() & (flat >= threshold))
    # strongest first; among equals (cells saturated at 1) the one whose 3 x 3 (x 3)
    # neighbourhood holds the most, the middle of its blob; then by index
    mass = uniform_filter(rho_star.astype(np.float64), 3, mode="constant").ravel()
    cand = cand[np.lexsort((cand, -mass[cand], -flat[cand]))]
    kept: list[int] = []
    for k in cand:
        if all(np.linalg.norm(locations[k] - locations[j]) >= nms_radius for j in kept):
            kept.append(int(k))
    return [Detected(k, *(float(c) for c in locations[k]), float(flat[k]),
                     tuple(int(b) for b in rect[k])) for k in kept]

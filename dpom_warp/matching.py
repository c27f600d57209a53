"""Matching two sets of points: the Hungarian assignment within a gate. The scores (detections
to ground truth, tracks to ground truth) and the trackers' naive linking all pair this way."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def assign(cost: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """Pairs (row, column) of a minimum-total-cost assignment (Hungarian), keeping only pairs
    whose cost is at most `gate`; pairs above the gate never displace admissible ones."""
    if cost.size == 0:
        return []
    big = 1e6 + 10.0 * float(np.abs(cost[np.isfinite(cost)]).max(initial=0.0))
    rows, cols = linear_sum_assignment(np.where(cost <= gate, cost, big))
    return [(int(r), int(c)) for r, c in zip(rows, cols) if cost[r, c] <= gate]


def match(det_xy: np.ndarray, gt_xy: np.ndarray, max_distance: float) -> list[tuple[int, int]]:
    """Pairs (detection, ground truth) of a minimum-total-distance assignment, each pair at most
    `max_distance` apart (ground-plane metres: "within 0.5 m" includes 0.5 m)."""
    if len(det_xy) == 0 or len(gt_xy) == 0:
        return []
    return assign(np.linalg.norm(det_xy[:, None, :] - gt_xy[None, :, :], axis=2), max_distance)

"""CLEAR detection scores: Hungarian matching within a distance, MODA, precision, recall."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from .io import InputError


def match(det_xy: np.ndarray, gt_xy: np.ndarray, max_distance: float) -> list[tuple[int, int]]:
    """Pairs (detection, ground truth) of a minimum-total-distance assignment, each pair closer
    than `max_distance` (ground-plane metres)."""
    if len(det_xy) == 0 or len(gt_xy) == 0:
        return []
    d = np.linalg.norm(det_xy[:, None, :] - gt_xy[None, :, :], axis=2)
    big = 1e6
    rows, cols = linear_sum_assignment(np.where(d <= max_distance, d, big))
    return [(int(r), int(c)) for r, c in zip(rows, cols) if d[r, c] <= max_distance]


def score_frames(detections: dict[str, np.ndarray], truth: dict[str, list[dict]],
                 max_distance: float, hidden_visibility: float = 0.0,
                 camera_xy: np.ndarray | None = None) -> dict:
    """MODA, precision and recall over a sequence.

    Args:
        detections: frame name -> (n, 2) detected x, y.
        truth: frame name -> ground-truth objects (dicts with x, y and optional visibility).
        max_distance: match gate, metres.
        hidden_visibility: ground truth whose visibility is below this is 'hidden'; the
            `*_visible` scores neither penalise missing it nor count a detection on it as false.
        camera_xy: camera position on the ground; when given, `mean_range_error_m` is the mean
            signed error of matched detections along the line of sight (negative: too near).

    Returns:
        dict with n_gt, tp, fp, fn, moda, precision, recall, mean localisation error of matched
        detections, and the same scores with hidden people not penalised.
    """
    tp = fp = fn = n_gt = 0
    tp_v = fp_v = fn_v = n_gt_v = 0
    errors, range_errors = [], []
    for name, objs in truth.items():
        det = np.asarray(detections.get(name, np.zeros((0, 2))), dtype=float).reshape(-1, 2)
        gt = np.array([[o["x"], o["y"]] for o in objs], dtype=float).reshape(-1, 2)
        hidden = np.array([o.get("visibility", 1.0) < hidden_visibility for o in objs], bool)
        pairs = match(det, gt, max_distance)
        matched_gt = {g for _, g in pairs}
        errors += [float(np.linalg.norm(det[d] - gt[g])) for d, g in pairs]
        if camera_xy is not None:
            c = np.asarray(camera_xy, float)
            range_errors += [float(np.linalg.norm(det[d] - c) - np.linalg.norm(gt[g] - c))
                             for d, g in pairs]
        tp += len(pairs)
        fp += len(det) - len(pairs)
        fn += len(gt) - len(pairs)
        n_gt += len(gt)
        tp_v += sum(1 for _, g in pairs if not hidden[g])
        fp_v += len(det) - len(pairs)
        fn_v += sum(1 for g in range(len(gt)) if g not in matched_gt and not hidden[g])
        n_gt_v += int((~hidden).sum())

    def ratio(a, b):
        return float(a / b) if b else float("nan")

    return {
        "frames": len(truth), "n_gt": n_gt, "tp": tp, "fp": fp, "fn": fn,
        "moda": 1.0 - ratio(fp + fn, n_gt) if n_gt else float("nan"),
        "precision": ratio(tp, tp + fp), "recall": ratio(tp, n_gt),
        "mean_error_m": float(np.mean(errors)) if errors else float("nan"),
        "median_error_m": float(np.median(errors)) if errors else float("nan"),
        "mean_range_error_m": float(np.mean(range_errors)) if range_errors else float("nan"),
        "n_gt_visible": n_gt_v,
        "moda_visible": 1.0 - ratio(fp_v + fn_v, n_gt_v) if n_gt_v else float("nan"),
        "recall_visible": ratio(tp_v, n_gt_v),
        "match_distance": max_distance, "hidden_visibility": hidden_visibility,
    }


def load_ground_truth(path: str | Path) -> dict[str, list[dict]]:
    """Read ground truth JSON: a list of {"frame": name, "objects": [{"x", "y", ...}]}."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such ground-truth file")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e.msg} at line {e.lineno})") from None
    if not isinstance(data, list):
        raise InputError(f"{path}: expected a JSON list of frames, found {type(data).__name__}")
    out = {}
    for n, item in enumerate(data):
        if not isinstance(item, dict) or "frame" not in item or not isinstance(item.get("objects"), list):
            raise InputError(f"{path}: entry {n}: expected {{\"frame\": name, \"objects\": [...]}}")
        for o in item["objects"]:
            if not isinstance(o, dict) or not all(isinstance(o.get(c), (int, float)) for c in ("x", "y")):
                raise InputError(f"{path}: frame {item['frame']}: expected objects with numeric x and y")
        out[str(item["frame"])] = item["objects"]
    return out

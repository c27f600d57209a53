"""CLEAR detection scores: Hungarian matching within a distance, MODA, precision, recall."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .io import InputError
from .matching import assign, match  # noqa: F401 - match: the scores' and the benchmarks'


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m) intersection over union of inclusive pixel boxes u0, v0, u1, v1."""
    a = np.asarray(a, float).reshape(-1, 4)
    b = np.asarray(b, float).reshape(-1, 4)
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]) + 1
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]) + 1
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    area_a = (a[:, 2] - a[:, 0] + 1) * (a[:, 3] - a[:, 1] + 1)
    area_b = (b[:, 2] - b[:, 0] + 1) * (b[:, 3] - b[:, 1] + 1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def score_frames(detections: dict[str, np.ndarray], truth: dict[str, list[dict]],
                 max_distance: float, hidden_visibility: float = 0.0,
                 camera_xy: np.ndarray | None = None) -> dict:
    """MODA, precision and recall over a sequence.

    Args:
        detections: frame name -> (n, 2) detected x, y, or (n, 3) x, y, z (3D distances).
        truth: frame name -> ground-truth objects (dicts with x, y, optional z and visibility).
        max_distance: match gate, metres.
        hidden_visibility: ground truth whose visibility is below this is 'hidden'; the
            `*_visible` scores neither penalise missing it nor count a detection on it as false.
        camera_xy: camera position on the ground; when given, `mean_range_error_m` is the mean
            signed error of matched detections along the line of sight (negative: too near).

    Returns:
        dict with n_gt, tp, fp, fn, moda, precision, recall, mean localisation error of matched
        detections, and the same scores with hidden people not penalised.
    """
    dims = next((np.asarray(d).shape[-1] for d in detections.values() if np.asarray(d).ndim == 2), 2)
    rows = {}
    for name, det in detections.items():  # as Detections rows: x, y, z, rho = 1, no box
        det = np.asarray(det, dtype=float).reshape(-1, dims)
        rows[name] = np.column_stack([det, np.zeros((len(det), 3 - dims)), np.ones(len(det)),
                                      -np.ones((len(det), 4))])
    dets = Detections("run", rows)
    plane = "ground" if dims == 2 else "space"
    every = counts(dets, truth, 0.0, plane, max_distance)
    visible = counts(dets, truth, 0.0, plane, max_distance, hidden_visibility, penalise_hidden=False)
    errors, range_errors = [], []
    for name, objs in truth.items():
        det = dets.at(name, 0.0)[:, :dims]
        gt = np.array([[o["x"], o["y"], o.get("z", 0.0)][:dims] for o in objs], dtype=float).reshape(-1, dims)
        pairs = match(det, gt, max_distance)
        errors += [float(np.linalg.norm(det[d] - gt[g])) for d, g in pairs]
        if camera_xy is not None:
            c = np.asarray(camera_xy, float)
            range_errors += [float(np.linalg.norm(det[d, :2] - c) - np.linalg.norm(gt[g, :2] - c))
                             for d, g in pairs]

    def mean(x):
        return float(np.mean(x)) if x else float("nan")

    return {
        "frames": len(truth), "n_gt": every["n_gt"], "tp": every["tp"], "fp": every["fp"],
        "fn": every["fn"], "moda": every["moda"], "precision": every["precision"],
        "recall": every["recall"], "mean_error_m": mean(errors),
        "median_error_m": float(np.median(errors)) if errors else float("nan"),
        "mean_range_error_m": mean(range_errors),
        "n_gt_visible": visible["n_gt"], "moda_visible": visible["moda"],
        "recall_visible": visible["recall"],
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


# ---------------------------------------------------------------------------------------
# Curves over thresholds: `dpom-warp eval`
# ---------------------------------------------------------------------------------------

DISTANCES = tuple(round(0.1 * i, 1) for i in range(1, 11))  # metres
OVERLAPS = tuple(round(0.1 * i, 1) for i in range(1, 10))  # IoU


RHO, BOX = 3, slice(4, 8)  # columns of a detection row: x, y, z, rho, u0, v0, u1, v1


class Detections:
    """Scored detections of a sequence: frame name -> (n, 8) array x, y, z (metres), rho,
    u0, v0, u1, v1 (image box, -1 when unknown)."""

    def __init__(self, name: str, frames: dict[str, np.ndarray]):
        self.name = name
        self.frames = {k: np.asarray(v, float).reshape(-1, 8) for k, v in frames.items()}

    def at(self, frame: str, threshold: float) -> np.ndarray:
        d = self.frames.get(frame, np.zeros((0, 8)))
        return d[d[:, RHO] >= threshold]

    def scores(self) -> np.ndarray:
        return np.concatenate([d[:, RHO] for d in self.frames.values()] + [np.zeros(0)])

    @property
    def has_boxes(self) -> bool:
        return all(np.all(d[:, BOX] >= 0) for d in self.frames.values())


def cube_iou(a: np.ndarray, b: np.ndarray, size) -> np.ndarray:
    """(n, m) intersection over union of axis-aligned boxes of one `size` (w, d, h) centred
    at the points a (n, 3) and b (m, 3)."""
    size = np.asarray(size, float)
    overlap = np.clip(size - np.abs(a[:, None, :] - b[None, :, :]), 0, None)
    inter = overlap.prod(axis=2)
    return inter / (2.0 * size.prod() - inter)


def counts(dets: Detections, truth: dict[str, list[dict]], threshold: float, plane: str,
           gate: float, hidden_visibility: float = 0.0, penalise_hidden: bool = True,
           cube_size=None, memo: dict | None = None) -> dict:
    """CLEAR counts over a sequence at one detection threshold.

    Args:
        plane: 'ground' (match x, y within `gate` metres), 'space' (x, y, z within `gate`
            metres), 'image' (image boxes with IoU at least `gate`) or 'cube' (object boxes of
            `cube_size` around the centres with IoU at least `gate`).
        hidden_visibility, penalise_hidden: with penalise_hidden False, ground truth less
            visible than hidden_visibility is left out: missing it is no error, and a
            detection matched to it is neither right nor wrong.
        memo: a dict kept across calls that differ only in `threshold` (a curve): a frame
            whose detections above the threshold are those of an earlier call is not matched
            again (the same rows, so the same counts).

    Returns:
        dict with tp, fp, fn, n_gt, moda, modp (mean overlap of matches: 1 - d / gate on the
        ground, IoU in the image), precision, recall.
    """
    tp = fp = fn = n_gt = 0
    overlap = 0.0
    memo = {} if memo is None else memo
    for frame, objs in truth.items():
        det = dets.at(frame, threshold)
        key = (frame, len(det))  # the rows above a threshold are the len(det) best-scored
        if key not in memo:
            memo[key] = frame_counts(det, objs, plane, gate, hidden_visibility, penalise_hidden,
                                     cube_size)
        f_tp, f_fp, f_fn, f_gt, f_overlap = memo[key]
        tp, fp, fn, n_gt, overlap = tp + f_tp, fp + f_fp, fn + f_fn, n_gt + f_gt, overlap + f_overlap
    return {"threshold": threshold, "tp": tp, "fp": fp, "fn": fn, "n_gt": n_gt,
            "moda": 1.0 - (fp + fn) / n_gt if n_gt else float("nan"),
            "modp": overlap / tp if tp else float("nan"),
            "precision": tp / (tp + fp) if tp + fp else float("nan"),
            "recall": tp / n_gt if n_gt else float("nan")}


def frame_counts(det: np.ndarray, objs: list[dict], plane: str, gate: float,
                 hidden_visibility: float, penalise_hidden: bool, cube_size=None) -> tuple:
    """(tp, fp, fn, n_gt, summed overlap) of one frame's detections (n, 8) (see counts)."""
    hidden = np.array([(not penalise_hidden) and o.get("visibility", 1.0) < hidden_visibility
                       for o in objs], bool)
    if plane in ("ground", "space"):
        n = 2 if plane == "ground" else 3
        gt = np.array([[o["x"], o["y"], o.get("z", 0.0)][:n] for o in objs], float).reshape(-1, n)
        cost = np.linalg.norm(det[:, None, :n] - gt[None, :, :], axis=2)
        pairs = assign(cost, gate)
        quality = [1.0 - cost[d, g] / gate for d, g in pairs]
    else:
        if plane == "image":
            gt = np.array([o["bbox"] for o in objs], float).reshape(-1, 4)
            iou = box_iou(det[:, BOX], gt)
        else:
            gt = np.array([[o["x"], o["y"], o.get("z", 0.0)] for o in objs], float).reshape(-1, 3)
            iou = cube_iou(det[:, :3], gt, cube_size)
        pairs = assign(1.0 - iou, 1.0 - gate + 1e-12)
        quality = [iou[d, g] for d, g in pairs]
    on_hidden = sum(1 for _, g in pairs if hidden[g])
    matched = {g for _, g in pairs}
    return (len(pairs) - on_hidden, len(det) - len(pairs),
            sum(1 for g in range(len(gt)) if g not in matched and not hidden[g]),
            int((~hidden).sum()), sum(q for q, (_, g) in zip(quality, pairs) if not hidden[g]))


def detection_thresholds(dets: Detections, n: int = 60) -> np.ndarray:
    """Candidate detection thresholds: quantiles of the detections' scores (at most n)."""
    s = np.unique(dets.scores())
    if len(s) <= n:
        return s
    return np.unique(np.quantile(s, np.linspace(0, 1, n)))


def moda_curve(dets, truth, plane, gates, hidden_visibility, penalise_hidden, cube_size=None):
    """MODA (with MODP, precision, recall) per gate, each at its best detection threshold."""
    ths = detection_thresholds(dets)
    curve = []
    for gate in gates:
        best, memo = None, {}
        for t in ths:
            c = counts(dets, truth, float(t), plane, gate, hidden_visibility, penalise_hidden,
                       cube_size, memo)
            if best is None or c["moda"] > best["moda"]:
                best = c
        curve.append({"gate": gate, **(best or counts(dets, truth, 1.1, plane, gate,
                                                       hidden_visibility, penalise_hidden, cube_size))})
    return curve


def pr_curve(dets, truth, plane, gate, hidden_visibility, penalise_hidden, cube_size=None):
    """Precision and recall at every detection threshold (high to low), and the average
    precision (area under the precision envelope, all points)."""
    memo = {}
    points = [counts(dets, truth, float(t), plane, gate, hidden_visibility, penalise_hidden,
                     cube_size, memo)
              for t in np.unique(dets.scores())[::-1]]
    points = [p for p in points if p["tp"] + p["fp"] > 0]
    if not points or not points[0]["n_gt"]:
        return {"points": [], "ap": float("nan")}
    recall = np.array([0.0] + [p["recall"] for p in points])
    precision = np.array([1.0] + [p["precision"] for p in points])
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    ap = float(np.sum((recall[1:] - recall[:-1]) * envelope[1:]))
    return {"points": [{"threshold": p["threshold"], "precision": p["precision"],
                        "recall": p["recall"]} for p in points], "ap": ap}


def evaluate(dets: Detections, truth: dict[str, list[dict]], hidden_visibility: float = 0.1,
             pr_distance: float = 0.5, pr_overlap: float = 0.4, cube_size=None) -> dict:
    """All curves of the paper for one detector, under both protocols.

    With `cube_size` (the object box, for voxel grids) distances are 3D ('moda_space',
    'pr_space' in place of the ground ones) and object boxes are matched by 3D overlap
    ('moda_cube', 'pr_cube'), as in the paper's drone experiment.
    """
    frames = {k: v for k, v in truth.items()}
    image = dets.has_boxes and all("bbox" in o for objs in frames.values() for o in objs)
    result = {"name": dets.name, "frames": len(frames),
              "n_gt": sum(len(v) for v in frames.values())}
    dist = "ground" if cube_size is None else "space"
    for protocol, penalise in (("penalise_hidden", True), ("ignore_hidden", False)):
        r = {"moda_ground": moda_curve(dets, frames, dist, DISTANCES, hidden_visibility, penalise),
             "pr_ground": pr_curve(dets, frames, dist, pr_distance, hidden_visibility, penalise)}
        if image:
            r["moda_image"] = moda_curve(dets, frames, "image", OVERLAPS, hidden_visibility, penalise)
            r["pr_image"] = pr_curve(dets, frames, "image", pr_overlap, hidden_visibility, penalise)
        if cube_size is not None:
            r["moda_cube"] = moda_curve(dets, frames, "cube", OVERLAPS, hidden_visibility, penalise,
                                        cube_size)
            r["pr_cube"] = pr_curve(dets, frames, "cube", pr_overlap, hidden_visibility, penalise,
                                    cube_size)
        result[protocol] = r
    result.update(hidden_visibility=hidden_visibility, pr_distance=pr_distance,
                  pr_overlap=pr_overlap, distance=dist,
                  cube_size=None if cube_size is None else [float(s) for s in cube_size])
    return result


def read_detections_csv(path: str | Path, name: str | None = None) -> Detections:
    """Detections of any detector in the run's CSV form (frame,x,y,z,rho,u0,v0,u1,v1; the box
    columns may be missing or -1)."""
    import csv

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such detections file")
    frames: dict[str, list] = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        need = {"frame", "x", "y", "rho"}
        if reader.fieldnames is None or not need <= set(reader.fieldnames):
            raise InputError(f"{path}: expected a CSV header with frame, x, y, rho "
                             f"(and u0, v0, u1, v1), found {reader.fieldnames}")
        for n, row in enumerate(reader, start=2):
            try:
                box = [float(row.get(k) if row.get(k) not in (None, "") else -1) for k in ("u0", "v0", "u1", "v1")]
                z = float(row.get("z") or 0.0)
                frames.setdefault(row["frame"], []).append(
                    [float(row["x"]), float(row["y"]), z, float(row["rho"])] + box)
            except ValueError:
                raise InputError(f"{path}: line {n}: expected numbers in x, y, rho, u0..v1") from None
    return Detections(name or path.stem, frames)


def run_detections(run_dir: str | Path, min_rho: float = 0.05) -> tuple[Detections, dict, tuple | None]:
    """Scored detections of a `dpom-warp run` folder, re-detected from its rho maps down to
    `min_rho` (the CSV holds only those above the run's threshold), with the run's grid,
    camera pose (fitted one included) and non-maximum suppression.

    Returns:
        (detections, the run's summary, the object box (w, d, h) for voxel runs else None).
    """
    from .config import ConfigError, parse_config
    from .detect import detect_map
    from .geometry import build_geometry

    run_dir = Path(run_dir)
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, json.JSONDecodeError):
        raise InputError(f"{run_dir}: not a dpom-warp run folder (no readable summary.json)") from None
    try:
        cfg = parse_config(summary["config"])
    except (ConfigError, KeyError) as e:
        raise InputError(f"{run_dir}/summary.json: config does not parse ({e})") from None
    camera = cfg.camera
    if cfg.pose_auto:
        import dataclasses

        camera = dataclasses.replace(camera, T_world_from_camera=np.array(
            summary["ground_fit"]["T_world_from_camera"], float))
    geom = build_geometry(camera, cfg.grid, cfg.obj)
    frames = {}
    for item in summary["per_frame"]:
        name = item["frame"]
        path = run_dir / "maps" / f"{Path(name).stem}.npy"
        try:
            rho = np.load(path)
        except (OSError, ValueError):
            raise InputError(f"{path}: missing or unreadable occupancy map") from None
        dets = detect_map(rho, geom, cfg.detection, threshold=min_rho)
        frames[name] = [[d.x, d.y, d.z, d.rho, *d.box] for d in dets]
    cube = None
    if cfg.grid.mode == "voxel":
        cube = (cfg.obj.width, cfg.obj.depth or cfg.obj.width, cfg.obj.height)
    return Detections(run_dir.name, frames), summary, cube


def markdown_table(results: list[dict]) -> str:
    """One row per detector and protocol: the headline numbers of the curves."""

    def at(curve, gate):
        return next((c for c in curve or [] if abs(c["gate"] - gate) < 1e-9), None)

    def f(x):
        return "n/a" if x is None or x != x else f"{x:.3f}"

    r0 = results[0]
    lines = [f"| detector | protocol | MODA @ {r0['pr_distance']} m | MODP | precision | recall "
             f"| threshold | AP @ {r0['pr_distance']} m | MODA @ IoU 0.5 | AP @ IoU {r0['pr_overlap']} |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        for protocol, label in (("penalise_hidden", "hidden penalised"),
                                ("ignore_hidden", f"visibility < {r['hidden_visibility']:g} ignored")):
            p = r[protocol]
            g = at(p["moda_ground"], r["pr_distance"]) or {}
            i = at(p.get("moda_image"), 0.5) or {}
            lines.append(
                f"| {r['name']} | {label} | {f(g.get('moda'))} | {f(g.get('modp'))} | "
                f"{f(g.get('precision'))} | {f(g.get('recall'))} | {f(g.get('threshold'))} | "
                f"{f(p['pr_ground']['ap'])} | {f(i.get('moda'))} | "
                f"{f(p.get('pr_image', {}).get('ap'))} |")
    return "\n".join(lines)


def evaluate_runs(sources: list[str | Path], ground_truth: str | Path | None = None,
                  hidden_visibility: float = 0.1, min_rho: float = 0.05) -> list[dict]:
    """Evaluate run folders and detection CSVs against one ground truth (by default the first
    run's evaluation.ground_truth). A run is scored on the frames it processed."""
    results, truth = [], None
    for src in sources:
        src = Path(src)
        cube = None
        if src.is_dir():
            dets, summary, cube = run_detections(src, min_rho)
            if ground_truth is None:
                ground_truth = summary["config"].get("evaluation", {}).get("ground_truth")
                if ground_truth is None:
                    raise InputError(f"{src}: the run had no evaluation.ground_truth; "
                                     f"expected --ground-truth GT.json")
            frames = list(dets.frames)
        else:
            if not src.exists():
                raise InputError(f"{src}: no such run folder or detections CSV")
            dets, frames = read_detections_csv(src), None
            if ground_truth is None:
                raise InputError(f"{src}: expected --ground-truth GT.json for a CSV")
        if truth is None:
            truth = load_ground_truth(ground_truth)
        sub = truth if frames is None else {k: truth[k] for k in frames if k in truth}
        if frames is not None and len(sub) < len(frames):
            missing = next(k for k in frames if k not in truth)
            raise InputError(f"{ground_truth}: no ground truth for frame {missing} of {src}")
        results.append(evaluate(dets, sub, hidden_visibility, cube_size=cube))
        if src.is_dir() and (src / "tracks.csv").exists():
            results[-1]["tracking"] = run_track_scores(src, summary, sub, hidden_visibility)
    return results


def run_track_scores(run_dir: Path, summary: dict, truth: dict, hidden_visibility: float) -> dict:
    """Tracking scores of a run's tracks.csv, and of the naive linking of its detections.csv
    (the baseline), when the ground truth has identities."""
    from .track_eval import naive_tracks, track_scores
    from .track_files import read_tracks_csv

    frames = [p["frame"] for p in summary["per_frame"]]
    if not all("id" in o for f in frames for o in truth.get(f, [])):
        return {"skipped": "the ground truth has no identities (objects[].id)"}
    dims = 3 if summary["config"]["grid"]["mode"] == "voxel" else 2
    tracks = read_tracks_csv(run_dir / "tracks.csv")
    dets = read_detections_csv(run_dir / "detections.csv")
    gate = summary["config"]["evaluation"]["match_distance"]
    naive = naive_tracks({f: d[:, :dims] for f, d in dets.frames.items()}, frames, gate)
    return {"method": summary.get("tracking", {}).get("method"),
            "tracks": track_scores(tracks, truth, frames, dims, hidden_visibility),
            "naive": track_scores(naive, truth, frames, dims, hidden_visibility)}


def tracking_table(results: list[dict]) -> str:
    """One row per run, tracker (its tracks, the naive linking) and gate: MOTA, MOTP, IDF1,
    HOTA, identity switches (hidden people ignored below the visibility threshold)."""
    lines = ["| run | tracks | gate | MOTA | MOTP (m) | IDF1 | HOTA | ID switches | per 500 person-frames |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        t = r.get("tracking")
        if not t or "skipped" in t:
            continue
        for who, label in (("tracks", t["method"]), ("naive", "naive linking")):
            for gate, s in t[who]["ignore_hidden"].items():
                lines.append(f"| {r['name']} | {label} | {gate} m | {s['mota']:.3f} | {s['motp']:.3f} | "
                             f"{s['idf1']:.3f} | {s['hota']:.3f} | {s['num_switches']} | "
                             f"{s['switches_per_500']:.2f} |")
    return "\n".join(lines) if len(lines) > 2 else ""

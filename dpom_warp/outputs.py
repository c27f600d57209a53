"""A run's output folder made ready (run.json, --overwrite, --resume), what its summary holds,
and the tracks a frame's picture and Rerun log show; the files themselves are written by the
writers (writers.py). The recorded and the live run both use these."""

from __future__ import annotations

import json
import platform
import shutil
import statistics
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .drift import summary as drift_summary
from .evaluate import score_frames
from .io import TEMP_MARK, write_json_atomic
from .writers import TRACK_FILES, jsonable


RUN_STATE = "run.json"


OUTPUTS = ("maps", "images", "frames", "plots", "ply", "detections.csv", "summary.json", "eval.json",
           *TRACK_FILES, RUN_STATE)


def check_output(out: Path, resolved: dict, overwrite: bool, resume: bool) -> None:
    """Refuse, before any work, an output folder that is a file, or not empty unless
    overwriting or resuming a run of the same config (`resolved`); changes nothing."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"output.dir: {out} is a file; expected an empty or new folder")
    if not (out.exists() and any(out.iterdir())) or (overwrite and not resume):
        return
    if not resume:
        raise ConfigError(f"output.dir: {out} is not empty; expected an empty or new folder "
                          f"(use --overwrite to replace its results or --resume to continue)")
    path = out / RUN_STATE
    try:
        before = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        raise ConfigError(f"--resume: {out} holds no resumable run ({RUN_STATE} missing "
                          f"or unreadable)") from None
    state = {"config": jsonable(resolved)}
    if before != json.loads(json.dumps(state)):
        diff = _first_difference(before.get("config", {}), state["config"])
        raise ConfigError(f"--resume: {out} holds a run of another config ({diff}); "
                          f"expected the same config, or use --overwrite")


def prepare_output(out: Path, resolved: dict, overwrite: bool, resume: bool) -> None:
    """Make `out` ready: refuse a non-empty folder unless overwriting or resuming a run of
    the same config (check_output); remove what an interrupted write left behind."""
    check_output(out, resolved, overwrite, resume)
    if out.exists() and any(out.iterdir()) and overwrite and not resume:
        for name in OUTPUTS:
            target = out / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a file where a folder above it should be, no permission
        raise ConfigError(f"output.dir: {out}: cannot make the folder ({e.strerror or e}); expected a "
                          f"path where a new folder can be made") from None
    remove_temporaries(out)  # of a killed run
    write_json_atomic(out / RUN_STATE, {"config": jsonable(resolved)})


def remove_temporaries(out: Path) -> None:
    """The temporary files of atomic writes left in a run's folder: by a killed run, or by
    Ctrl-C landing between a temporary file's creation and the write's own cleanup."""
    for stale in list(out.glob(f".*{TEMP_MARK}*")) + list(out.glob(f"*/.*{TEMP_MARK}*")):
        stale.unlink(missing_ok=True)


def _first_difference(a, b, path=""):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
    return f"{path}: {a!r} then, {b!r} now"


def fps_of(timestamps: list) -> float | None:
    """The frame rate of frames with timestamps, None without: one over the median interval
    between consecutive frames, the intervals over frames dropped or skipped between left
    out (those over 1.5 times the intervals' 10th percentile: a short recording with a frame
    skipped has as many of those as of the others)."""
    ts = [t for t in timestamps if t is not None]
    if len(ts) < 2 or len(ts) < len(timestamps):
        return None
    gaps = np.array([b - a for a, b in zip(ts, ts[1:]) if b > a])
    if not len(gaps):
        return None
    return 1.0 / float(np.median(gaps[gaps <= 1.5 * np.percentile(gaps, 10)]))


def pictures_deferred(cfg: RunConfig, frames: int) -> bool:
    """Whether a run's pictures are drawn after tracking (they show the tracks), or after the
    frames (a picture of every output.images_every-th frame done, counted in order), rather
    than by whoever infers each frame."""
    return cfg.output.images and (cfg.output.images_every > 1 or cfg.tracking.resolved_method(frames) != "off")


class ShownTracks:
    """What a frame's picture and Rerun log show of the tracks, frame after frame (`at`, in
    order): each track's id, box (the silhouette of the cell nearest to it), bridged flag and
    trail (its positions over the last tracking.trail frames, this one's included). Holds
    only the trails' frames."""

    def __init__(self, geometry, trail: int):
        self.geometry, self.trail = geometry, max(1, trail)
        self.history: dict[int, list] = {}

    def at(self, i: int, rows: list) -> list[dict]:
        """Frame i's tracks from rows [(id, xyz, bridged)]."""
        shown = []
        for tid, xyz, bridged in rows:
            self.history.setdefault(tid, []).append((i, xyz))
            past = [p for j, p in self.history[tid] if j > i - self.trail]
            k = int(np.argmin(np.linalg.norm(self.geometry.locations - xyz, axis=1)))
            shown.append({"id": tid, "box": self.geometry.rect[k], "bridged": bridged, "trail": past, "xyz": xyz})
        self.history = {tid: [(j, p) for j, p in h if j > i - self.trail] for tid, h in self.history.items()
                        if h[-1][0] > i - self.trail}
        return shown


def summarise(cfg, done, records, skipped, truth, geometry, dev, background, ground, grown):
    """The summary (summary.json's content), from the frame records in frame order."""
    per_frame = [records[f.name]["stats"] for f in done]

    def median(key):
        return statistics.median(p[key] for p in per_frame) if per_frame else float("nan")

    summary = {
        "config": cfg.resolved,
        "device": dev, "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "background": background, "ground_fit": ground, "frames": len(done),
        "skipped": skipped, "detections": sum(p["detections"] for p in per_frame),
        "unconverged": [p["frame"] for p in per_frame if not p.get("converged", True)],
        "list_capacity_growth": grown,
        "timings": {"median_read_s": median("read_s"), "median_infer_s": median("infer_s"),
                    "median_lists_s": median("engine_lists_s"),
                    "median_iterations_s": median("engine_iterations_s"),
                    "median_detect_s": median("detect_s"), "median_write_s": median("write_s"),
                    "median_iterations": median("iterations"),
                    "median_entries": median("entries"),
                    "median_kept_entries": median("kept_entries") if per_frame and all(
                        p.get("kept_entries") is not None for p in per_frame) else None},
        "per_frame": per_frame,
    }
    drifts = {p["frame"]: p["drift"] for p in per_frame if "drift" in p}
    rig = hasattr(geometry, "parts")  # a rig's (geometry.RigGeometry)
    if drifts and rig:  # each camera's range
        summary["drift"] = {n: drift_summary({f: d[n] for f, d in drifts.items() if d.get(n)}) for n in cfg.camera_names}
    elif drifts:  # each frame's estimate is in its record (and per_frame); here their range
        summary["drift"] = drift_summary(drifts)
    if rig:  # each camera's frames, and the rig frames it had none for (inferred from the others)
        def camera_median(key, n):
            times = [p[key][n] for p in per_frame if n in p.get(key, {})]
            return statistics.median(times) if times else None

        summary["cameras"] = {n: {"frames": sum(records[f.name]["cameras"][n] is not None for f in done),
                                  "missing": [f.name for f in done if records[f.name]["cameras"][n] is None],
                                  "median_read_s": camera_median("read_s_cameras", n),
                                  "median_lists_s": camera_median("lists_s_cameras", n),
                                  "median_iterations_s": camera_median("iterations_s_cameras", n)}
                              for n in cfg.camera_names}
    if truth is not None and done:
        dims = 3 if cfg.grid.mode == "voxel" else 2
        det_xy = {f.name: np.array(records[f.name]["xy"]).reshape(-1, dims) for f in done}
        summary["scores"] = score_frames(det_xy, {f.name: truth[f.name] for f in done},
                                         cfg.evaluation.match_distance,
                                         cfg.evaluation.hidden_visibility, geometry.centre[:2])
    return summary



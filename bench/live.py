"""The live mode against a 30 fps stream: a SoftwareCamera plays the people demo's room
(512 x 424, Kinect v2-like, five people) rendered at the stream's rate, people walking ~1.3 m/s
to waypoints (--stream-frames frames, rendered once into .cache/live_stream), at --fps;
`dpom-warp run` infers them live for --frames frames (the demo's config, the stream's
background frames, online tracks, a picture every --every frames), and the processing rate,
the drops and the latency (a frame's arrival to its record written) are reported, median of
--repeats runs. The rate is the run's once running (summary.json's live.frames_per_s_steady:
frames written from the first's arrival plus the median latency to the last's record), with the
rate over the whole run beside it (frames_per_s: from the first frame's arrival to the end of
the run, the helpers' and the camera's shutdown included).

Each run's tracks are scored against the stream's ground truth (each map's camera frame from
its timestamp; MOTA, IDF1 and identity switches at 0.5 m, people under 10 % visible ignored),
beside the same maps tracked by KSP, and every SPARSE-th map alone (what a machine keeping a
fifth of the frames would have) tracked online with the maps' timestamps and without them (one
camera frame between two maps, as the live tracker did before it used them).

With --busy N, N other processes keep a core each busy (a Python loop) through every run: the
machine a live run shares with other work.

    python -m bench.live [--fps 30] [--frames 300] [--every 30] [--repeats 3] [--workers 1 2 3]
                         [--stream-frames 900] [--busy N] [--output runs/live]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
SPARSE = 5
STREAM = ROOT / ".cache" / "live_stream"
WALK = 1.3  # m/s, the stream's people


def stream_sets(fps: float, frames: int) -> list[str]:
    """The demo config's overrides that render its room at the stream's rate (people walking
    WALK m/s to waypoints) into STREAM and read the frames, background and truth from there."""
    return [f"synthetic.cache={STREAM}", f"synthetic.frames={frames}", "synthetic.motion=paths",
            f"synthetic.step_m={WALK / fps:.4f}", f"input.fps={fps:g}", f"input.frames={STREAM}/frames/*.png",
            f"input.background={STREAM}/background/*.png", f"evaluation.ground_truth={STREAM}/ground_truth.json"]


def track_quality(run_dir: Path, truth: list, fps: float, cfg) -> dict:
    """MOTA, IDF1 and identity switches (0.5 m, hidden people ignored) of a live run's tracks,
    of its maps tracked by KSP, and of every SPARSE-th map tracked online with and without the
    maps' timestamps; the truth of each map is its camera frame's (its timestamp x fps, the
    stream looping)."""
    import numpy as np

    from dpom_warp.geometry import build_geometry
    from dpom_warp.track_eval import track_scores
    from dpom_warp.track_files import per_frame, read_tracks_csv
    from dpom_warp.tracking import Cells, run_tracker

    summary = json.loads((run_dir / "summary.json").read_text())
    names = [p["frame"] for p in summary["per_frame"]]
    times = [p["timestamp"] for p in summary["per_frame"]]
    gt = {n: truth[round(t * fps) % len(truth)] for n, t in zip(names, times)}

    def score(tracks: dict, frames: list) -> dict:
        s = track_scores(tracks, gt, frames, 2, 0.1, gates=(0.5,))["ignore_hidden"]["0.5"]
        return {"mota": s["mota"], "idf1": s["idf1"], "switches": s["num_switches"]}

    maps = np.stack([np.load(run_dir / "maps" / f"{n}.npy").ravel() for n in names])
    cells = Cells.for_run(build_geometry(cfg.camera, cfg.grid, cfg.obj), cfg)
    out = {"live": score(read_tracks_csv(run_dir / "tracks.csv"), names)}
    every = slice(None, None, SPARSE)
    for key, method, take, stamps in (("ksp", "ksp", slice(None), times),
                                      ("sparse", "online", every, times[every]),
                                      ("sparse_no_times", "online", every, None)):
        frames = names[take]
        tracks, _ = run_tracker(maps[take], cells, cfg.grid.shape, cfg.tracking, fps, cfg.detection.threshold,
                                method, stamps)
        at = per_frame(tracks, len(frames))  # (id, xyz, bridged) a frame, as track_scores reads them
        out[key] = score({n: [(i, *map(float, p)) for i, p, _ in rows] for n, rows in zip(frames, at)}, frames)
    kept = times[every]
    out["sparse_rate"] = (len(kept) - 1) / (kept[-1] - kept[0]) if len(kept) > 1 else 0.0
    return out


def spin() -> None:
    while True:
        pass


class Busy:
    """`n` processes each keeping a core busy while in the `with` block."""

    def __init__(self, n: int):
        self.n, self.procs = n, []

    def __enter__(self):
        import multiprocessing

        self.procs = [multiprocessing.get_context("spawn").Process(target=spin, daemon=True) for _ in range(self.n)]
        for p in self.procs:
            p.start()
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.terminate()
            p.join()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--every", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2, 3],
                    help="processes of the live run, each measured (1: the main process alone)")
    ap.add_argument("--stream-frames", type=int, default=900,
                    help="frames of the rendered stream (the camera loops it; 900: 30 s at 30 fps)")
    ap.add_argument("--busy", type=int, default=0, help="other processes keeping a core busy each during the runs")
    ap.add_argument("--output", default="runs/live")
    a = ap.parse_args()
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
    from dpom_warp.loading import load_config
    from dpom_warp.evaluate import load_ground_truth
    from dpom_warp.live import LIVE_WORKERS
    from dpom_warp.frames import render_synthetic
    from dpom_warp.pipeline import run
    from dpom_warp.sources import expand
    from dpom_warp.sources.software import SoftwareCamera

    demo = ROOT / "configs" / "demo_people.yaml"
    stream_cfg = load_config(demo, stream_sets(a.fps, a.stream_frames))
    render_synthetic(stream_cfg, lambda *_: None)  # the stream, rendered the first time
    cam = SoftwareCamera.of_files(expand(stream_cfg.inputs.frames, "input.frames"), stream_cfg.camera, a.fps).register()
    truth = load_ground_truth(stream_cfg.evaluation.ground_truth)
    truth = [truth[k] for k in sorted(truth)]
    sets = stream_sets(a.fps, a.stream_frames) + [
        "input.frames=realsense", "evaluation.ground_truth=null", f"output.images_every={a.every}",
        "tracking.method=online"]
    runs = {w: [] for w in a.workers}
    for i in range(a.repeats):
        for w in a.workers:  # taken in turn: the same machine state for each
            live_cfg = load_config(demo, sets)
            cam.start()
            try:
                with Busy(a.busy):
                    s = run(live_cfg, str(Path(a.output) / f"run{i}_x{w}"), "cpu", progress=False,
                            log=lambda *_: None, overwrite=True, max_frames=a.frames, workers=w)
            finally:
                cam.stop()
            runs[w].append(s["live"] | {"infer_ms": 1000 * s["timings"]["median_infer_s"],
                                        "track_ms": s["tracking"].get("ms_per_frame"),
                                        "quality": track_quality(Path(a.output) / f"run{i}_x{w}", truth, a.fps,
                                                                 stream_cfg)})
    cam.unregister()

    def med(w, k):
        return statistics.median(r[k] for r in runs[w])

    def q(w, who, k):
        return statistics.median(r["quality"][who][k] for r in runs[w])

    busy = f"; {a.busy} other process{'es' * (a.busy > 1)} keeping a core busy" if a.busy else ""
    lines = []
    for w in a.workers:
        who = "one process" if w == 1 else (f"`--workers {w}` (the main process and {w - 1} helper{'s' * (w > 2)}"
                                            f"{'; the default' if w == LIVE_WORKERS else ''})")
        kept = statistics.median(r["quality"]["sparse_rate"] for r in runs[w])
        trackers = (("live", "as run (online)"), ("ksp", "its maps by KSP"),
                    ("sparse", f"every {SPARSE}th map alone ({kept:.1f} frames/s kept), online by their timestamps"),
                    ("sparse_no_times", "the same without the timestamps (one camera frame between maps)"))
        lines.append(
            f"Live on the demo's room rendered at {a.fps:g} frames/s (512x424, five people walking {WALK:g} m/s; "
            f"{a.frames} frames, a picture every {a.every}{busy}), {who}: **{med(w, 'frames_per_s_steady'):.1f} frames/s** processed once running "
            f"({med(w, 'frames_per_s'):.1f} over the whole run, start-up and shutdown included), "
            f"{100 * med(w, 'dropped_share'):.0f} % of the frames dropped (the newest is always taken), latency "
            f"from a frame's arrival to its record median {med(w, 'latency_ms_median'):.0f} ms (95th percentile "
            f"{med(w, 'latency_ms_p95'):.0f} ms); inference {med(w, 'infer_ms'):.0f} ms, online tracking "
            f"{med(w, 'track_ms'):.1f} ms a frame; median of {a.repeats} runs. Its tracks against the "
            f"stream's ground truth (0.5 m, people under 10 % visible ignored): "
            + "; ".join(f"{label} MOTA {q(w, key, 'mota'):.3f}, IDF1 {q(w, key, 'idf1'):.3f}, "
                        f"{q(w, key, 'switches'):g} identity switches" for key, label in trackers) + ".")
    if 1 in runs and len(runs) > 1:
        best = max(runs, key=lambda w: med(w, "frames_per_s_steady"))
        lines.append(f"`--workers {best}` against one process: "
                     f"{med(best, 'frames_per_s_steady') / med(1, 'frames_per_s_steady'):.2f}x "
                     "the frames processed (same run, taken in turn).")
    print("\n\n".join(lines))
    Path(a.output).mkdir(parents=True, exist_ok=True)
    (Path(a.output) / "live.md").write_text("\n\n".join(lines) + "\n")
    (Path(a.output) / "live.json").write_text(json.dumps({str(w): r for w, r in runs.items()}, indent=2))


if __name__ == "__main__":
    main()

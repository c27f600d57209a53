"""The live mode against a 30 fps stream: a SoftwareCamera plays the people demo's frames
(512 x 424, Kinect v2-like) at --fps, `dpom-warp run` infers them live for --frames frames
(the demo's config, its background frames, online tracks, a picture every --every frames),
and the processing rate, the drops and the latency (a frame's arrival to its record written)
are reported, median of --repeats runs. The rate is the run's once running (summary.json's
live.frames_per_s_steady: frames written from the first's record to the last's), with the rate
over the whole run beside it (frames_per_s: from the first frame's arrival to the end of the
run, the helpers' and the camera's shutdown included).

    python -m bench.live [--fps 30] [--frames 300] [--every 30] [--repeats 3] [--workers 1 2]
                         [--output runs/live]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--every", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2],
                    help="processes of the live run, each measured (1: the main process alone)")
    ap.add_argument("--output", default="runs/live")
    a = ap.parse_args()
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
    from dpom_warp.config import load_config
    from dpom_warp.pipeline import run
    from dpom_warp.sources.realsense import SoftwareCamera

    demo = ROOT / "configs" / "demo_people.yaml"
    cam = SoftwareCamera.of_config(load_config(demo), a.fps).register()
    sets = ["input.frames=realsense", "evaluation.ground_truth=null", f"output.images_every={a.every}",
            "tracking.method=online"]
    runs = {w: [] for w in a.workers}
    for i in range(a.repeats):
        for w in a.workers:  # taken in turn: the same machine state for each
            live_cfg = load_config(demo, sets)
            cam.start()
            try:
                s = run(live_cfg, str(Path(a.output) / f"run{i}_x{w}"), "cpu", progress=False,
                        log=lambda *_: None, overwrite=True, max_frames=a.frames, workers=w)
            finally:
                cam.stop()
            runs[w].append(s["live"] | {"infer_ms": 1000 * s["timings"]["median_infer_s"],
                                        "track_ms": s["tracking"].get("ms_per_frame")})
    cam.unregister()

    def med(w, k):
        return statistics.median(r[k] for r in runs[w])

    lines = []
    for w in a.workers:
        who = "one process" if w == 1 else f"`--workers {w}` (the main process and {w - 1} helper{'s' * (w > 2)})"
        lines.append(
            f"Live on the demo stream ({a.fps:g} frames/s, 512x424, {a.frames} frames, a picture every "
            f"{a.every}), {who}: **{med(w, 'frames_per_s_steady'):.1f} frames/s** processed once running "
            f"({med(w, 'frames_per_s'):.1f} over the whole run, start-up and shutdown included), "
            f"{100 * med(w, 'dropped_share'):.0f} % of the frames dropped (the newest is always taken), latency "
            f"from a frame's arrival to its record median {med(w, 'latency_ms_median'):.0f} ms (95th percentile "
            f"{med(w, 'latency_ms_p95'):.0f} ms); inference {med(w, 'infer_ms'):.0f} ms, online tracking "
            f"{med(w, 'track_ms'):.1f} ms a frame; median of {a.repeats} runs.")
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

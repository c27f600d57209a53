"""What reading a recording costs: the people demo's frames (512 x 424) written as a ROS 1 bag,
a ROS 2 bag (sqlite), an MCAP bag (16UC1) and a ROS 1 bag in 32FC1 metres, each read into its
frame cache (decode + 16-bit .npy), then the cached frames read back as a run reads them; and
the detections of a run on each against the PNG run of the same frames.

    python -m bench.recordings [--output runs/recordings] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="runs/recordings")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
    import yaml

    from dpom_warp.loading import load_config
    from dpom_warp.io import read_depth
    from dpom_warp.frames import render_synthetic
    from dpom_warp.pipeline import run
    from dpom_warp.sources import materialise
    from test_recordings import messages, typestore, write_bag

    out = Path(a.output)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    os.environ["DPOM_WARP_CACHE"] = str(out / "cache")
    demo = ROOT / "configs" / "demo_people.yaml"
    cfg = load_config(demo)
    render_synthetic(cfg, lambda *_: None)
    frames = sorted(Path(ROOT / ".cache" / "demo_people" / "frames").glob("*.png"))
    camera = {"fx": cfg.camera.fx, "fy": cfg.camera.fy, "cx": cfg.camera.cx, "cy": cfg.camera.cy}
    png = run(load_config(demo, ["output.images=false", "tracking.method=off", "evaluation.ground_truth=null"]),
              str(out / "png"), "cpu", progress=False, log=lambda *_: None)
    png_rows = (out / "png" / "detections.csv").read_text().splitlines()[1:]
    rows = []
    kinds = [("ROS 1 bag, 16UC1", "ros1", "16UC1", "demo.bag"), ("ROS 2 bag (sqlite), 16UC1", "ros2", "16UC1", "demo2"),
             ("MCAP, 16UC1", "mcap", "16UC1", "demo_mcap"), ("ROS 1 bag, 32FC1 metres", "ros1", "32FC1", "demo_f.bag")]
    for label, kind, enc, name in kinds:
        bag = write_bag(out / name, kind, messages(typestore(kind == "ros1"), frames, enc, camera))
        if kind == "mcap":
            bag = next(bag.glob("*.mcap"))
        decode, read = [], []
        for _ in range(a.repeats):
            shutil.rmtree(out / "cache", ignore_errors=True)
            t = time.perf_counter()
            meta = materialise(str(bag), None, log=lambda *_: None)
            decode.append((time.perf_counter() - t) / len(frames))
            files = [Path(meta["folder"]) / f["frame"] for f in meta["frames"]]
            t = time.perf_counter()
            for f in files:
                read_depth(f, meta["depth_scale"], (cfg.camera.height, cfg.camera.width))
            read.append((time.perf_counter() - t) / len(files))
        raw = yaml.safe_load(demo.read_text())
        for k in ("width", "height", "intrinsics"):
            raw["camera"].pop(k)
        raw["input"] = {"frames": str(bag.resolve()), "background": str(ROOT / ".cache" / "demo_people" / "background" / "*.png")}
        raw["evaluation"] = {"ground_truth": None}
        raw.pop("synthetic")
        raw["output"] = {"images": False}
        raw["tracking"] = {"method": "off"}
        path = out / f"{name}.yaml"
        path.write_text(yaml.safe_dump(raw))
        rec = run(load_config(path), str(out / f"run_{name}"), "cpu", progress=False, log=lambda *_: None)
        rec_rows = (out / f"run_{name}" / "detections.csv").read_text().splitlines()[1:]
        renamed = [f"{int(r.split(',')[0]):04d}.png," + r.split(",", 1)[1] for r in rec_rows]
        same = "identical" if renamed == png_rows else "**different**"
        rows.append(f"| {label} | {len(frames)} | {1000 * statistics.median(decode):.1f} ms | "
                    f"{1000 * statistics.median(read):.1f} ms | {same} | {1000 * rec['timings']['median_infer_s']:.0f} ms |")
    lines = ["| recording | frames | read into the cache, per frame | cached frame read by the run | "
             "detections vs the PNG run | inference per frame |", "|---|---|---|---|---|---|", *rows,
             "", f"PNG run of the same frames: {1000 * png['timings']['median_infer_s']:.0f} ms inference per "
                 f"frame; times are medians of {a.repeats} readings, one core."]
    print("\n".join(lines))
    (out / "recordings.md").write_text("\n".join(lines) + "\n")
    (out / "recordings.json").write_text(json.dumps({"rows": rows}, indent=2))


if __name__ == "__main__":
    main()

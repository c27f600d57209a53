"""One process, `--workers N` and `--ray` on the same run: frames per second, the per-frame cost
of spreading the frames, and what the driver can carry.

    python -m bench.scaleout [--config configs/demo_people.yaml] [--frames 20] [--workers 2]
                             [--repeats 3] [--output runs/scaleout] [--set key.path=value ...]

Each mode runs as a user runs it (`python -m dpom_warp.cli run ...` in a fresh process, `--ray`
starting its own local Ray instance), `--repeats` times in turn; the medians are reported.
  - command s: the whole command, from start to exit (Python, Ray and kernels starting included);
  - frames/s: frames over the time from the first frame sent to the last written;
  - work ms: a frame's own work where it is inferred (read, infer, detect, picture), mean;
  - overhead ms/frame: what a frame costs beyond its work, per process: frames-phase wall x
    processes / frames - work (sending, receiving, waiting, writing; for one process the
    writing and the loop);
  - driver ms/frame (--ray): the driver's busy time per frame (reading the file, sending,
    receiving, writing); 1 / it is the most frames per second one driver can write.
Every mode's detections.csv and maps must equal the one-process run's (checked).
`--frames` other than the config's renders a longer sequence into its own cache.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path



def sets_for(config: str, frames: int | None) -> list[str]:
    if not frames:
        return []
    from dpom_warp.config import read_config

    cache = f"{read_config(config)['synthetic']['cache']}_{frames}"  # paths as the run reads them
    return [f"synthetic.frames={frames}", f"synthetic.cache={cache}",
            f"input.frames={cache}/frames/*.png", f"input.background={cache}/background/*.png",
            f"evaluation.ground_truth={cache}/ground_truth.json"]


def run_mode(config: str, out: Path, extra: list[str], sets: list[str]) -> dict:
    cmd = [sys.executable, "-m", "dpom_warp.cli", "run", config, "--no-progress", "--overwrite",
           "--output", str(out)] + [a for s in sets for a in ("--set", s)] + extra
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    runner, per = summary["runner"], summary["per_frame"]
    n = len(per)
    work = statistics.fmean(p["read_s"] + p["infer_s"] + p["detect_s"] + p["render_s"] for p in per)
    processes = {"one process": 1, "processes": runner.get("workers"), "ray": runner.get("actors")}[runner["kind"]]
    return {"command_s": wall, "frames": n, "frames_per_s": runner["frames_per_s"],
            "processes": processes, "work_ms": 1000 * work,
            "write_ms": 1000 * statistics.fmean(p["write_s"] for p in per),
            "overhead_ms": 1000 * (runner["frames_wall_s"] * processes / n - work),
            "driver_ms": 1000 * runner["driver_s_per_frame"] if "driver_s_per_frame" in runner else None,
            "setup_s": summary["timings"]["setup_s"], "moda": summary.get("scores", {}).get("moda")}


def same_files(a: Path, b: Path) -> bool:
    if (a / "detections.csv").read_bytes() != (b / "detections.csv").read_bytes():
        return False
    return all((b / "maps" / m.name).read_bytes() == m.read_bytes() for m in (a / "maps").iterdir())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="configs/demo_people.yaml")
    ap.add_argument("--frames", type=int, help="render a sequence this long (default: the config's)")
    ap.add_argument("--workers", type=int, default=2, help="processes for --workers and actors for --ray")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--output", default="runs/scaleout")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    a = ap.parse_args()
    out = Path(a.output)
    sets = sets_for(a.config, a.frames) + a.set
    modes = {"one process": [], f"--workers {a.workers}": ["--workers", str(a.workers)],
             f"--ray ({a.workers} actors)": ["--ray", "--workers", str(a.workers)]}
    runs = {m: [] for m in modes}
    for i in range(a.repeats):  # modes in turn, so a slow spell of the machine hits them all
        for m, extra in modes.items():
            runs[m].append(run_mode(a.config, out / m.split()[0].strip("-"), extra, sets))
            print(f"repeat {i + 1}: {m}: {runs[m][-1]['frames_per_s']:.2f} frames/s", flush=True)
    base = out / "one"
    results = {}
    for m in modes:
        if not same_files(base, out / m.split()[0].strip("-")):
            raise SystemExit(f"{m}: detections.csv or maps differ from the one-process run")
        med = {k: statistics.median(r[k] for r in runs[m]) for k in runs[m][0]
               if runs[m][0][k] is not None}
        results[m] = med
    one = results["one process"]["frames_per_s"]
    lines = [f"{results['one process']['frames']} frames of {a.config} on {platform.machine()} "
             f"({os.cpu_count()} CPUs), median of {a.repeats}; same detections.csv and maps in every mode",
             "", "| mode | frames/s | vs one process | command s | work ms/frame | overhead ms/frame "
             "| driver ms/frame |", "|---|---|---|---|---|---|---|"]
    for m, r in results.items():
        lines.append(f"| {m} | {r['frames_per_s']:.2f} | {r['frames_per_s'] / one:.2f}x | "
                     f"{r['command_s']:.1f} | {r['work_ms']:.0f} | {r['overhead_ms']:.1f} | "
                     + (f"{r['driver_ms']:.1f} |" if "driver_ms" in r else "- |"))
    print("\n".join(lines))
    out.mkdir(parents=True, exist_ok=True)
    (out / "scaleout.json").write_text(json.dumps({"runs": runs, "medians": results}, indent=2))
    (out / "scaleout.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

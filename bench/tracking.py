"""Tracks on long rendered sequences: offline KSP, online, and the naive linking of the same
detections, scored with identities.

Each scene is a fresh rendered sequence (the people demo's camera unless it says otherwise)
of --frames frames at 15 fps, people walking 1.0 to 1.4 m/s to waypoints: they cross behind
each other, stop, leave the view and come back, and walk behind cabinets (hidden for a
while). Every scene is inferred once (background frames, fast path); the tracks of both
methods are computed from the same maps, the naive baseline links the same detections.

    python -m bench.tracking [--frames 75] [--jobs 2] [--output runs/tracking] [--tuning]
                             [--set tracking.KEY=VALUE ...] [--infer-set KEY=VALUE ...] [--retrack]

--tuning: another draw (seeds + 1000, cached apart) for choosing tracking defaults; the
README reports the draw above, on which no parameter was chosen. --infer-set overrides the
inference of every scene (a model default measured on whole sequences: people entering and
leaving the view); --set only the tracking.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from bench.robustness import slug_of

FRAMES = 75  # frames a scene
COMMON = ["synthetic.motion=paths", "synthetic.step_m=0.08", "input.fps=15"]
SCENES = {
    "6 people crossing": ["synthetic.people=6"],
    "6 people, leaving and coming back": ["synthetic.people=6", "synthetic.area=[-1.5, 1.5, 1.5, 5.5]",
                                          "synthetic.leave=2.0"],
    "5 people, two cabinets": ["synthetic.people=5", "synthetic.obstacles=2"],
    "crowd of 8, 0.5 m apart": ["synthetic.people=8", "synthetic.min_gap=0.5",
                                "synthetic.area=[-1.8, 1.8, 2.2, 5.8]"],
    "ceiling 3.0 m, pitch 90, 4 people": [
        "camera.extrinsics.pitch_deg=90", "camera.extrinsics.y=4.0", "camera.extrinsics.height=3.0",
        "grid.x=[-1.8, 1.8, 0.1]", "grid.y=[2.4, 5.6, 0.1]", "synthetic.in_view=head",
        "synthetic.people=4", "synthetic.area=[-1.2, 1.2, 3.0, 5.0]", "synthetic.leave=0.6"],
}


def scene_sets(name: str, frames: int, tuning: bool) -> list[str]:
    """The demo config's overrides for one tracking scene of one draw (its seed, its cached
    frames, background frames)."""
    seed = 11 + list(SCENES).index(name) + (1000 if tuning else 0)
    cache = Path(".cache") / ("tracking_tuning" if tuning else "tracking") / f"{slug_of(name)}_{frames}"
    return COMMON + SCENES[name] + [
        f"synthetic.seed={seed}", f"synthetic.frames={frames}",
        f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
        f"input.background={cache}/background/*.png",
        f"evaluation.ground_truth={cache}/ground_truth.json", "output.images=false"]


def run_scene(args):
    name, infer_sets, frames, out, extra, tuning, again = args
    import os

    os.environ.setdefault("WARP_CACHE_PATH", str(Path(".cache") / f"warp-{os.getpid()}"))
    from dpom_warp.loading import load_config
    from dpom_warp.pipeline import retrack, run

    slug = slug_of(name)
    cfg = load_config("configs/demo_people.yaml", scene_sets(name, frames, tuning) + ["tracking.method=ksp"]
                      + list(infer_sets))
    run_dir = Path(out) / slug
    if again and (run_dir / "summary.json").exists():  # --retrack: the maps of an earlier run
        summary = json.loads((run_dir / "summary.json").read_text())
    else:
        summary = run(cfg, str(run_dir), "cpu", progress=False, log=lambda *_: None, overwrite=True)
    sc = summary["scores"]
    result = {"moda": sc["moda_visible"], "n_gt": sc["n_gt"], "frames": summary["frames"],
              "infer_s": summary["timings"]["median_infer_s"]}
    for method in ("ksp", "online"):
        rep = retrack(run_dir, [f"tracking.method={method}", *extra], log=lambda *_: None)
        ev = json.loads((run_dir / "eval.json").read_text())[0]["tracking"]
        result[method] = {"report": rep, "scores": ev["tracks"]}
        result["naive"] = {"scores": ev["naive"]}
    return name, result


def long_run(run_dir: Path, frames: int, extra=()) -> dict:
    """Tracking cost on a long run: a scene's maps played forwards then backwards (a
    continuous sequence) up to `frames` frames, read from disk as the windows need them,
    tracked by both methods after a warm-up: time per frame, the largest graph, and the
    memory the tracker holds at its peak (Python's allocations, tracemalloc, in a second
    pass: maps kept for two windows, the graph, the tracks)."""
    import tracemalloc

    from dpom_warp.config import apply_overrides, parse_config
    from dpom_warp.geometry import build_geometry
    from dpom_warp.tracking import Cells, FrameMaps, run_tracker

    summary = json.loads((run_dir / "summary.json").read_text())
    cfg = parse_config(apply_overrides(summary["config"], list(extra)))
    paths = sorted((run_dir / "maps").glob("*.npy"))
    order = paths + paths[::-1]
    seq = [order[i % len(order)] for i in range(frames)]
    geometry = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    cells = Cells.for_run(geometry, cfg)
    out = {"frames": frames, "window": cfg.tracking.window, "overlap": cfg.tracking.overlap,
           "grid_cells": len(cells.positions)}
    for method, n in (("ksp", frames), ("online", min(frames, 3000))):
        def track(m):
            return run_tracker(FrameMaps(seq[:m], keep=2 * cfg.tracking.window), cells, cfg.grid.shape,
                               cfg.tracking, cfg.inputs.fps, cfg.detection.threshold, method)

        track(min(n, 2 * cfg.tracking.window))  # warm-up: imports, first allocations
        runs = [track(n) for _ in range(3)]
        tracemalloc.start()
        track(min(n, 4 * cfg.tracking.window))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        reps = sorted((r[1] for r in runs), key=lambda r: r["ms_per_frame"])
        out[method] = {"frames": n, "ms_per_frame": reps[1]["ms_per_frame"], "tracks": len(runs[0][0]),
                       "max_nodes": reps[1]["max_nodes"], "max_arcs": reps[1]["max_arcs"],
                       "peak_mb": peak / 2 ** 20}
    return out


POOLED = ("num_switches", "num_false_positives", "num_misses", "num_objects", "person_frames")


def pooled(results: dict, who: str, gate: str, protocol: str = "ignore_hidden") -> dict:
    """Scores over every scene's person-frames: MOTA from the summed counts, IDF1 and HOTA
    weighted by person-frames (each scene is scored on its own identities)."""
    rows = [r[who]["scores"][protocol][gate] for r in results.values()]
    tot = {k: sum(r[k] for r in rows) for k in POOLED}
    n = max(1, tot["num_objects"])
    mota = 1.0 - (tot["num_misses"] + tot["num_false_positives"] + tot["num_switches"]) / n
    w = [r["num_objects"] for r in rows]
    avg = {k: sum(r[k] * x for r, x in zip(rows, w)) / max(1, sum(w)) for k in ("idf1", "hota", "motp")}
    return {"mota": mota, **avg, "num_switches": tot["num_switches"],
            "switches_per_500": 500.0 * tot["num_switches"] / max(1, tot["person_frames"]),
            "person_frames": tot["person_frames"]}


def table(results: dict, gate: str = "0.5") -> list[str]:
    """Per scene and pooled: the detections' MODA (hidden people ignored, as the tracks'
    scores), the KSP tracks' own MODA (their positions, identities aside), then MOTA, IDF1,
    HOTA and identity switches of KSP, online and the naive linking."""
    lines = ["| scene | person-frames | detections MODA | tracks MODA | KSP MOTA | IDF1 | HOTA | ID sw. "
             "| online MOTA | IDF1 | ID sw. | naive MOTA | IDF1 | ID sw. |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    scenes = {n: r for n, r in results.items() if n != "long"}

    def track_moda(s):
        return 1.0 - (s["num_misses"] + s["num_false_positives"]) / max(1, s["num_objects"])

    for name, r in list(scenes.items()) + [("**pooled**", None)]:
        if r is None:
            k, o, nv = (pooled(scenes, w, gate) for w in ("ksp", "online", "naive"))
            rows = [x["ksp"]["scores"]["ignore_hidden"][gate] for x in scenes.values()]
            n = sum(x["n_gt"] for x in scenes.values())
            moda = f"{sum(x['moda'] * x['n_gt'] for x in scenes.values()) / max(1, n):.3f}"
            tmoda = 1.0 - sum(x["num_misses"] + x["num_false_positives"] for x in rows) / max(
                1, sum(x["num_objects"] for x in rows))
            pf = k["person_frames"]
        else:
            k, o, nv = (r[w]["scores"]["ignore_hidden"][gate] for w in ("ksp", "online", "naive"))
            pf, moda = k["person_frames"], f"{r['moda']:.3f}"
            tmoda = track_moda(k)
        lines.append(f"| {name} | {pf} | {moda} | {tmoda:.3f} | {k['mota']:.3f} | {k['idf1']:.3f} | {k['hota']:.3f} "
                     f"| {k['num_switches']} | {o['mota']:.3f} | {o['idf1']:.3f} | {o['num_switches']} "
                     f"| {nv['mota']:.3f} | {nv['idf1']:.3f} | {nv['num_switches']} |")
    return lines


def _mb(x):
    return f"{x:.1f} MB"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=FRAMES)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--output", default="runs/tracking")
    ap.add_argument("--tuning", action="store_true", help="the tuning draw (seeds + 1000)")
    ap.add_argument("--set", action="append", default=[], metavar="tracking.KEY=VALUE",
                    help="tracking override for both methods")
    ap.add_argument("--infer-set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="config override for every scene's run (inference)")
    ap.add_argument("--retrack", action="store_true",
                    help="track the maps of the scenes' earlier runs again instead of inferring")
    ap.add_argument("--long", type=int, default=10000, metavar="FRAMES",
                    help="also time both methods on a run this long (the first scene's maps "
                         "played back and forth; 0: no)")
    a = ap.parse_args()
    jobs = [(n, a.infer_set, a.frames, a.output + ("_tuning" if a.tuning else ""), a.set, a.tuning, a.retrack)
            for n in SCENES]
    with ProcessPoolExecutor(a.jobs) as pool:
        results = dict(pool.map(run_scene, jobs))
    lines = table(results)
    out = Path(a.output + ("_tuning" if a.tuning else ""))
    if a.long:
        first = out / slug_of(next(iter(SCENES)))
        results["long"] = long_run(first, a.long, a.set)
        lo = results["long"]
        lines += ["", f"Long run (the first scene's maps back and forth, read from disk as needed): KSP "
                      f"{lo['ksp']['ms_per_frame']:.2f} ms a frame over {lo['ksp']['frames']} frames in "
                      f"windows of {lo['window']} (overlap {lo['overlap']}; at most {lo['ksp']['max_nodes']} "
                      f"nodes, {lo['ksp']['max_arcs']} arcs), online {lo['online']['ms_per_frame']:.2f} ms a "
                      f"frame over {lo['online']['frames']} frames "
                      f"(at most {lo['online']['max_nodes']} nodes); memory the tracker holds at its peak "
                      f"(Python allocations: maps of two windows, graph, tracks; {lo['grid_cells']} cells): "
                      f"{_mb(lo['ksp']['peak_mb'])} (KSP), {_mb(lo['online']['peak_mb'])} (online); "
                      f"median of 3 runs after a warm-up, one core."]
    print("\n".join(lines))
    out.mkdir(parents=True, exist_ok=True)
    (out / "tracking.json").write_text(json.dumps(results, indent=2, default=float))
    (out / "tracking.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

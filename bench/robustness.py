"""Do the demo's defaults hold on scenes they were not tuned on?

Runs the people demo config over synthetic variants (other seeds, camera heights and tilts,
crowd sizes, crowds 0.45 m apart, ceiling cameras at pitch 45 to 90 over tables), each a fresh
rendered sequence, and reports MODA / precision / recall at 0.5 m.

    python -m bench.robustness [--frames 10] [--jobs 2] [--output runs/robustness]
                               [--background frames|auto|floor] [--set key.path=value ...] [--name NAME]
                               [--tuning] [--device cpu|cuda:N] [--no-baseline]

--background: the empty room's frames (default), `input.background: auto` (estimated from the
variant's own frames), or the floor-only model (`--floor-only` is the same).

`--set` applies config overrides to every variant (e.g. `--set engine.exact=true` for the
exact path); results go to OUTPUT/NAME.json and .md. `--tuning` runs another draw of every
scene (seeds + 1000), on which the model's defaults were chosen; the tables report the draw
above, which no parameter was chosen on. `--device cuda:0` runs the variants' inference on a GPU
(the same table, to compare a GPU's detections with the CPU's); `--no-baseline` leaves out the
clustering baseline's column (it needs Open3D).
"""

from __future__ import annotations

import argparse
import json
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PLANE = ["object.shape=plane", "object.width=0.5", "model.top_support=0.05"]  # the paper's model, its own defaults
CEILING_90 = ["camera.extrinsics.pitch_deg=90", "camera.extrinsics.y=4.0", "grid.x=[-1.8, 1.8, 0.1]",
              "grid.y=[2.4, 5.6, 0.1]", "synthetic.in_view=head"]
DRIFT = "synthetic.drift=[0.012, 0.2, 0.025, 0.035]"
VARIANTS = {
    "seed 1": [],
    "seed 2": [],
    "seed 3": [],
    "camera 1.8 m, pitch 15": ["camera.extrinsics.height=1.8", "camera.extrinsics.pitch_deg=15"],
    "camera 2.8 m, pitch 30": ["camera.extrinsics.height=2.8", "camera.extrinsics.pitch_deg=30"],
    "roll 4 deg": ["camera.extrinsics.roll_deg=4"],
    "3 people": ["synthetic.people=3"],
    "8 people": ["synthetic.people=8"],
    "side by side 0.45 m": ["synthetic.people=6", "synthetic.pair_gap=0.45"],
    # crowds: people as close as 0.45 m, hiding each other
    "crowd of 10, 0.45 m apart": ["synthetic.people=10", "synthetic.min_gap=0.45",
                                  "synthetic.area=[-1.6, 1.6, 2.5, 5.5]"],
    "crowd of 12, camera 2.6 m": ["synthetic.people=12", "synthetic.min_gap=0.45",
                                  "synthetic.area=[-2.0, 2.0, 2.0, 6.0]", "camera.extrinsics.height=2.6",
                                  "camera.extrinsics.pitch_deg=25"],
    # ceiling cameras: the head must be in view (the feet often are not), tables in the room
    "ceiling 3.0 m, pitch 90": [*CEILING_90, "camera.extrinsics.height=3.0", "synthetic.people=3",
                                "synthetic.area=[-1.2, 1.2, 3.0, 5.0]"],
    "ceiling 3.5 m, pitch 90, yaw 30": [*CEILING_90, "camera.extrinsics.height=3.5", "camera.extrinsics.yaw_deg=30",
                                        "synthetic.people=5", "synthetic.tables=1",
                                        "synthetic.area=[-1.5, 1.5, 2.7, 5.3]"],
    "ceiling 2.6 m, pitch 45": ["synthetic.in_view=head", "camera.extrinsics.height=2.6",
                                "camera.extrinsics.pitch_deg=45", "camera.extrinsics.y=0.5",
                                "grid.x=[-2.4, 2.4, 0.1]", "grid.y=[0.6, 4.0, 0.1]", "synthetic.people=4",
                                "synthetic.tables=1", "synthetic.area=[-1.8, 1.8, 1.0, 3.4]"],
    "ceiling 3.2 m, pitch 45, yaw -40, 8 people": [
        "synthetic.in_view=head", "camera.extrinsics.height=3.2", "camera.extrinsics.pitch_deg=45",
        "camera.extrinsics.yaw_deg=-40", "camera.extrinsics.x=-3.0", "synthetic.people=8",
        "synthetic.tables=2", "synthetic.area=[-2.5, 2.5, 1.5, 6.5]"],
    # walls, two cabinets and a table inside the grid (issue 60: without empty-room frames, structure
    # is what floor-only and auto must not take for people)
    "walls, cabinets, table in the grid": ["synthetic.room=[-2.6, 2.6, -0.5, 6.6, 3.0]",
                                           "synthetic.area=[-2.0, 2.0, 1.5, 6.0]", "synthetic.obstacles=2",
                                           "synthetic.tables=1"],
    # frame-wide depth drift (issue 60): every frame's depths, the empty room's too, x 1 + N(0, 1.2 %),
    # a fifth of them jumping 2.5 to 3.5 % either way (a time-of-flight camera's temperature steps)
    "drift 1.2 %, jumps 3 %": [DRIFT],
    "drift, camera 1.8 m, pitch 15": [DRIFT, "camera.extrinsics.height=1.8", "camera.extrinsics.pitch_deg=15"],
    "drift, ceiling 3.0 m, pitch 90": [DRIFT, *CEILING_90, "camera.extrinsics.height=3.0", "synthetic.people=3",
                                       "synthetic.area=[-1.2, 1.2, 3.0, 5.0]"],
}

BACKGROUNDS = {"frames": "background frames", "auto": "background estimated from the frames (auto)",
               "floor": "floor-only background"}


def slug_of(name: str) -> str:
    return name.replace(" ", "_").replace(",", "").replace(".", "")


def scene_sets(name: str, overrides: list[str], frames: int, background: str, tuning: bool) -> list[str]:
    """The demo config's overrides for one scene of one draw (its seed, its cached frames)."""
    seed = (int(name.split()[1]) if name.startswith("seed") else 100) + (1000 if tuning else 0)
    cache = Path(".cache") / ("robustness_tuning" if tuning else "robustness") / slug_of(name)
    return overrides + [f"synthetic.seed={seed}", f"synthetic.frames={frames}",
                        f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
                        {"frames": f"input.background={cache}/background/*.png", "auto": "input.background=auto",
                         "floor": "input.background=null"}[background],
                        f"evaluation.ground_truth={cache}/ground_truth.json", "output.images=false"]


def run_variant(args):
    name, overrides, frames, out, background, extra = args[:6]
    tuning = len(args) > 6 and args[6]
    device = args[7] if len(args) > 7 else "cpu"
    baseline = len(args) <= 8 or args[8]
    import os

    os.environ.setdefault("WARP_CACHE_PATH", str(Path(".cache") / f"warp-{os.getpid()}"))
    from dpom_warp.loading import load_config
    from dpom_warp.pipeline import run

    slug = slug_of(name)
    sets = scene_sets(name, overrides, frames, background, tuning) + list(extra)
    cfg = load_config("configs/demo_people.yaml", sets)
    tag = "_".join(x.replace("/", "-") for x in extra)
    summary = run(cfg, str(Path(out) / slug / ({"frames": "bg"}.get(background, background) + tag)), device,
                  progress=False, log=lambda *_: None, overwrite=True)
    s = summary["scores"]
    result = {k: s[k] for k in ("moda", "precision", "recall", "mean_error_m", "n_gt")} | {
        "median_frame_s": summary["timings"]["median_infer_s"],
        "median_iterations": summary["timings"]["median_iterations"],
        "median_entries": summary["timings"]["median_entries"],
        "median_kept_entries": summary["timings"]["median_kept_entries"],
        "stride": summary["inference"]["stride"]}
    if baseline and background == "frames" and not extra:  # the same frames through the clustering baseline
        from bench.baseline import score_config

        b = score_config(cfg)
        result["baseline"] = {k: b[k] for k in ("moda", "precision", "recall", "mean_error_m")}
    return name, result


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--output", default="runs/robustness")
    ap.add_argument("--background", choices=("frames", "auto", "floor"), default="frames",
                    help="background frames, estimated from the frames, or the floor only")
    ap.add_argument("--floor-only", action="store_true", help="the same as --background floor")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="config override for every variant")
    ap.add_argument("--name", help="results file name (default robustness or robustness_floor)")
    ap.add_argument("--tuning", action="store_true",
                    help="the tuning draw: every scene with seed + 1000 (cached apart), for choosing "
                         "parameters without looking at the reported scenes")
    ap.add_argument("--device", default="cpu", help="the variants' inference device: cpu or cuda:N")
    ap.add_argument("--no-baseline", action="store_true", help="leave out the clustering baseline (needs Open3D)")
    a = ap.parse_args()
    background = "floor" if a.floor_only else a.background
    jobs = [(n, o, a.frames, a.output, background, a.set, a.tuning, a.device, not a.no_baseline)
            for n, o in VARIANTS.items()]
    with ProcessPoolExecutor(a.jobs) as pool:
        results = dict(pool.map(run_variant, jobs))
    lines = ["| scene | people | MODA | precision | recall | mean error (m) | stride | median s/frame "
             "| iterations | entries | left after the bound | clustering baseline MODA |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for n, r in results.items():
        base = f"{r['baseline']['moda']:.3f}" if "baseline" in r else "-"
        kept = r["median_kept_entries"]
        kept = f"{kept:.0f} ({kept / r['median_entries']:.0%})" if kept is not None else "-"
        lines.append(f"| {n} | {r['n_gt']} | {r['moda']:.3f} | {r['precision']:.3f} | {r['recall']:.3f} "
                     f"| {r['mean_error_m']:.3f} | {r['stride']} | {r['median_frame_s']:.3f} "
                     f"| {r['median_iterations']:.0f} | {r['median_entries']:.0f} | {kept} | {base} |")
    modas = [r["moda"] for r in results.values()]
    lines.append(f"\nMODA over {len(modas)} variants: median {statistics.median(modas):.3f}, "
                 f"min {min(modas):.3f}, max {max(modas):.3f} "
                 f"({BACKGROUNDS[background]}"
                 f"{'; ' + ', '.join(a.set) if a.set else ''}; device {a.device})")
    print("\n".join(lines))
    Path(a.output).mkdir(parents=True, exist_ok=True)
    name = a.name or {"frames": "robustness", "auto": "robustness_auto", "floor": "robustness_floor"}[background]
    (Path(a.output) / f"{name}.json").write_text(json.dumps(results, indent=2))
    (Path(a.output) / f"{name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

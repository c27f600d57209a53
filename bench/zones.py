"""Where people go, measured (issue 62): rendered sequences of six people walking, crossing and
passing behind two free-standing cabinets (the people demo's camera and model), run with two
zones and two counting lines; zones.csv and crossings.csv against the truth computed here from
the rendered people's positions (rectangles and sign changes, by hand: not zones.py), beside the
naive alternative, each frame's raw detections counted in the zone; and the bookkeeping's cost a
frame with 20 zones and 20 lines (zones.Zones.update on the run's own tracks).

    python -m bench.zones [--frames 60] [--seeds 1 2] [--output runs/zones] [--set KEY.PATH=VALUE ...]

--set: config overrides for the runs (as `dpom-warp run --set`), e.g. a finer grid.

The truth is the renderer's trajectories (trajectories.json: every person every frame, hidden
behind a cabinet or another person or not). Writes OUTPUT/zones.md and zones.json (bench.docs --only zones puts the table in the README)."""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import time
from pathlib import Path

import numpy as np

ZONES = {"left": (-3.0, 0.0, 0.5, 7.0), "back": (-1.5, 1.5, 4.0, 7.0)}  # x0, x1, y0, y1
HYSTERESES = (0.0, 0.05, 0.1, 0.15, 0.2)  # counting.hysteresis values the crossings are counted again at
LINES = {"middle": ((0.0, 0.5), (0.0, 7.0)), "across": ((-3.0, 4.0), (3.0, 4.0))}


def config(folder: Path, frames: int, seed: int) -> list[str]:
    """--set items: the demo, six people, two cabinets, the zones and lines."""
    zones = [{"name": n, "polygon": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]} for n, (x0, x1, y0, y1) in ZONES.items()]
    lines = [{"name": n, "from": list(a), "to": list(b)} for n, (a, b) in LINES.items()]
    scene = folder / "scene"
    return [f"synthetic.cache={scene}", f"synthetic.frames={frames}", f"synthetic.seed={seed}", "synthetic.people=6",
            "synthetic.obstacles=2", "synthetic.area=[-2.5, 2.5, 1.5, 6.5]", f"input.frames={scene}/frames/*.png",
            f"input.background={scene}/background/*.png", f"evaluation.ground_truth={scene}/ground_truth.json",
            f"output.dir={folder / 'out'}", "output.images=false", f"zones={json.dumps(zones)}",
            f"lines={json.dumps(lines)}"]


def truth_counts(truth: list) -> dict:
    """{(frame, zone): people inside}, by the rectangles."""
    return {(f["frame"], n): sum(x0 <= o["x"] <= x1 and y0 <= o["y"] <= y1 for o in f["objects"])
            for f in truth for n, (x0, x1, y0, y1) in ZONES.items()}


def truth_crossings(truth: list) -> list[tuple[int, str, str]]:
    """(frame, line, direction) each time a person changes side of a line from one frame to the
    next, within its segment (where the step meets the line)."""
    out, last = [], {}
    for f, frame in enumerate(truth):
        for o in frame["objects"]:
            p = np.array([o["x"], o["y"]])
            if o["id"] in last and last[o["id"]][0] == f - 1:
                q = last[o["id"]][1]
                for n, (a, b) in LINES.items():
                    a, b = np.array(a), np.array(b)
                    d = b - a
                    s0, s1 = (d[0] * (x[1] - a[1]) - d[1] * (x[0] - a[0]) for x in (q, p))
                    if (s0 > 0) != (s1 > 0) and s0 != s1:
                        at = q + (p - q) * s0 / (s0 - s1)  # where the step meets the line
                        t = (at - a) @ d / (d @ d)
                        if 0 <= t <= 1:
                            out.append((f, n, "in" if s1 > 0 else "out"))
            last[o["id"]] = (f, p)
    return out


def match(got: list, want: list, frames: int = 3) -> tuple[float, float]:
    """Precision and recall: a crossing matches one of the same line and direction within `frames`."""
    left, found = list(got), 0
    for f, n, d in want:
        m = next((g for g in left if g[1] == n and g[2] == d and abs(g[0] - f) <= frames), None)
        if m is not None:
            left.remove(m)
            found += 1
    return found / max(len(got), 1), found / max(len(want), 1)


def bookkeeping_ms(out: Path, repeats: int = 3) -> float:
    """Median ms a frame of zones.Zones.update with 20 zones and 20 lines over the run's tracks."""
    from dpom_warp.zones import Line, Zone, Zones

    rows = {}
    for r in csv.DictReader(open(out / "tracks.csv")):
        rows.setdefault(r["frame"], []).append((int(r["track"]), (float(r["x"]), float(r["y"]), 0.0), r["bridged"] == "1"))
    frames = [rows.get(f, []) for f in sorted(rows)]
    rng = np.random.default_rng(0)
    zones = [Zone(f"z{i}", np.array([[x, y], [x + 1, y], [x + 1, y + 1], [x, y + 1]]))
             for i, (x, y) in enumerate(rng.uniform([-3, 0.5], [2, 6], (20, 2)))]
    lines = [Line(f"l{i}", a, b) for i, (a, b) in enumerate(zip(rng.uniform([-3, 0.5], [3, 7], (20, 2)),
                                                                   rng.uniform([-3, 0.5], [3, 7], (20, 2))))]
    times = []
    for _ in range(repeats):
        z = Zones(zones, lines, 0.1, 5.0)
        t = time.perf_counter()
        for i, f in enumerate(frames):
            z.update(i, f)
        times.append(1000 * (time.perf_counter() - t) / max(len(frames), 1))
    return statistics.median(times)


def crossings_at(out: Path, truth: list, hysteresis: float) -> tuple[float, float]:
    """Precision and recall of the run's crossings counted again (dpom-warp track) at `hysteresis`."""
    from dpom_warp.pipeline import retrack

    retrack(out, [f"counting.hysteresis={hysteresis}"], log=lambda *_: None)
    names = {f["frame"]: i for i, f in enumerate(truth)}
    got = [(names[r["frame"]], r["line"], r["direction"]) for r in csv.DictReader(open(out / "crossings.csv"))]
    return match(got, truth_crossings(truth))


def run_seed(folder: Path, frames: int, seed: int, sets: list[str] = ()) -> dict:
    from dpom_warp.loading import load_config
    from dpom_warp.pipeline import run

    cfg = load_config("configs/demo_people.yaml", config(folder, frames, seed) + list(sets))
    run(cfg, str(folder / "out"), progress=False, log=lambda *_: None, overwrite=True)
    out = folder / "out"
    truth = json.loads((folder / "scene" / "trajectories.json").read_text())
    want = truth_counts(truth)
    rows = list(csv.DictReader(open(out / "zones.csv")))
    exact = float(np.mean([int(r["count"]) == want[(r["frame"], r["zone"])] for r in rows]))
    dets = {}
    for r in csv.DictReader(open(out / "detections.csv")):
        for n, (x0, x1, y0, y1) in ZONES.items():
            key = (r["frame"], n)
            dets[key] = dets.get(key, 0) + (x0 <= float(r["x"]) <= x1 and y0 <= float(r["y"]) <= y1)
    naive = float(np.mean([dets.get(k, 0) == v for k, v in want.items()]))
    names = {f["frame"]: i for i, f in enumerate(truth)}
    got = [(names[r["frame"]], r["line"], r["direction"]) for r in csv.DictReader(open(out / "crossings.csv"))]
    true = truth_crossings(truth)
    precision, recall = match(got, true)
    sweep = {h: crossings_at(out, truth, h) for h in HYSTERESES}
    crossings_at(out, truth, cfg.counting.hysteresis)  # (the run's files as the run made them)
    return {"seed": seed, "frames": frames, "rows": len(rows), "counts_exact": exact, "naive_exact": naive,
            "crossings_true": len(true), "crossings_found": len(got), "precision": precision, "recall": recall,
            "hysteresis": cfg.counting.hysteresis, "sweep": {str(h): v for h, v in sweep.items()},
            "bookkeeping_ms": bookkeeping_ms(out)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--output", default="runs/zones")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="a config override for the runs (repeatable)")
    args = ap.parse_args()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    results = [run_seed(Path(".cache/bench") / f"zones_{s}_{args.frames}", args.frames, s, args.set) for s in args.seeds]
    (out / "zones.json").write_text(json.dumps(results, indent=1))
    rows = ["| sequence | frame-zone rows | counts exact: tracks | counts exact: raw detections (naive) | "
            "crossings true / found | precision | recall | bookkeeping, 20 zones + 20 lines |",
            "|---|---|---|---|---|---|---|---|"]
    for r in results:
        rows.append(f"| seed {r['seed']}, {r['frames']} frames, 6 people, 2 cabinets | {r['rows']} | "
                    f"**{r['counts_exact']:.3f}** | {r['naive_exact']:.3f} | {r['crossings_true']} / "
                    f"{r['crossings_found']} | {r['precision']:.2f} | {r['recall']:.2f} | "
                    f"{r['bookkeeping_ms']:.2f} ms a frame |")
    rows += ["", "Crossings' precision / recall with other counting.hysteresis (the same tracks, `dpom-warp track`):", "",
             "| sequence | " + " | ".join(f"{h} m" for h in HYSTERESES) + " |", "|---|" + "---|" * len(HYSTERESES)]
    for r in results:
        rows.append(f"| seed {r['seed']} | " + " | ".join(f"{p:.2f} / {c:.2f}" for p, c in r["sweep"].values()) + " |")
    text = "\n".join(rows)
    (out / "zones.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()

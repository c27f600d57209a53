"""Does `extrinsics: auto` find the floor at every mounting of the robustness tables?

For each robustness scene (both draws: held-out and tuning), fits the floor on the scene's
first empty-room frames with the default `camera.ground` but `up`, once per `--up` (default:
auto, and 0,-1,0, the image's up, the default before auto), and compares the pose with the one
the scene was rendered from.

    python -m bench.ground [--up auto|X,Y,Z ...] [--output runs/ground]

Prints one row per scene (height and normal errors; the warning or the error, if any) and a
summary per `up`, and writes OUTPUT/ground.json and ground.md (the README's ground block).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np


def fit_scene(name: str, overrides: list[str], tuning: bool, up="auto") -> dict:
    """Render (or check) the scene's frames and fit its floor with the default options but `up`."""

    from bench.robustness import scene_sets
    from dpom_warp.loading import load_config
    from dpom_warp.ground import fit_ground_files
    from dpom_warp.io import InputError
    from dpom_warp.frames import render_synthetic

    cfg = load_config("configs/demo_people.yaml", scene_sets(name, overrides, 10, "frames", tuning))
    render_synthetic(cfg, log=lambda *_: None)
    files = sorted(Path(cfg.synthetic_cache, "background").glob("*.png"))[: cfg.ground_frames]
    camera = cfg.camera
    true = camera.T_world_from_camera
    row = {"scene": name, "draw": "tuning" if tuning else "held-out", "height_m": float(true[2, 3])}
    try:
        fit = fit_ground_files(files, camera, cfg.inputs.depth_scale, cfg.ground.model_copy(update={"up": up}))
    except InputError as e:
        return row | {"error": str(e)}
    up_true = true[2, :3]  # world z in camera coordinates: the true floor normal
    angle = math.degrees(math.acos(float(np.clip(up_true @ fit.normal, -1, 1))))
    return row | {"fitted_height_m": fit.camera_height, "height_error_m": fit.camera_height - float(true[2, 3]),
            "normal_error_deg": angle, "pitch_deg": fit.pitch_deg, "ambiguity": fit.ambiguity}


def summary(rows: list[dict], up: str) -> dict:
    fitted = [r for r in rows if "error" not in r]
    right = [r for r in fitted if abs(r["height_error_m"]) < 0.02 and r["normal_error_deg"] < 0.5]
    return {"up": up, "scenes": len(rows), "right": len(right), "errors": len(rows) - len(fitted),
            "worst_height_mm": 1000 * max((abs(r["height_error_m"]) for r in right), default=0.0),
            "worst_normal_deg": max((r["normal_error_deg"] for r in right), default=0.0),
            "warnings": sum(bool(r["ambiguity"]) for r in fitted)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--up", nargs="+", default=["auto", "0,-1,0"], help="camera.ground.up: auto or X,Y,Z")
    parser.add_argument("--output", default="runs/ground")
    args = parser.parse_args()
    from bench.robustness import VARIANTS

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    results, table = {}, ["| `camera.ground.up` | floor within 2 cm and 0.5 deg | no floor found (error) | "
                          "worst height error | worst normal error | warnings |", "|---|---|---|---|---|---|"]
    for text in args.up:
        up = text if text == "auto" else tuple(float(v) for v in text.split(","))
        rows = [fit_scene(name, overrides, tuning, up) for tuning in (False, True)
                for name, overrides in VARIANTS.items()]
        for r in rows:
            head = f"{r['draw']:8s} {r['scene']:45s} height {r['height_m']:.2f} m"
            if "error" in r:
                print(f"{head}: {r['error']}")
                continue
            print(f"{head}, fitted {r['fitted_height_m']:.4f} m ({1000 * r['height_error_m']:+.1f} mm), normal "
                  f"{r['normal_error_deg']:.2f} deg off" + (f"; warning: {r['ambiguity']}" if r["ambiguity"] else ""))
        s = summary(rows, text)
        results[text] = {"summary": s, "rows": rows}
        table.append(f"| `{text}` | {s['right']} of {s['scenes']} | {s['errors']} | {s['worst_height_mm']:.1f} mm | "
                     f"{s['worst_normal_deg']:.2f} deg | {s['warnings']} |")
        print(table[-1])
    (out / "ground.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "ground.md").write_text(
        f"The floor fitted on the first 5 empty-room frames of each robustness scene, both draws "
        f"({len(VARIANTS)} scenes each: eye level 1.8 to 2.8 m at pitch 15 to 30, ceiling 2.6 to 3.5 m at "
        f"pitch 45 to 90), against the pose it was rendered from:\n\n" + "\n".join(table) + "\n")


if __name__ == "__main__":
    main()

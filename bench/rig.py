"""What a rig of depth cameras gains over one (issue 61): rendered scenes seen by three cameras at
once, each scored as every camera alone, as detection-level fusion of those single runs (what
multi-camera trackers and body-tracking SDKs do: each camera decides, then detections within
0.4 m are merged, kept when one camera, or two, found them; the better of the two), and as the
rig's evidence fusion (one mean field over every camera's pixels); and the time of a rig frame
against one camera's, measured in the same process on the same frames.

    python -m bench.rig [--frames 10] [--output runs/rig] [--scenes rig3 rig3_tight] [--repeats 5]
                        [--tuning | --draw N] [--object-width 0.5] [--device cpu|cuda:N] [--batch N]
                        [--set KEY.PATH=VALUE ...] [--live FPS [--workers N ...]] [--calibrate]

Scenes (the same cameras' layout in each: one at the near end looking along the area, one on
each side looking across it; 256 x 212 pixels, Kinect v2's field of view):
- rig3: 16 people walking in 6 x 5 m, cameras 2.2 m up, pitched 20 degrees;
- rig3_tight: 26 people in 4.4 x 3.5 m, 0.5 m apart at least, cameras 1.9 m up, pitched 15:
  people hide each other from each camera (the issue's crowd).
--batch N adds the rig's throughput through Detector.detect_batch with engine.batch N (N rig
frames, every camera's, in one engine call; on a GPU, one launch), in rig frames and camera-frames
a second, and whether its detections are the frame-by-frame ones.
--set: config overrides (as `dpom-warp run --set`) for the rig, each camera alone and the batch.
--live FPS also plays each scene's rig frames through the live path at FPS (`dpom-warp run --play`:
every camera's frames sent at their rig frame's time, paired again as they arrive, the newest
inferred) with each --workers count: rig frames a second once running, the share dropped, the
latency, and whether every map written is the recorded rig's (the pairing right).
A second table scores the same detections without the people under 10 % visible from every camera
(the issue's held-out crowd has none; `dpom-warp eval`'s moda_visible).
--calibrate also places each scene's cameras with no pose given (calibrate.place_cameras on its
background and walking frames) and scores the rig with those poses (`calibration`).
The tables go to OUTPUT/rig.md and rig.json (bench.docs --only rig puts them in the README).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from dpom_warp.config.rig import RIG_WIDTH

CAMERA = {"width": 256, "height": 212, "intrinsics": {"fx": 182.5, "fy": 182.5, "cx": 127.5, "cy": 105.5}}
WIDTH = RIG_WIDTH  # object.width (a rig's default), metres: chosen on the tuning draw (--tuning; docs/rig.md)
MERGE = 0.4  # metres: detection-level fusion merges detections closer than this
SEEN = 0.1  # "seen": visible this much from some camera (the held-out crowd: everyone is)


def layout(height: float, pitch: float, area) -> dict:
    """The three cameras around `area` (x0, x1, y0, y1): near end, left side, right side."""
    x0, x1, y0, y1 = area
    mid = (y0 + y1) / 2
    return {"near": {"height": height, "pitch_deg": pitch, "x": 0.0, "y": y0 - 1.6},
            "left": {"height": height, "pitch_deg": pitch, "yaw_deg": -90.0, "x": x0 - 1.6, "y": mid},
            "right": {"height": height, "pitch_deg": pitch, "yaw_deg": 90.0, "x": x1 + 1.6, "y": mid}}


SCENES = {
    "rig3": dict(height=2.2, pitch=20.0, area=(-3.0, 3.0, 2.0, 7.0), people=16, min_gap=0.6, seed=11),
    "rig3_tight": dict(height=1.9, pitch=15.0, area=(-2.2, 2.2, 2.75, 6.25), people=26, min_gap=0.5, seed=12),
}


def rig_config(name: str, folder: Path, frames: int, draw: int = 0, width: float = WIDTH,
               device: str = "cpu") -> dict:
    """The scene's rig config (its frames rendered into folder/scene); `draw`: added to the
    scene's seed (0: the reported draw, 1000: the tuning draw), `width`: the object's."""
    s = SCENES[name]
    x0, x1, y0, y1 = s["area"]
    scene = folder / "scene"
    poses = layout(s["height"], s["pitch"], s["area"])
    return {"device": device,
            "cameras": [{"name": n, "input": {"frames": f"{scene}/{n}/frames/*.png",
                                              "background": f"{scene}/{n}/background/*.png", "fps": 5},
                         "camera": {**CAMERA, "extrinsics": p}} for n, p in poses.items()],
            "grid": {"x": [x0 - 0.5, x1 + 0.5, 0.1], "y": [y0 - 0.5, y1 + 0.5, 0.1]},
            "object": {"width": width, "height": 1.85, "shape": "solid"},
            "evaluation": {"ground_truth": f"{scene}/ground_truth.json"},
            "output": {"dir": str(folder / "out"), "images": False},
            "tracking": {"method": "off"},
            "synthetic": {"cache": str(scene), "seed": s["seed"] + draw, "frames": frames, "background_frames": 5,
                          "people": s["people"], "min_gap": s["min_gap"], "area": list(s["area"]), "furniture": 0,
                          "room": [x0 - 2.0, x1 + 2.0, y0 - 2.0, y1 + 2.0, 3.0]}}


def fuse_detections(per_camera: list[dict], agree: int) -> dict:
    """Detection-level fusion: each frame's detections of every camera (name -> (n, 2)), strongest
    camera order kept, merged greedily within MERGE into one (their mean), kept where at least
    `agree` cameras found it."""
    out = {}
    for frame in per_camera[0]:
        groups = []  # [points, cameras]
        for c, dets in enumerate(per_camera):
            for p in dets.get(frame, np.zeros((0, 2))):
                near = [g for g in groups if np.linalg.norm(np.mean(g[0], axis=0) - p) < MERGE and c not in g[1]]
                if near:
                    near[0][0].append(p)
                    near[0][1].add(c)
                else:
                    groups.append(([p], {c}))
        out[frame] = np.array([np.mean(g[0], axis=0) for g in groups if len(g[1]) >= agree]).reshape(-1, 2)
    return out


def batched(run_cfg: dict, depths: list, batch: int, repeats: int, want: list, sets: list[str] = ()) -> dict:
    """The rig's frames (`run_cfg`: its config, rendered) through Detector.detect_batch with
    engine.batch = `batch`: rig frames and camera-frames a second (median of `repeats` passes
    over at least one full batch, after a warm-up pass), and whether each frame's detections are
    `want`'s (each frame's (n, 2), in order)."""
    from dpom_warp import Detector

    det = Detector.from_config({**run_cfg, "engine": {"batch": batch}}, list(sets))
    order = [i % len(depths) for i in range(max(batch, len(depths)))]
    frames = [depths[i] for i in order]
    got = det.detect_batch(frames)  # (the warm-up)
    same = all(np.array_equal(np.array([[x.x, x.y] for x in r.detections]).reshape(-1, 2), want[i])
               for r, i in zip(got, order))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        det.detect_batch(frames)
        times.append(time.perf_counter() - t)
    per = statistics.median(times) / len(frames)
    return {"batch": batch, "rig_frames_per_s": 1 / per, "camera_frames_per_s": len(depths[0]) / per,
            "same_detections": same}


def run_scene(name: str, folder: Path, frames: int, repeats: int, draw: int = 0, width: float = WIDTH,
              device: str = "cpu", batch: int = 0, sets: list[str] = ()) -> dict:
    from dpom_warp import Detector
    from dpom_warp.evaluate import load_ground_truth, score_frames
    from dpom_warp.frames import run_frames, render_synthetic
    from dpom_warp.loading import config_from_mapping
    from dpom_warp.worker import read_rig_frame

    raw = rig_config(name, folder, frames, draw, width, device)
    cfg = config_from_mapping(raw)
    render_synthetic(cfg, lambda *_: None)
    rig_frames = run_frames(cfg, log=lambda *_: None).frames
    truth = load_ground_truth(raw["evaluation"]["ground_truth"])
    depths = [read_rig_frame(cfg, f.paths) for f in rig_frames]
    names = cfg.camera_names
    run_cfg = {k: v for k, v in raw.items() if k != "synthetic"}  # rendered above
    rig = Detector.from_config(run_cfg, list(sets))
    stride = rig.engine.resolution.stride  # each camera alone at the rig's resolution
    singles = [Detector.from_config({**run_cfg,
                                     "cameras": [{**c, "input": {**c["input"], "stride": stride}}
                                                 for c in raw["cameras"] if c["name"] == n]}, list(sets))
               for n in names]
    dets = {"rig": {}, **{n: {} for n in names}}
    times = {"rig": [], **{n: [] for n in names}}
    for f, depth in zip(rig_frames, depths):  # each frame alternately by the rig and each camera alone
        for _ in range(repeats):
            t = time.perf_counter()
            got = rig.detect(depth)
            times["rig"].append(time.perf_counter() - t)
            for n, det, d in zip(names, singles, depth):
                t = time.perf_counter()
                one = det.detect([d])
                times[n].append(time.perf_counter() - t)
                dets[n][f.name] = np.array([[x.x, x.y] for x in one.detections]).reshape(-1, 2)
        dets["rig"][f.name] = np.array([[x.x, x.y] for x in got.detections]).reshape(-1, 2)
    frames_truth = {f.name: truth[f.name] for f in rig_frames}
    # each truth's `visibility` is its best camera's: "seen" leaves out the people under SEEN
    # visible from every camera (neither missing them nor a detection on them counts)
    full = {k: score_frames(v, frames_truth, 0.5, SEEN) for k, v in dets.items()}
    scores = {k: v["moda"] for k, v in full.items()}
    fusion = {k: score_frames(fuse_detections([dets[n] for n in names], k), frames_truth, 0.5, SEEN) for k in (1, 2)}
    fused = {k: v["moda"] for k, v in fusion.items()}
    seen = {**{k: v["moda_visible"] for k, v in full.items()},
            "detection_fusion": max(v["moda_visible"] for v in fusion.values())}
    median = {k: statistics.median(v) for k, v in times.items()}
    hidden = sum(1 for f in rig_frames for o in truth[f.name]
                 if min(o["visible_in"].get(n, 0.0) for n in names) < 0.1)
    rate = batched(run_cfg, depths, batch, repeats, [dets["rig"][f.name] for f in rig_frames], sets) if batch else None
    return {"scene": name, "sets": list(sets), "tuning": draw == 1000, "draw": draw, "object_width": width, "device": device, "people": SCENES[name]["people"], "frames": len(rig_frames),
            "truth": sum(len(v) for v in frames_truth.values()), "hidden_from_one": hidden,
            "unseen": full["rig"]["n_gt"] - full["rig"]["n_gt_visible"], "moda_seen": seen,
            "moda": scores, "rig_counts": {k: full["rig"][k] for k in ("tp", "fp", "fn")}, "detection_fusion": {"any": fused[1], "two": fused[2], "best": max(fused.values())},
            "median_s": median, "rig_over_camera": median["rig"] / statistics.mean(median[n] for n in names),
            "rig_over_sum": median["rig"] / sum(median[n] for n in names), "batched": rate}


def calibration(name: str, folder: Path, frames: int, draw: int = 0, width: float = WIDTH, device: str = "cpu",
                sets: list[str] = ()) -> dict:
    """The scene's rig calibrated with no pose given (calibrate.place_cameras on its rendered
    background and walking frames): each camera's pose against the rendered one, and the MODA of
    the rig with the calibrated poses. Calibration knows the floor but not where the world's origin
    and heading are: its world is turned and shifted on the floor so that the first camera's
    position and heading are the truth's (its height, pitch and roll stay the fit's), which puts the
    grid and the ground truth where they were; every other camera is then placed by the calibration."""
    from dpom_warp import Detector
    from dpom_warp.calibrate import place_cameras, planar, pose_angles
    from dpom_warp.config import apply_overrides
    from dpom_warp.evaluate import load_ground_truth, score_frames
    from dpom_warp.frames import run_frames
    from dpom_warp.geometry import pose_from_angles
    from dpom_warp.loading import config_from_mapping
    from dpom_warp.worker import read_rig_frame

    raw = {k: v for k, v in rig_config(name, folder, frames, draw, width, device).items() if k != "synthetic"}
    s = SCENES[name]
    truth = {n: pose_from_angles(p["height"], p["pitch_deg"], 0.0, p.get("yaw_deg", 0.0), p["x"], p["y"])
             for n, p in layout(s["height"], s["pitch"], s["area"]).items()}
    auto = {**raw, "cameras": [{**c, "camera": {k: v for k, v in c["camera"].items() if k != "extrinsics"}}
                               for c in raw["cameras"]]}
    t = time.perf_counter()
    placed = place_cameras(config_from_mapping(apply_overrides(auto, list(sets))), device, log=lambda *_: None)
    seconds = time.perf_counter() - t
    first, want = placed[0].T_world_from_camera, truth[placed[0].name]
    onto = planar(np.deg2rad(pose_angles(want)[3]), *want[:2, 3]) @ np.linalg.inv(
        planar(np.deg2rad(pose_angles(first)[3]), *first[:2, 3]))  # the calibration's world onto the truth's
    cameras = {}
    for p in placed:
        got, ref = onto @ p.T_world_from_camera, truth[p.name]
        cos = (np.trace(got[:3, :3].T @ ref[:3, :3]) - 1) / 2
        cameras[p.name] = {"height_error_m": abs(float(got[2, 3] - ref[2, 3])),
                           "position_error_m": float(np.linalg.norm(got[:2, 3] - ref[:2, 3])),
                           "rotation_error_deg": float(np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))),
                           "people_matched": p.people, "T": got}
    placed_cfg = {**raw, "cameras": [{**c, "camera": {**c["camera"], "extrinsics": {
        "T_world_from_camera": cameras[c["name"]]["T"].tolist()}}} for c in raw["cameras"]]}
    cfg = config_from_mapping(raw)
    rig_frames = run_frames(cfg, log=lambda *_: None).frames
    det = Detector.from_config(placed_cfg, list(sets))
    dets = {f.name: np.array([[x.x, x.y] for x in det.detect(read_rig_frame(cfg, f.paths)).detections]).reshape(-1, 2)
            for f in rig_frames}
    gt = load_ground_truth(raw["evaluation"]["ground_truth"])
    score = score_frames(dets, {f.name: gt[f.name] for f in rig_frames}, 0.5, SEEN)
    for c in cameras.values():
        del c["T"]
    return {"cameras": cameras, "seconds": seconds, "moda": score["moda"], "moda_seen": score["moda_visible"]}


def cli_run(run_cfg: dict, path: Path, out: Path, extra: list[str], sets: list[str] = ()) -> Path:
    """`dpom-warp run` of `run_cfg` (written to `path`) into `out`, with `extra` arguments and
    the --set items `sets`; returns `out`."""
    import yaml

    from dpom_warp.cli import main as cli

    path.write_text(yaml.safe_dump(run_cfg))
    args = ["run", str(path), "--no-progress", "--overwrite", "--output", str(out), *extra]
    for item in sets:
        args += ["--set", item]
    assert cli(args) == 0
    return out


def live_rig(run_cfg: dict, folder: Path, fps: float, workers: int, want: dict, sets: list[str] = ()) -> dict:
    """The scene's rig frames played at `fps` through the live path with `workers` processes:
    its live block's rate, drops and latency, and whether each map is the recorded rig's
    (`want`: frame stem -> map)."""
    out = cli_run(run_cfg, folder / "live.yaml", folder / f"live_{workers}",
                  ["--play", "--workers", str(workers), "--set", f"input.fps={fps:g}"], sets)
    live = json.loads((out / "summary.json").read_text())["live"]
    maps = sorted(out.glob("maps/*.npy"))
    same = sum(np.array_equal(np.load(m), want[m.stem]) for m in maps)
    return {"fps": fps, "workers": workers, "frames": live["frames"], "received": live["received"],
            "dropped_share": live["dropped_share"], "rig_frames_per_s": live["frames_per_s_steady"],
            "latency_ms": live["latency_ms_median"], "maps_as_recorded": same}


def recorded_maps(run_cfg: dict, folder: Path, sets: list[str] = ()) -> dict:
    """The rig's maps of a recorded run of its frames (frame stem -> map)."""
    out = cli_run(run_cfg, folder / "recorded.yaml", folder / "recorded", [], sets)
    return {m.stem: np.load(m) for m in out.glob("maps/*.npy")}


def markdown(results: list[dict], machine: str) -> str:
    names = [k for k in results[0]["moda"] if k != "rig"]
    rows = ["| scene | people (truth) | " + " | ".join(f"camera {n} alone" for n in names)
            + " | detection fusion (1 / 2 agree) | evidence fusion (rig) | rig frame / one camera's |",
            "|---|---|" + "---|" * len(names) + "---|---|---|"]
    for r in results:
        rows.append(f"| {r['scene']} | {r['people']} ({r['truth']}; {r['hidden_from_one']} under 10 % visible "
                    f"from a camera) | " + " | ".join(f"{r['moda'][n]:.3f}" for n in names)
                    + f" | {r['detection_fusion']['any']:.3f} / {r['detection_fusion']['two']:.3f} | "
                      f"**{r['moda']['rig']:.3f}** | {r['rig_over_camera']:.2f}x ({1000 * r['median_s']['rig']:.0f} ms; "
                      f"{r['rig_over_sum']:.2f}x the three cameras' sum) |")
    rows += ["", f"Not counting the people under {100 * SEEN:.0f} % visible from every camera (the issue's held-out crowd has "
             "none; missing them, or a detection on them, is no error):", "",
             f"| scene | people under {100 * SEEN:.0f} % visible from every camera | " + " | ".join(f"camera {n} alone" for n in names)
             + " | detection fusion (the better) | evidence fusion (rig) | rig over detection fusion |",
             "|---|---|" + "---|" * len(names) + "---|---|---|"]
    for r in results:
        seen = r["moda_seen"]
        rows.append(f"| {r['scene']} | {r['unseen']} of {r['truth']} | " + " | ".join(f"{seen[n]:.3f}" for n in names)
                    + f" | {seen['detection_fusion']:.3f} | **{seen['rig']:.3f}** | "
                      f"{seen['rig'] - seen['detection_fusion']:+.3f} |")
    if any("calibrated" in r for r in results):
        rows += ["", "Calibrated with no pose given (`dpom-warp calibrate`'s placement on the same frames; the "
                 "calibration's world turned and shifted on the floor onto the first camera's true position and "
                 "heading), each camera's pose against the rendered one and the rig's MODA with the calibrated poses:",
                 "", "| scene | camera | people matched | height error | position error | rotation error |",
                 "|---|---|---|---|---|---|"]
        for r in results:
            c = r.get("calibrated")
            for n, e in (c or {}).get("cameras", {}).items():
                rows.append(f"| {r['scene']} | {n} | {e['people_matched'] if e['people_matched'] is not None else 'first'} | "
                            f"{100 * e['height_error_m']:.1f} cm | {100 * e['position_error_m']:.1f} cm | "
                            f"{e['rotation_error_deg']:.2f} deg |")
        rows += ["", "| scene | MODA, poses given | MODA, calibrated | without the people under 10 % visible: given / "
                 "calibrated | calibration time |", "|---|---|---|---|---|"]
        for r in results:
            if (c := r.get("calibrated")):
                rows.append(f"| {r['scene']} | {r['moda']['rig']:.3f} | {c['moda']:.3f} | {r['moda_seen']['rig']:.3f} / "
                            f"{c['moda_seen']:.3f} | {c['seconds']:.0f} s |")
    device = results[0].get("device", "cpu")
    where = machine if device == "cpu" else f"{device} ({machine})"
    notes = [f"{r['scene']}: engine.batch {b['batch']}, {b['rig_frames_per_s']:.1f} rig frames a second = "
             f"{b['camera_frames_per_s']:.0f} camera-frames a second (detections "
             f"{'the same as' if b['same_detections'] else 'NOT the same as'} frame by frame)"
             for r in results if (b := r.get("batched"))]
    notes += [f"{r['scene']} live (`--play` at {v['fps']:g} frames/s, {v['workers']} process"
              f"{'es' * (v['workers'] > 1)}): {v['rig_frames_per_s'] or 0:.1f} rig frames a second once running, "
              f"{100 * v['dropped_share']:.0f} % of the {v['received']} dropped, latency median {v['latency_ms']:.0f} ms; "
              f"{v['maps_as_recorded']} of its {v['frames']} maps the recorded rig's, bit for bit"
              for r in results for v in r.get("live", [])]
    return "\n".join(rows) + f"\n\nMODA at 0.5 m, fast path; {where}." + "".join("\n\n" + n for n in notes)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3, help="timings: each frame this many times, median")
    ap.add_argument("--output", default="runs/rig")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--tuning", action="store_true", help="the tuning draw (every scene's seed + 1000, cached apart), "
                                                          "on which the object's width was chosen")
    ap.add_argument("--draw", type=int, default=0, metavar="N",
                    help="another draw: every scene's seed + N, cached apart (1000: the tuning draw)")
    ap.add_argument("--object-width", type=float, default=WIDTH, help="object.width of the rig and of each camera alone")
    ap.add_argument("--device", default="cpu", help="the rig's and each camera's inference device: cpu or cuda:N")
    ap.add_argument("--batch", type=int, default=0, metavar="N",
                    help="also the rig's throughput with engine.batch N (detect_batch; 0: not measured)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="a config override for the rig and each camera alone (repeatable)")
    ap.add_argument("--live", type=float, default=0.0, metavar="FPS",
                    help="also play the rig frames through the live path at FPS (0: not measured)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 3], help="--live's process counts")
    ap.add_argument("--calibrate", action="store_true",
                    help="also calibrate each scene's rig with no pose given (dpom-warp calibrate's placement): "
                         "each camera's pose error and the calibrated rig's MODA")
    args = ap.parse_args()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    from bench.docs import machine

    results = []
    for name in args.scenes:
        draw = 1000 if args.tuning else args.draw
        folder = Path(".cache/bench") / f"{name}_{args.frames}{'_tuning' if draw == 1000 else f'_draw{draw}' if draw else ''}"
        r = run_scene(name, folder, args.frames, args.repeats, draw, args.object_width, args.device, args.batch,
                      args.set)
        if args.calibrate:
            r["calibrated"] = calibration(name, folder, args.frames, draw, args.object_width, args.device, args.set)
        if args.live:
            run_cfg = {k: v for k, v in rig_config(name, folder.resolve(), args.frames, draw, args.object_width,
                                                    args.device).items() if k != "synthetic"}  # (a file's paths: its folder's)
            want = recorded_maps(run_cfg, folder, args.set)
            r["live"] = [live_rig(run_cfg, folder, args.live, w, want, args.set) for w in args.workers]
        print(json.dumps(r))
        results.append(r)
    (out / "rig.json").write_text(json.dumps(results, indent=1))
    text = markdown(results, machine())
    (out / "rig.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()

"""Why each error of a robustness draw happens: every missed person and false detection,
with what the model says at its place.

Runs the people demo's config over bench.robustness's scenes (the tuning draw with --tuning)
through the Python API and matches each frame's detections with its ground truth at 0.5 m.
For a missed person: their height and visibility, the nearest other person and detection
(a detection under 0.5 m was matched to someone else), and at the cell
within 0.3 m with the largest rho: rho (mean field), e (eq. 13's share), rho* before the
top-band test (sigmoid(alpha e + beta) rho), the top band's counts (support / against /
hidden / missing / in view, the kept band's) and the readings behind the cell's core; then the
largest rho* within 0.3 m and its cell's distance to the nearest detection. For a false
detection: its rho* and the nearest people, with the same at its cell, and its log odds in the
joint test (detection.min_log_odds). Before the summary, a count of the errors by kind
(miss_kind, false_kind) and the lowest log odds of the true and of the false detections.

    python -m bench.errors [--tuning] [--background frames|auto|floor] [--set key=value ...]
                           [--scenes NAME ...] [--frames 10] [--tracking]

--tracking: bench.tracking's long scenes instead (people entering and leaving the view; all
75 frames unless --frames says fewer).
--bands: also every detection, true or false, whose kept top band has no supporting pixel
(model.top_support's s = 0: only hidden pixels carry it), with its counts, and how many of
the true and of the false detections are such.
"""

from __future__ import annotations

import argparse
import collections

import numpy as np

from bench import tracking
from bench.robustness import VARIANTS, scene_sets

GATE = 0.5  # the matching gate, metres
BACKGROUNDS = {"auto": "input.background=auto", "floor": "input.background=null"}


def cell_values(detector, result, k: int) -> dict:
    """What the model says at location k of the frame just detected: rho, e, rho* before the
    top band, the band's counts, whether the band is out of view, readings behind, rho*."""
    from dpom_warp.reference import band_out_of_view

    engine, p = detector.engine, detector.engine.params
    rho, e = float(result.rho.ravel()[k]), float(engine.share.numpy()[k])
    counts = tuple(int(c.numpy()[k]) for c in engine.prior.top_counts)  # support, against, hidden, missing, seen
    area = float(engine.area.numpy()[k % len(engine.area)])
    return dict(rho=rho, e=e, before=rho / (1.0 + np.exp(-(p.alpha * e + p.beta))), counts=counts,
                out_of_view=bool(band_out_of_view(counts[4], area, p)), behind=int(engine.prior.n_behind.numpy()[k]),
                rho_star=float(result.rho_star.ravel()[k]))


def nearest(points: np.ndarray, p) -> float:
    """Distance from p to the nearest of `points` (n, 2), metres; inf when there are none."""
    return float(np.hypot(*(points - p).T).min()) if len(points) else float("inf")


def strongest_near(rho_star, locations, near, found) -> tuple[float, float]:
    """Of the cells `near` a missed person (indices into the flat map), the largest rho* and
    that cell's distance to the nearest detection (metres; inf without detections): a person
    found as one with a neighbour shows how close to the neighbour's detection their own peak
    lies (the 0.4 m suppression)."""
    flat = np.asarray(rho_star).ravel()
    k = int(near[np.argmax(flat[near])])
    return float(flat[k]), nearest(found, locations[k])


def unsupported_u(counts, top_hidden: float, top_missing: float) -> float | None:
    """The top band's u = (s + top_hidden f) / (s + a + f + top_missing m) of a band with no
    supporting pixel (s = 0) and some judged (`counts`: support, against, hidden, missing, ...);
    None for any other band."""
    s, against, hidden, missing = counts[:4]
    n = against + hidden + top_missing * missing
    return None if s or not n else top_hidden * hidden / n


def band_unsupported(detector, result, locations, d, where: str, true: bool) -> int:
    """1 (and a line naming it) when detection `d`'s kept top band has no supporting pixel
    (unsupported_u), else 0."""
    p = detector.engine.params
    counts = cell_values(detector, result, int(np.argmin(np.hypot(*(locations - (d.x, d.y)).T))))["counts"]
    u = unsupported_u(counts, p.top_hidden, p.top_missing)
    if u is None:
        return 0
    print(f"band    {where}: {'true' if true else 'false'} detection at ({d.x:.2f}, {d.y:.2f}), rho* {d.rho:.3f}, "
          f"band support 0 / against {counts[1]} / hidden {counts[2]} / missing {counts[3]}, u {u:.3f}")
    return 1


def cell_state(v: dict) -> str:
    return (f"rho {v['rho']:.3f}, e {v['e']:.3f}, rho* before the top band {v['before']:.3f}, top band "
            f"s/a/f/missing/in view {'/'.join(str(c) for c in v['counts'])}, readings behind {v['behind']}, rho* "
            f"{v['rho_star']:.3f}")


def miss_kind(v: dict | None, threshold: float) -> str:
    """Why a person was missed, from the cell within 0.3 m with the largest rho (cell_values;
    None: no cell there): the mean field did not support them, eq. 13 or the top band cut rho*
    under the threshold, or rho* passed and the detection step kept a neighbour's instead."""
    if v is None or v["rho"] < threshold:
        return "no support in the mean field"
    if v["rho_star"] >= threshold:
        return "found as one with a neighbour"
    return "cut by eq. 13" if v["before"] < threshold else "cut by the top band"


def false_kind(v: dict, nearest: float, gate: float) -> str:
    """What a false detection is: a cell whose top band is out of view, a second cell within
    the matching gate of a person found by another detection, or something elsewhere."""
    if v["out_of_view"]:
        return "band out of view"
    return "second cell beside a person" if nearest < gate else "elsewhere"


def main():
    from dpom_warp.api import Detector
    from dpom_warp.evaluate import load_ground_truth, match
    from dpom_warp.io import read_depth
    from dpom_warp.sources import expand

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tuning", action="store_true", help="the tuning draw (seeds + 1000)")
    ap.add_argument("--background", choices=("frames", "auto", "floor"), default="frames")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    ap.add_argument("--scenes", nargs="+", choices=list(VARIANTS) + list(tracking.SCENES))
    ap.add_argument("--frames", type=int, help="frames a scene (default 10; a tracking scene: 75)")
    ap.add_argument("--tracking", action="store_true", help="bench.tracking's scenes")
    ap.add_argument("--bands", action="store_true", help="also list the detections whose top band has no support")
    a = ap.parse_args()
    scenes = a.scenes or list(tracking.SCENES if a.tracking else VARIANTS)
    false_total = missed_total = 0
    kinds = collections.Counter()
    odds = {"true": [], "false": []}  # the detections' log odds in the joint test
    unsupported = {True: 0, False: 0}  # --bands: true and false detections whose band has no support
    counts = {name: a.frames or (tracking.FRAMES if name in tracking.SCENES else 10) for name in scenes}
    for name in scenes:
        frames = counts[name]
        if name in tracking.SCENES:
            sets = tracking.scene_sets(name, tracking.FRAMES, a.tuning) + (
                [BACKGROUNDS[a.background]] if a.background in BACKGROUNDS else [])
        else:
            sets = scene_sets(name, VARIANTS[name], frames, a.background, a.tuning)
        sets += a.set + ["device=cpu"]
        detector = Detector.from_config("configs/demo_people.yaml", sets)
        cfg = detector.config
        truth = load_ground_truth(cfg.evaluation.ground_truth)
        locations = detector.worker.geometry.locations[:, :2]
        shape = (cfg.camera.height, cfg.camera.width)
        for f in expand(cfg.inputs.frames, "input.frames")[:frames]:
            result = detector.detect(read_depth(f, cfg.inputs.depth_scale, shape))
            people = truth[f.name]
            found = np.array([(d.x, d.y) for d in result.detections]).reshape(-1, 2)
            where = np.array([(o["x"], o["y"]) for o in people]).reshape(-1, 2)
            pairs = match(found, where, GATE)
            matched_found, matched_people = {i for i, _ in pairs}, {j for _, j in pairs}
            for j, o in enumerate(people):
                if j in matched_people:
                    continue
                missed_total += 1
                person_gap = nearest(np.delete(where, j, axis=0), where[j])
                near = np.flatnonzero(np.hypot(*(locations - where[j]).T) < 0.3)
                v = cell_values(detector, result, int(near[np.argmax(result.rho.ravel()[near])])) if len(
                    near) else None
                state = cell_state(v) if v else "no cell within 0.3 m"
                if len(near):
                    peak, peak_gap = strongest_near(result.rho_star, locations, near, found)
                    state += f"; largest rho* within 0.3 m {peak:.3f}, {peak_gap:.2f} m from the nearest detection"
                kinds[miss_kind(v, cfg.detection.threshold)] += 1
                gap = nearest(found, where[j])
                print(f"missed  {name} {f.name}: person at ({o['x']:.2f}, {o['y']:.2f}), {o['height']:.2f} m, "
                      f"{100 * o['visibility']:.0f} % visible, nearest person {person_gap:.2f} m, nearest detection "
                      f"{gap:.2f} m; {state}")
            for i, d in enumerate(result.detections):
                if d.log_odds is not None:
                    odds["true" if i in matched_found else "false"].append(d.log_odds)
                if a.bands:
                    unsupported[i in matched_found] += band_unsupported(
                        detector, result, locations, d, f"{name} {f.name}", i in matched_found)
                if i in matched_found:
                    continue
                false_total += 1
                dist = np.hypot(*(where - found[i]).T) if len(where) else np.array([])
                close = ", ".join(f"{dist[j]:.2f} m ({people[j]['height']:.2f} m tall)" for j in np.argsort(dist)[:2])
                k = int(np.argmin(np.hypot(*(locations - found[i]).T)))
                v = cell_values(detector, result, k)
                kinds[false_kind(v, dist.min() if len(dist) else np.inf, GATE)] += 1
                joint = "" if d.log_odds is None else f", log odds {d.log_odds:.1f}"
                print(f"false   {name} {f.name}: at ({d.x:.2f}, {d.y:.2f}), nearest people {close or 'none'}; "
                      f"{cell_state(v)}{joint}")
    if a.bands:
        print(f"top bands with no supporting pixel: {unsupported[True]} true detections, "
              f"{unsupported[False]} false")
    draw = "tuning draw" if a.tuning else "held-out draw"
    per_scene = " / ".join(str(n) for n in sorted(set(counts.values())))
    print("kinds: " + "; ".join(f"{kind} {n}" for kind, n in kinds.most_common()))
    if odds["true"] or odds["false"]:
        print("joint test, log odds of the detections kept: " + "; ".join(
            f"{n} {which}, lowest {', '.join(f'{x:.1f}' for x in sorted(v)[:5]) or '-'}"
            for which, v in odds.items() for n in [len(v)]))
    print(f"{draw}, {len(scenes)} scenes x {per_scene} frames, background {a.background}"
          f"{'; ' + ', '.join(a.set) if a.set else ''}: {false_total} false detections, {missed_total} missed")


if __name__ == "__main__":
    main()

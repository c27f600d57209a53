"""Tracking scores against ground truth with identities (objects[].id).

MOTA, MOTP, IDF1, identity switches, fragmentations and mostly tracked / lost come from
py-motmetrics (Milan et al.'s CLEAR MOT and Ristani et al.'s identity measures, as the MOT
Challenge computes them); HOTA (Luiten et al., IJCV 2021) is computed here, as TrackEval
defines it, because no py-motmetrics release has it (tests compare it with TrackEval). A
track and a person match within the ground-plane gate (metres; in 3D for voxel runs); HOTA's
similarity is 1 - distance / gate, averaged over its thresholds 0.05 ... 0.95.

Two protocols for hidden people, as the detection scores: people in the ground truth less
visible than `hidden_visibility` are either counted (`penalise_hidden`) or neither required
nor held against a track that finds them (`ignore_hidden`: the track points matched to them
within the gate are left out, as MOT Challenge leaves out its distractors).
"""

from __future__ import annotations

import warnings

import numpy as np

from .io import InputError

GATES = (0.5, 1.0)  # metres: this project's gate, and the multi-camera benchmarks'
ALPHAS = np.arange(0.05, 0.99, 0.05)


def _distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    return np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)


def frames_of(tracks: dict[str, list], truth: dict[str, list[dict]], frames: list[str], dims: int,
              gate: float, hidden_visibility: float | None):
    """Per frame (gt ids, gt positions, track ids, track positions) with the ignore_hidden
    protocol applied when `hidden_visibility` is given; tracks: name -> [(id, x, y, z, ...)]."""
    out = []
    for name in frames:
        objs = truth.get(name, [])
        for o in objs:
            if "id" not in o:
                raise InputError(f"ground truth: frame {name}: expected objects with an id "
                                 f"(objects[].id) to score tracks")
        gt = np.array([[o["x"], o["y"], o.get("z", 0.0)][:dims] for o in objs], float).reshape(-1, dims)
        gid = np.array([int(o["id"]) for o in objs], int)
        rows = tracks.get(name, [])
        tr = np.array([r[1:1 + dims] for r in rows], float).reshape(-1, dims)
        tid = np.array([int(r[0]) for r in rows], int)
        if hidden_visibility is not None and len(objs):
            hidden = np.array([o.get("visibility", 1.0) < hidden_visibility for o in objs])
            if hidden.any() and len(tr):
                from .matching import assign

                d = _distances(tr, gt[hidden])
                drop = {i for i, _ in assign(d, gate)}
                keep = np.array([i not in drop for i in range(len(tr))], bool)
                tr, tid = tr[keep], tid[keep]
            gt, gid = gt[~hidden], gid[~hidden]
        out.append((gid, gt, tid, tr))
    return out


def clear_identity(per_frame: list, gate: float) -> dict:
    """MOTA, MOTP (mean distance of the matches, metres), IDF1 and the counts, by motmetrics."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pandas deprecation notes from motmetrics
        import motmetrics as mm

        acc = mm.MOTAccumulator(auto_id=True)
        for gid, gt, tid, tr in per_frame:
            d = _distances(gt, tr)
            acc.update(gid.tolist(), tid.tolist(), np.where(d <= gate, d, np.nan))
        names = ["mota", "motp", "idf1", "idp", "idr", "num_switches", "num_fragmentations",
                 "num_false_positives", "num_misses", "num_objects", "mostly_tracked",
                 "mostly_lost", "num_unique_objects", "precision", "recall"]
        row = mm.metrics.create().compute(acc, metrics=names, name="run").iloc[0]
    out = {k: (float(row[k]) if row[k] == row[k] else None) for k in names}
    for k in names:
        if k.startswith("num_") or k.startswith("mostly_"):
            out[k] = int(row[k])
    return out


def hota(per_frame: list, gate: float) -> dict:
    """HOTA, DetA, AssA and LocA (averaged over ALPHAS), TrackEval's definition with the
    similarity 1 - distance / gate."""
    gids = sorted({int(g) for gid, _, _, _ in per_frame for g in gid})
    tids = sorted({int(t) for _, _, tid, _ in per_frame for t in tid})
    gi, ti = {g: i for i, g in enumerate(gids)}, {t: i for i, t in enumerate(tids)}
    n_g, n_t = len(gids), len(tids)
    frames = []
    for gid, gt, tid, tr in per_frame:
        sim = np.clip(1.0 - _distances(gt, tr) / gate, 0.0, None)
        frames.append((np.array([gi[int(g)] for g in gid], int), np.array([ti[int(t)] for t in tid], int), sim))
    n_gt_dets = sum(len(g) for g, _, _ in frames)
    n_tr_dets = sum(len(t) for _, t, _ in frames)
    if n_tr_dets == 0 or n_gt_dets == 0:
        return {"hota": 0.0, "deta": 0.0, "assa": 0.0, "loca": 1.0 if n_tr_dets == 0 else 0.0}
    # how much each (person, track) pair could be matched, as a share of their union
    potential = np.zeros((n_g, n_t))
    g_count, t_count = np.zeros((n_g, 1)), np.zeros((1, n_t))
    for g, t, sim in frames:
        if len(g) and len(t):
            denom = sim.sum(0, keepdims=True) + sim.sum(1, keepdims=True) - sim
            share = np.divide(sim, denom, out=np.zeros_like(sim), where=denom > np.finfo(float).eps)
            potential[g[:, None], t[None, :]] += share
        g_count[g] += 1
        t_count[0, t] += 1
    alignment = potential / (g_count + t_count - potential)
    tp, fn, fp = np.zeros(len(ALPHAS)), np.zeros(len(ALPHAS)), np.zeros(len(ALPHAS))
    loc = np.zeros(len(ALPHAS))
    matches = np.zeros((len(ALPHAS), n_g, n_t))
    from scipy.optimize import linear_sum_assignment

    eps = np.finfo(float).eps
    for g, t, sim in frames:
        if not len(g) or not len(t):
            fn += len(g)
            fp += len(t)
            continue
        score = alignment[g[:, None], t[None, :]] * sim
        rows, cols = linear_sum_assignment(-score)
        for a, alpha in enumerate(ALPHAS):
            ok = sim[rows, cols] >= alpha - eps
            r, c = rows[ok], cols[ok]
            tp[a] += len(r)
            fn[a] += len(g) - len(r)
            fp[a] += len(t) - len(r)
            if len(r):
                loc[a] += sim[r, c].sum()
                matches[a, g[r], t[c]] += 1
    assa = np.zeros(len(ALPHAS))
    for a in range(len(ALPHAS)):
        m = matches[a]
        ass = m / np.maximum(1, g_count + t_count - m)
        assa[a] = (m * ass).sum() / max(1, tp[a])
    deta = tp / np.maximum(1, tp + fn + fp)
    loca = np.maximum(1e-10, loc) / np.maximum(1e-10, tp)
    h = np.sqrt(deta * assa)
    return {"hota": float(h.mean()), "deta": float(deta.mean()), "assa": float(assa.mean()),
            "loca": float(loca.mean())}


def track_scores(tracks: dict[str, list], truth: dict[str, list[dict]], frames: list[str],
                 dims: int = 2, hidden_visibility: float = 0.1, gates=GATES) -> dict:
    """Both protocols at every gate: {protocol: {gate: {mota, motp, idf1, ..., hota, ...}}},
    with the person-frames and the identity switches per 500 person-frames."""
    out = {}
    for protocol, hv in (("penalise_hidden", None), ("ignore_hidden", hidden_visibility)):
        out[protocol] = {}
        for gate in gates:
            per_frame = frames_of(tracks, truth, frames, dims, gate, hv)
            s = {**clear_identity(per_frame, gate), **hota(per_frame, gate)}
            s["person_frames"] = int(sum(len(g) for g, _, _, _ in per_frame))
            s["switches_per_500"] = 500.0 * s["num_switches"] / max(1, s["person_frames"])
            out[protocol][f"{gate:g}"] = s
    out["hidden_visibility"] = hidden_visibility
    return out


def link_naive(positions: list[np.ndarray], gate: float) -> list[list[int]]:
    """The naive baseline: each frame's detections matched to the previous frame's by the
    Hungarian method within `gate` metres; an unmatched detection starts a new identity.
    Returns the identity of every detection, frame by frame."""
    from .matching import match

    out, prev, prev_ids, next_id = [], None, [], 0
    for pos in positions:
        pos = np.asarray(pos, float)
        pos = pos.reshape(0, 2) if pos.size == 0 else pos
        ids = [-1] * len(pos)
        if prev is not None and len(prev) and len(pos):
            for i, j in match(pos, prev, gate):
                ids[i] = prev_ids[j]
        for i in range(len(pos)):
            if ids[i] < 0:
                next_id += 1
                ids[i] = next_id
        out.append(ids)
        prev, prev_ids = pos, ids
    return out


def naive_tracks(detections: dict[str, np.ndarray], frames: list[str], gate: float) -> dict[str, list]:
    """The naive baseline on a run's detections (name -> (n, dims) positions): linked frame
    to frame by the Hungarian method within `gate` (link_naive)."""
    pos = [np.asarray(detections.get(f, np.zeros((0, 2))), float) for f in frames]
    ids = link_naive(pos, gate)
    return {f: [(i, *p) for i, p in zip(idf, pf)] for f, idf, pf in zip(frames, ids, pos)}

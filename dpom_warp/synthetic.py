"""Synthetic depth sequences: people walking, or quadcopters flying, in a furnished room,
rendered with Open3D's RaycastingScene from a pinhole camera, with sensor-like noise, and
ground truth.

Everything is seeded: the same spec and camera give the same frames, bit for bit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ._open3d import o3d
from .geometry import Camera
from .io import write_depth_png, write_json_atomic
from .scene_spec import SceneSpec, drift_scales

GENERATOR_VERSION = 3  # 2: objects with no visible pixel are left out of the ground truth; 3: objects carry ids


def _cylinder(radius, length, p0, p1=None, resolution=12):
    """Cylinder from point p0 downwards by `length` (or from p0 to p1)."""
    p0 = np.asarray(p0, float)
    p1 = p0 - np.array([0, 0, length]) if p1 is None else np.asarray(p1, float)
    axis = p1 - p0
    n = np.linalg.norm(axis)
    m = o3d.geometry.TriangleMesh.create_cylinder(radius=radius, height=n, resolution=resolution)
    z = axis / n
    a = np.cross([0.0, 0.0, 1.0], z)
    s, c = np.linalg.norm(a), z[2]
    if s > 1e-9:
        k = a / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        r = np.eye(3) + s * kx + (1 - c) * kx @ kx
    else:
        r = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    m.rotate(r, center=(0, 0, 0))
    m.translate((p0 + p1) / 2)
    return m


def _box(size, centre):
    m = o3d.geometry.TriangleMesh.create_box(*size)
    m.translate(np.asarray(centre, float) - np.asarray(size, float) / 2)
    return m


def person_mesh(height: float, heading: float, phase: float, build: float = 1.0):
    """A human-like figure standing at the origin: legs, torso, arms, neck and head.

    Args:
        height: overall height, metres.
        heading: walking direction, radians from world +x.
        phase: gait phase, radians (legs and arms swing with sin(phase)).
        build: width scale of torso and shoulders.
    """
    h = height
    swing = 0.3 * math.sin(phase)
    hip_z, leg_len = 0.49 * h, 0.49 * h
    parts = []
    for side, sgn in ((-1, 1), (1, -1)):
        hip = np.array([side * 0.09 * build, 0.0, hip_z])
        a = sgn * swing
        foot = hip + leg_len * np.array([0.0, math.sin(a), -math.cos(a)])
        parts.append(_cylinder(0.065, 0, hip, foot))
    torso = o3d.geometry.TriangleMesh.create_cylinder(radius=1.0, height=1.0, resolution=20)
    v = np.asarray(torso.vertices)
    v *= np.array([0.19 * build, 0.12, 0.33 * h])
    torso.vertices = o3d.utility.Vector3dVector(v + np.array([0, 0, hip_z + 0.16 * h]))
    parts.append(torso)
    shoulder_z = hip_z + 0.31 * h
    for side, sgn in ((-1, -1), (1, 1)):
        sh = np.array([side * 0.23 * build, 0.0, shoulder_z])
        a = sgn * swing * 0.8
        hand = sh + 0.36 * h * np.array([side * 0.05, math.sin(a), -math.cos(a)])
        parts.append(_cylinder(0.045, 0, sh, hand))
    r_head = 0.063 * h
    parts.append(_cylinder(0.05, 0, np.array([0, 0, h - 2 * r_head + 0.02]),
                           np.array([0, 0, shoulder_z])))
    head = o3d.geometry.TriangleMesh.create_sphere(radius=r_head, resolution=10)
    head.translate((0, 0.01, h - r_head))
    parts.append(head)
    mesh = parts[0]
    for p in parts[1:]:
        mesh += p
    rot = o3d.geometry.get_rotation_matrix_from_xyz((0, 0, heading - math.pi / 2))
    mesh.rotate(rot, center=(0, 0, 0))
    return mesh


def drone_mesh(heading: float):
    """A quadcopter centred at the origin: body, four arms, four rotors; 0.35 x 0.35 x 0.09 m."""
    parts = [_box((0.16, 0.16, 0.06), (0, 0, 0))]
    for a in np.deg2rad([45, 135, 225, 315]):
        d = np.array([math.cos(a), math.sin(a), 0.0])
        arm = _box((0.2, 0.03, 0.02), (0, 0, 0))
        arm.rotate(o3d.geometry.get_rotation_matrix_from_xyz((0, 0, a)), center=(0, 0, 0))
        parts.append(arm.translate(0.1 * d))
        rotor = o3d.geometry.TriangleMesh.create_cylinder(radius=0.07, height=0.012, resolution=16)
        parts.append(rotor.translate(0.15 * d + np.array([0, 0, 0.035])))
    mesh = parts[0]
    for p in parts[1:]:
        mesh += p
    mesh.rotate(o3d.geometry.get_rotation_matrix_from_xyz((0, 0, heading)), center=(0, 0, 0))
    return mesh


def obstacle_meshes(spec: SceneSpec, rng: np.random.Generator, footprints):
    """Free-standing cabinets inside the flying area; returns meshes and their boxes
    (x0, x1, y0, y1, height)."""
    ax0, ax1, ay0, ay1 = spec.area
    meshes, boxes = [], []
    for _ in range(spec.obstacles):
        for _ in range(200):
            w, d, h = rng.uniform(0.6, 1.1), rng.uniform(0.4, 0.6), rng.uniform(1.6, 1.9)
            cx, cy = rng.uniform(ax0 + 0.5, ax1 - 0.5), rng.uniform(ay0 + 0.8, ay1 - 1.0)
            box = (cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2, h)
            if all(box[1] < b[0] - 0.8 or box[0] > b[1] + 0.8 or box[3] < b[2] - 0.8 or box[2] > b[3] + 0.8
                   for b in boxes + [(*f, 3.0) for f in footprints]):
                break
        boxes.append(box)
        meshes.append(_box((w, d, h), (cx, cy, h / 2)))
    return meshes, boxes


def table_meshes(spec: SceneSpec, rng: np.random.Generator, footprints):
    """Free-standing tables (top and four legs) inside the walking area, 0.9 m clear of the
    furniture and of each other (a table that finds no such place is left out); returns
    meshes and their footprints (x0, x1, y0, y1)."""
    ax0, ax1, ay0, ay1 = spec.area
    meshes, placed = [], []
    for _ in range(spec.tables):
        for _ in range(200):
            w, d, h = rng.uniform(0.8, 1.4), rng.uniform(0.6, 0.9), rng.uniform(0.72, 0.76)
            if rng.random() < 0.5:
                w, d = d, w
            cx, cy = rng.uniform(ax0 + w / 2, ax1 - w / 2), rng.uniform(ay0 + d / 2, ay1 - d / 2)
            fp = (cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2)
            if all(fp[1] < f[0] - 0.9 or fp[0] > f[1] + 0.9 or fp[3] < f[2] - 0.9 or fp[2] > f[3] + 0.9
                   for f in footprints + placed):
                break
        else:
            continue
        placed.append(fp)
        meshes.append(_box((w, d, 0.04), (cx, cy, h - 0.02)))
        for sx in (-1, 1):
            for sy in (-1, 1):
                meshes.append(_box((0.05, 0.05, h - 0.04),
                                   (cx + sx * (w / 2 - 0.05), cy + sy * (d / 2 - 0.05), (h - 0.04) / 2)))
    return meshes, placed


def fly(spec: SceneSpec, camera: Camera, boxes, rng: np.random.Generator):
    """Drones' (x, y, z, heading) per frame: a random flight that keeps each in view, clear of
    the furniture (boxes x0, x1, y0, y1, height) and 0.6 m from the others."""
    ax0, ax1, ay0, ay1 = spec.area
    z0, z1 = spec.altitude

    def clear(x, y, z):
        return all(not (b[0] - 0.35 < x < b[1] + 0.35 and b[2] - 0.35 < y < b[3] + 0.35 and z < b[4] + 0.2)
                   for b in boxes)

    def in_view(x, y, z, camera=camera):
        if isinstance(camera, (list, tuple)):  # a rig: in one camera's view at least
            return any(in_view(x, y, z, c) for c in camera)
        u, v, depth = camera.project(np.array([[x + dx, y, z + dz] for dx in (-0.2, 0.2) for dz in (-0.06, 0.06)]))
        return bool(np.all(depth > 0.5) and np.all((u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)))

    def ok(p, others):
        x, y, z = p
        return (ax0 <= x <= ax1 and ay0 <= y <= ay1 and z0 <= z <= z1 and clear(x, y, z)
                and in_view(x, y, z) and all(np.linalg.norm(np.subtract(p, o[:3])) > 0.6 for o in others))

    state = []
    for _ in range(spec.people):
        for _ in range(10000):
            p = [rng.uniform(ax0, ax1), rng.uniform(ay0, ay1), rng.uniform(z0, z1)]
            if ok(p, state):
                break
        else:
            raise RuntimeError("synthetic: could not place every drone in view; enlarge 'area'")
        state.append(p + [rng.uniform(0, 2 * math.pi), rng.normal(0, 0.3)])
    frames = []
    for _ in range(spec.frames):
        frames.append([dict(x=s[0], y=s[1], z=s[2], heading=s[3]) for s in state])
        for i, s in enumerate(state):
            others = [q for j, q in enumerate(state) if j != i]
            for attempt in range(50):
                hd = s[3] + rng.normal(0, 0.4) + (0 if attempt < 5 else rng.uniform(-math.pi, math.pi))
                climb = s[4] + rng.normal(0, 0.2) if attempt < 5 else rng.normal(0, 0.5)
                step = spec.step_m * np.array([math.cos(hd), math.sin(hd), climb])
                p = list(np.array(s[:3]) + step)
                if ok(p, others):
                    state[i] = p + [hd, float(np.clip(climb, -0.6, 0.6))]
                    break
    return frames


def room_meshes(spec: SceneSpec, rng: np.random.Generator):
    """Floor, walls and furniture; returns (meshes, footprints (x0, x1, y0, y1))."""
    x0, x1, y0, y1, hgt = spec.room
    t = 0.1
    meshes = [
        _box((x1 - x0 + 2, y1 - y0 + 2, t), ((x0 + x1) / 2, (y0 + y1) / 2, -t / 2)),  # floor
        _box((t, y1 - y0, hgt), (x0 - t / 2, (y0 + y1) / 2, hgt / 2)),
        _box((t, y1 - y0, hgt), (x1 + t / 2, (y0 + y1) / 2, hgt / 2)),
        _box((x1 - x0, t, hgt), ((x0 + x1) / 2, y1 + t / 2, hgt / 2)),
        _box((x1 - x0, t, hgt), ((x0 + x1) / 2, y0 - t / 2, hgt / 2)),
    ]
    footprints = []
    for i in range(spec.furniture):
        kind = ("table", "cabinet", "shelf")[i % 3]
        for _ in range(100):
            if kind == "table":
                w, d, hh = rng.uniform(1.0, 1.6), rng.uniform(0.6, 0.9), 0.75
            elif kind == "cabinet":
                w, d, hh = rng.uniform(0.6, 1.2), rng.uniform(0.4, 0.6), rng.uniform(0.9, 1.4)
            else:
                w, d, hh = rng.uniform(0.8, 1.5), 0.35, rng.uniform(1.6, 2.0)
            # against a side or the back wall
            wall = rng.integers(0, 3)
            if wall == 0:
                cx, cy, w, d = x0 + d / 2 + 0.02, rng.uniform(y0 + 2, y1 - 1), d, w
            elif wall == 1:
                cx, cy, w, d = x1 - d / 2 - 0.02, rng.uniform(y0 + 2, y1 - 1), d, w
            else:
                cx, cy = rng.uniform(x0 + 1, x1 - 1), y1 - d / 2 - 0.02
            fp = (cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2)
            if all(fp[1] < f[0] - 0.3 or fp[0] > f[1] + 0.3 or fp[3] < f[2] - 0.3 or fp[2] > f[3] + 0.3
                   for f in footprints):
                break
        footprints.append(fp)
        if kind == "table":
            meshes.append(_box((w, d, 0.04), (cx, cy, hh - 0.02)))
            for sx in (-1, 1):
                for sy in (-1, 1):
                    meshes.append(_box((0.05, 0.05, hh - 0.04),
                                       (cx + sx * (w / 2 - 0.05), cy + sy * (d / 2 - 0.05), (hh - 0.04) / 2)))
        else:
            meshes.append(_box((w, d, hh), (cx, cy, hh / 2)))
    return meshes, footprints


def _scene(meshes):
    scene = o3d.t.geometry.RaycastingScene()
    ids = [scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m)) for m in meshes]
    return scene, ids


def render(scene, camera: Camera):
    """z-depth (metres, inf = no hit) and geometry id of every pixel."""
    d = camera.rays().reshape(-1, 3)
    o = np.broadcast_to(camera.centre, d.shape)
    rays = o3d.core.Tensor(np.concatenate([o, d], 1).astype(np.float32))
    out = scene.cast_rays(rays)
    t = out["t_hit"].numpy().reshape(camera.height, camera.width).astype(np.float64)
    gid = out["geometry_ids"].numpy().reshape(camera.height, camera.width)
    return t, gid


def sensor_noise(depth, spec: SceneSpec, rng: np.random.Generator):
    """Depth-dependent Gaussian noise, random dropouts, holes at depth edges, range limits."""
    z = np.where(np.isfinite(depth), depth, 0.0)
    a, b = spec.noise
    noisy = z + rng.normal(size=z.shape) * (a + b * z ** 2)
    jump = np.zeros(z.shape, bool)
    dv = np.abs(np.diff(z, axis=0)) > 0.1
    du = np.abs(np.diff(z, axis=1)) > 0.1
    jump[1:] |= dv
    jump[:-1] |= dv
    jump[:, 1:] |= du
    jump[:, :-1] |= du
    lost = (jump & (rng.random(z.shape) < spec.edge_holes)) | (rng.random(z.shape) < spec.dropout)
    lost |= (z < spec.range_m[0]) | (z > spec.range_m[1])
    return np.where(lost, 0.0, noisy)


def _in_view(camera: Camera, x, y, top, from_above=False):
    """Feet and head in the image, or (`from_above`) the head; `camera` a list: in one of them."""
    if isinstance(camera, (list, tuple)):
        return any(_in_view(c, x, y, top, from_above) for c in camera)
    u, v, z = camera.project(np.array([[x, y, top]] if from_above else [[x, y, 0.0], [x, y, top]]))
    return bool(np.all(z > 0.3) and np.all((u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)))


def _free(x, y, footprints, margin=0.45):
    return all(not (f[0] - margin < x < f[1] + margin and f[2] - margin < y < f[3] + margin)
               for f in footprints)


def walk(spec: SceneSpec, camera: Camera, footprints, rng: np.random.Generator):
    """People's (x, y, heading, phase) per frame: a random walk that keeps them in view
    (spec.in_view), off the furniture and spec.min_gap apart. Returns list over frames of lists of dicts."""
    ax0, ax1, ay0, ay1 = spec.area
    heights = rng.uniform(1.55, 1.95, spec.people)
    builds = rng.uniform(0.9, 1.15, spec.people)

    def ok(x, y, others, i):
        return (ax0 <= x <= ax1 and ay0 <= y <= ay1 and _free(x, y, footprints)
                and _in_view(camera, x, y, heights[i], spec.in_view == "head")
                and all(math.hypot(x - o[0], y - o[1]) > spec.min_gap for o in others))

    if spec.pair_gap > 0:
        return _walk_pairs(spec, ok, heights, builds, rng)
    pos = []
    for i in range(spec.people):
        for _ in range(10000):
            x, y = rng.uniform(ax0, ax1), rng.uniform(ay0, ay1)
            if ok(x, y, pos, i):
                break
        else:
            raise RuntimeError("synthetic: could not place everyone in view; enlarge 'area'")
        pos.append([x, y, rng.uniform(0, 2 * math.pi), rng.uniform(0, 2 * math.pi)])
    frames = []
    for _ in range(spec.frames):
        frames.append([dict(x=p[0], y=p[1], heading=p[2], phase=p[3], height=float(heights[i]),
                            build=float(builds[i])) for i, p in enumerate(pos)])
        for i, p in enumerate(pos):
            others = [q for j, q in enumerate(pos) if j != i]
            for attempt in range(50):
                hd = p[2] + rng.normal(0, 0.3) + (0 if attempt < 5 else rng.uniform(-math.pi, math.pi))
                x, y = p[0] + spec.step_m * math.cos(hd), p[1] + spec.step_m * math.sin(hd)
                if ok(x, y, others, i):
                    p[:3] = [x, y, hd]
                    break
            p[3] += 1.3
    return frames


def stroll(spec: SceneSpec, camera: Camera, footprints, rng: np.random.Generator):
    """motion 'paths': people's (x, y, heading, phase) per frame, each walking straight to a
    waypoint at ~step_m a frame (+-15 %), pausing at some, waiting or stepping aside when
    another person is within min_gap; start in view, waypoints in `area` widened by
    spec.leave and inside the room, off the furniture."""
    ax0, ax1, ay0, ay1 = spec.area
    rx0, rx1, ry0, ry1, _ = spec.room
    heights = rng.uniform(1.55, 1.95, spec.people)
    builds = rng.uniform(0.9, 1.15, spec.people)
    lo = (max(ax0 - spec.leave, rx0 + 0.4), max(ay0 - spec.leave, ry0 + 0.4))
    hi = (min(ax1 + spec.leave, rx1 - 0.4), min(ay1 + spec.leave, ry1 - 0.4))

    def clear(x, y, others):
        return (_free(x, y, footprints) and rx0 + 0.3 < x < rx1 - 0.3 and ry0 + 0.3 < y < ry1 - 0.3
                and all(math.hypot(x - o[0], y - o[1]) > spec.min_gap for o in others))

    def waypoint(x, y):
        for _ in range(1000):
            wx, wy = rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1])
            if _free(wx, wy, footprints) and math.hypot(wx - x, wy - y) > 1.0:
                return [wx, wy]
        return [x, y]

    people = []
    for i in range(spec.people):
        for _ in range(10000):
            x, y = rng.uniform(ax0, ax1), rng.uniform(ay0, ay1)
            if (clear(x, y, [(q["x"], q["y"]) for q in people])
                    and _in_view(camera, x, y, heights[i], spec.in_view == "head")):
                break
        else:
            raise RuntimeError("synthetic: could not place everyone in view; enlarge 'area'")
        people.append({"x": x, "y": y, "heading": rng.uniform(0, 2 * math.pi),
                       "phase": rng.uniform(0, 2 * math.pi), "speed": spec.step_m * rng.uniform(0.85, 1.15),
                       "goal": waypoint(x, y), "pause": 0, "waited": 0})
    frames = []
    for _ in range(spec.frames):
        frames.append([dict(x=p["x"], y=p["y"], heading=p["heading"], phase=p["phase"],
                            height=float(heights[i]), build=float(builds[i])) for i, p in enumerate(people)])
        for i, p in enumerate(people):
            if p["pause"] > 0:
                p["pause"] -= 1
                continue
            gx, gy = p["goal"]
            dist = math.hypot(gx - p["x"], gy - p["y"])
            if dist <= p["speed"]:
                p["goal"] = waypoint(gx, gy)
                p["pause"] = int(rng.integers(8, 21)) if rng.random() < 0.3 else 0
                continue
            others = [(q["x"], q["y"]) for j, q in enumerate(people) if j != i]
            toward = math.atan2(gy - p["y"], gx - p["x"])
            for turn in (0.0, 0.6, -0.6, 1.2, -1.2):
                hd = toward + turn
                x, y = p["x"] + p["speed"] * math.cos(hd), p["y"] + p["speed"] * math.sin(hd)
                if clear(x, y, others):
                    p.update(x=x, y=y, heading=hd, phase=p["phase"] + 1.3 * p["speed"] / 0.3, waited=0)
                    break
            else:
                p["waited"] += 1
                if p["waited"] > 4:
                    p["goal"], p["waited"] = waypoint(p["x"], p["y"]), 0
    return frames


def _walk_pairs(spec: SceneSpec, ok, heights, builds, rng: np.random.Generator):
    """walk() for people in pairs (spec.pair_gap): each pair moves as one, the second person
    pair_gap to the left of the first, both in view, off the furniture, min_gap from others."""
    n, gap = spec.people, spec.pair_gap
    units = [list(range(i, min(i + 2, n))) for i in range(0, n, 2)]

    def members(x, y, h, unit):
        return [(x, y)] + [(x - gap * math.sin(h), y + gap * math.cos(h))] * (len(unit) - 1)

    def unit_ok(x, y, h, unit, others):
        return all(ok(px, py, others, i) for (px, py), i in zip(members(x, y, h, unit), unit))

    state = []  # x, y, heading, phase of each unit's first person
    for unit in units:
        others = [m for st, u in zip(state, units) for m in members(*st[:3], u)]
        for _ in range(10000):
            x, y, h = rng.uniform(*spec.area[:2]), rng.uniform(*spec.area[2:]), rng.uniform(0, 2 * math.pi)
            if unit_ok(x, y, h, unit, others):
                break
        else:
            raise RuntimeError("synthetic: could not place every pair in view; enlarge 'area'")
        state.append([x, y, h, rng.uniform(0, 2 * math.pi)])
    frames = []
    for _ in range(spec.frames):
        people = []
        for st, unit in zip(state, units):
            for (px, py), i in zip(members(*st[:3], unit), unit):
                people.append(dict(x=px, y=py, heading=st[2], phase=st[3] + 1.7 * (i - unit[0]),
                                   height=float(heights[i]), build=float(builds[i])))
        frames.append(people)
        for u, (st, unit) in enumerate(zip(state, units)):
            others = [m for v, (s2, u2) in enumerate(zip(state, units)) if v != u for m in members(*s2[:3], u2)]
            for attempt in range(50):
                hd = st[2] + rng.normal(0, 0.3) + (0 if attempt < 5 else rng.uniform(-math.pi, math.pi))
                x, y = st[0] + spec.step_m * math.cos(hd), st[1] + spec.step_m * math.sin(hd)
                if unit_ok(x, y, hd, unit, others):
                    st[:3] = [x, y, hd]
                    break
            st[3] += 1.3
    return frames


TRAJECTORIES = "trajectories.json"  # every object's position every frame, hidden or not (ground_truth.json: seen)


def trajectory_row(name: str, people: list) -> dict:
    """A frame's entry of trajectories.json: each object's id (its place in the sequence, as in
    ground_truth.json) and position, whether any camera sees it or not."""
    return {"frame": name, "objects": [{"id": n, "x": round(p["x"], 4), "y": round(p["y"], 4),
                                        "z": round(p.get("z", 0.0), 4)} for n, p in enumerate(people)]}


def furnish(spec: SceneSpec, rng: np.random.Generator):
    """(the room's meshes, the footprints people keep off, the boxes drones keep clear of)."""
    room, footprints = room_meshes(spec, rng)
    boxes = [(*f, 3.0) for f in footprints]
    if spec.obstacles:
        extra, inside = obstacle_meshes(spec, rng, footprints)
        room, boxes = room + extra, boxes + inside
        if spec.kind == "people":  # people walk around them (and behind them, hidden)
            footprints = footprints + [b[:4] for b in inside]
    if spec.tables:
        extra, placed = table_meshes(spec, rng, footprints)
        room, footprints, boxes = room + extra, footprints + placed, boxes + [(*f, 0.8) for f in placed]
    return room, footprints, boxes


def clear_frames(out: Path) -> None:
    """out/frames and out/background made, emptied of a scene rendered before with more frames
    (not of a concurrent render's hidden temporary files)."""
    for sub in ("frames", "background"):
        (out / sub).mkdir(parents=True, exist_ok=True)
        for old in (out / sub).glob("[0-9]*.png"):
            old.unlink()


def moves(spec: SceneSpec, camera, footprints, boxes, rng: np.random.Generator) -> list:
    """The objects of every frame (walk, stroll or fly), kept in view of `camera` (a list: of
    one of them at least)."""
    if spec.kind == "people":
        return (stroll if spec.motion == "paths" else walk)(spec, camera, footprints, rng)
    return fly(spec, camera, boxes, rng)


def placed_meshes(spec: SceneSpec, people: list) -> list:
    """The meshes of one frame's objects, placed."""
    if spec.kind == "people":
        meshes = [person_mesh(p["height"], p["heading"], p["phase"], p["build"]) for p in people]
    else:
        meshes = [drone_mesh(p["heading"]) for p in people]
    for m, p in zip(meshes, people):
        m.translate((p["x"], p["y"], p.get("z", 0.0)))
    return meshes


def seen_objects(meshes, people, ids, gid, camera: Camera) -> list:
    """Each object's ground truth as `camera` sees it in a frame whose geometry ids are `gid`
    (its box and the share of it in view), None where it is out of view or wholly hidden."""
    objects = []
    for n, (m, p, pid) in enumerate(zip(meshes, people, ids)):
        alone, _ = _scene([m])
        ta, _ = render(alone, camera)
        full = np.isfinite(ta)
        visible = int((gid == pid).sum())
        if visible == 0:  # out of view or wholly hidden: nothing in the image to find
            objects.append(None)
            continue
        vv, uu = np.nonzero(full)
        obj = {"id": n, "x": round(p["x"], 4), "y": round(p["y"], 4), "z": round(p.get("z", 0.0), 4)}
        if "height" in p:
            obj["height"] = round(p["height"], 3)
        objects.append({**obj, "bbox": [int(uu.min()), int(vv.min()), int(uu.max()), int(vv.max())],
                        "visibility": round(visible / float(full.sum()), 4)})
    return objects


def generate(spec: SceneSpec, camera: Camera, out_dir: str | Path) -> dict:
    """Render the sequence into `out_dir` (frames/, background/, ground_truth.json, scene.json).

    The folder is reused when its scene.json matches spec, camera and generator version.

    Returns:
        The scene description written to scene.json.
    """
    out = Path(out_dir)
    described = spec.model_dump()
    if not any(spec.drift):  # no drift: the key of scenes rendered before it existed
        del described["drift"]
    desc = {"version": GENERATOR_VERSION, "spec": described,
            "camera": {"width": camera.width, "height": camera.height, "fx": camera.fx,
                       "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                       "T_world_from_camera": np.asarray(camera.T_world_from_camera).tolist()}}
    meta = out / "scene.json"
    if meta.exists() and (out / TRAJECTORIES).exists():  # (a scene rendered before trajectories were written: again)
        try:
            if json.loads(meta.read_text()) == json.loads(json.dumps(desc)):
                return desc
        except json.JSONDecodeError:
            pass
    if spec.kind not in ("people", "drones"):
        raise ValueError(f"synthetic.kind: expected people or drones, found {spec.kind!r}")
    if spec.in_view not in ("body", "head"):
        raise ValueError(f"synthetic.in_view: expected body or head, found {spec.in_view!r}")
    if spec.motion not in ("random", "paths"):
        raise ValueError(f"synthetic.motion: expected random or paths, found {spec.motion!r}")
    rng = np.random.default_rng(spec.seed)
    room, footprints, boxes = furnish(spec, rng)
    meta.unlink(missing_ok=True)  # an interrupted render is never taken for a finished one
    clear_frames(out)
    static, _ = _scene(room)
    t_static, _ = render(static, camera)
    scales = drift_scales(spec)
    for f in range(spec.background_frames):
        write_depth_png(out / "background" / f"{f:04d}.png",
                        sensor_noise(t_static, spec, rng) * scales["background"][f])
    truth, paths = [], []
    for f, people in enumerate(moves(spec, camera, footprints, boxes, rng)):
        paths.append(trajectory_row(f"{f:04d}.png", people))
        meshes = placed_meshes(spec, people)
        scene, ids = _scene(room + meshes)
        t, gid = render(scene, camera)
        name = f"{f:04d}.png"
        write_depth_png(out / "frames" / name, sensor_noise(t, spec, rng) * scales["frames"][f])
        objects = [o for o in seen_objects(meshes, people, ids[len(room):], gid, camera) if o is not None]
        truth.append({"frame": name, "objects": objects})
    write_json_atomic(out / "ground_truth.json", truth)
    write_json_atomic(out / TRAJECTORIES, paths)
    drift_file = out / "drift.json"
    if any(spec.drift):
        write_json_atomic(drift_file, {"background": scales["background"],
                                       "frames": {f"{f:04d}.png": s for f, s in enumerate(scales["frames"])}})
    else:
        drift_file.unlink(missing_ok=True)
    write_json_atomic(meta, desc)
    return desc

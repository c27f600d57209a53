"""A synthetic scene seen by a rig (issue 61): one room and one sequence of people (or drones),
kept in view of one camera at least, rendered from every camera of the rig with its own sensor
noise. The ground truth is the rig's: an object is listed where one camera sees some of it, with
each camera's visible share (`visible_in`) and its best one as `visibility` (what the rig has
to go on). Seeded like synthetic.generate: the same spec and cameras give the same frames."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .geometry import Camera
from .io import write_depth_png, write_json_atomic
from .scene_spec import SceneSpec, drift_scales
from .synthetic import (GENERATOR_VERSION, TRAJECTORIES, _scene, clear_frames, furnish, moves, placed_meshes,
                        render, seen_objects, sensor_noise, trajectory_row)


def camera_description(camera: Camera) -> dict:
    """What scene.json says of a camera (a change re-renders the scene)."""
    return {"width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy, "cx": camera.cx,
            "cy": camera.cy, "T_world_from_camera": np.asarray(camera.T_world_from_camera).tolist()}


def generate_rig(spec: SceneSpec, cameras: list[tuple[str, Camera]], out_dir: str | Path) -> dict:
    """Render the sequence from every camera: out_dir/NAME/frames/0000.png ..., NAME/background/,
    with one ground_truth.json and scene.json in out_dir (reused when scene.json matches)."""
    out = Path(out_dir)
    described = spec.model_dump()
    if not any(spec.drift):
        del described["drift"]
    desc = {"version": GENERATOR_VERSION, "spec": described,
            "cameras": [{"name": n, **camera_description(c)} for n, c in cameras]}
    meta = out / "scene.json"
    if meta.exists() and (out / TRAJECTORIES).exists():
        try:
            if json.loads(meta.read_text()) == json.loads(json.dumps(desc)):
                return desc
        except json.JSONDecodeError:
            pass
    rng = np.random.default_rng(spec.seed)
    room, footprints, boxes = furnish(spec, rng)
    meta.unlink(missing_ok=True)  # an interrupted render is never taken for a finished one
    noise = [np.random.default_rng([spec.seed, 61, c]) for c in range(len(cameras))]  # each camera's own
    scales = drift_scales(spec)
    static, _ = _scene(room)
    for (name, camera), rng_c in zip(cameras, noise):
        clear_frames(out / name)
        t_static, _ = render(static, camera)
        for f in range(spec.background_frames):
            write_depth_png(out / name / "background" / f"{f:04d}.png",
                            sensor_noise(t_static, spec, rng_c) * scales["background"][f])
    truth, paths = [], []
    for f, people in enumerate(moves(spec, [c for _, c in cameras], footprints, boxes, rng)):
        paths.append(trajectory_row(f"{f:04d}.png", people))
        meshes = placed_meshes(spec, people)
        scene, ids = _scene(room + meshes)
        seen = []
        for (name, camera), rng_c in zip(cameras, noise):
            t, gid = render(scene, camera)
            write_depth_png(out / name / "frames" / f"{f:04d}.png", sensor_noise(t, spec, rng_c) * scales["frames"][f])
            seen.append(seen_objects(meshes, people, ids[len(room):], gid, camera))
        objects = []
        for i in range(len(people)):
            views = {name: s[i] for (name, _), s in zip(cameras, seen) if s[i] is not None}
            if not views:  # hidden from every camera
                continue
            best = max(views.values(), key=lambda o: o["visibility"])
            objects.append({**best, "visible_in": {n: o["visibility"] for n, o in views.items()}})
        truth.append({"frame": f"{f:04d}.png", "objects": objects})
    write_json_atomic(out / "ground_truth.json", truth)
    write_json_atomic(out / TRAJECTORIES, paths)
    write_json_atomic(meta, desc)
    return desc

"""The kernel benchmark's standard scenes (`python -m bench`, bench.pictures, the goldens):
each a config and --set overrides, rendered once into .cache/bench/<name> (2 frames) or
.cache/bench/<name>_seq (a sequence), read back as depth frames in metres.

- kinect_v2: 512x424, people, 6 x 6.5 m ground grid at 0.1 m (the people demo);
- kinect_v2_far: the same camera 2 m high, pitch 15, six people, the grid 7 x 7 m reaching 7.5 m;
- kinect_v1: 640x480, people, the same area at 0.05 m;
- drones: 512x424, 4 x 4.5 x 2.4 m voxel grid at 0.1 m (the drone demo's room).
"""

from __future__ import annotations

import numpy as np

SCENES = {
    "kinect_v2": ("configs/demo_people.yaml", []),
    "kinect_v2_far": ("configs/demo_people.yaml", [
        "camera.extrinsics={height: 2.0, pitch_deg: 15.0, roll_deg: 0.0}", "grid.x=[-3.5, 3.5, 0.1]",
        "grid.y=[0.5, 7.5, 0.1]", "synthetic.people=6"]),
    "kinect_v1": ("configs/demo_people.yaml", [
        "camera.width=640", "camera.height=480",
        "camera.intrinsics={fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5}",
        "grid.x=[-3.0, 3.0, 0.05]", "grid.y=[0.5, 7.0, 0.05]", "model.sensor_noise=[0.002, 0.0025]"]),
    "drones": ("configs/demo_drones.yaml", ["grid.z=[0.0, 2.4, 0.1]", "grid.x=[-2.0, 2.0, 0.1]",
                                            "grid.y=[1.5, 6.0, 0.1]"]),
}


def scene_sets(name) -> tuple[str, list[str]]:
    """(config path, --set overrides) of a standard scene: 2 frames rendered into .cache/bench/<name>."""
    path, sets = SCENES[name]
    cache = f".cache/bench/{name}"
    return path, list(sets) + [f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
                               f"input.background={cache}/background/*.png",
                               f"evaluation.ground_truth={cache}/ground_truth.json", "synthetic.frames=2",
                               "synthetic.background_frames=5"]


def load_scene(name, extra=()):
    """(config, first frame, background frames) of a standard scene, rendered if needed."""
    from dpom_warp.io import read_depth
    from dpom_warp.loading import load_config
    from dpom_warp.sources import expand
    from dpom_warp.synthetic import generate

    path, sets = scene_sets(name)
    cfg = load_config(path, sets + list(extra))
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    scale, shape = cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width)
    depth = read_depth(expand(cfg.inputs.frames, "input.frames")[0], scale, shape)
    bg = np.stack([read_depth(f, scale, shape) for f in expand(cfg.inputs.background, "input.background")])
    return cfg, depth, bg


def scene_frames(name, n, with_truth=False):
    """(frames (n, H, W), background frames) of an n-frame sequence of a standard scene
    (rendered once into .cache/bench/<name>_seq); with_truth adds the frame names and the
    ground truth."""
    from dpom_warp.evaluate import load_ground_truth
    from dpom_warp.io import read_depth
    from dpom_warp.sources import expand

    cache = f".cache/bench/{name}_seq"
    cfg, _, bg = load_scene(name, [f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png",
                                   f"input.background={cache}/background/*.png",
                                   f"evaluation.ground_truth={cache}/ground_truth.json", f"synthetic.frames={n}"])
    shape = (cfg.camera.height, cfg.camera.width)
    files = expand(cfg.inputs.frames, "input.frames")[:n]
    frames = np.stack([read_depth(f, cfg.inputs.depth_scale, shape) for f in files])
    if not with_truth:
        return frames, bg
    return frames, bg, [f.name for f in files], load_ground_truth(f"{cache}/ground_truth.json")

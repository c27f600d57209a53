"""What a synthetic sequence is made of (the config's `synthetic` section, SceneSpec) and the
depth drift it is rendered with (synthetic.py renders it)."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from .values import Int, Node, Num, Pair, _fail, _numbers


class SceneSpec(Node):  # the config's `synthetic` section (config.sections adds its cache folder)
    """What to generate.

    Attributes:
        seed: random seed of the whole sequence.
        frames: number of frames with people.
        background_frames: number of frames of the empty room.
        people: number of people walking, or of drones flying (fixed for the sequence).
        kind: 'people' or 'drones'.
        area: (x_min, x_max, y_min, y_max) where people walk or drones fly, world metres.
        altitude: (z_min, z_max) of the drones' centres, metres.
        obstacles: free-standing cabinets (1.6-1.9 m high) inside `area`, for drones to hide behind.
        room: (x_min, x_max, y_min, y_max, height) of the room's walls.
        furniture: number of furniture pieces placed in the room.
        step_m: distance a person walks between frames.
        pair_gap: > 0: people walk in pairs, side by side, this far apart (centre to centre,
            across their heading): person 2i + 1 at the left of person 2i.
        min_gap: people keep at least this far apart, centre to centre (crowds: 0.45).
        tables: free-standing tables (0.72-0.76 m high) inside `area`, which people walk around
            (a ceiling camera sees them from above).
        in_view: 'body': a person's feet and head are both in the image (a camera at eye
            level); 'head': the top of the head is (a ceiling camera, which sees the floor at a
            person's feet only far from below it).
        motion: 'random': a random walk of step_m a frame that keeps everyone in view;
            'paths': people walk straight to waypoints at about step_m a frame, stop at some
            for 8 to 20 frames, wait or step aside for each other, and walk behind obstacles
            (tracking scenes: crossings, people standing still, hidden ones).
        leave: 'paths': waypoints may lie this far (metres) outside `area`, where a person
            may leave the camera's view and come back later.
        noise: (a, b) of the depth noise sigma(z) = a + b z^2, metres.
        dropout: share of pixels with no reading, at random.
        edge_holes: probability that a pixel at a depth edge has no reading.
        range_m: (near, far) sensor range; outside it there is no reading.
        drift: (sigma, jump_share, jump_min, jump_max): each frame's depths, background frames'
            too, are multiplied by 1 + N(0, sigma), and a jump_share of the frames by a further
            1 +- U(jump_min, jump_max) (a time-of-flight camera's temperature or exposure
            steps); the scales are written to drift.json. All zero: no drift (and the scene's
            cache key and random draws are those of a scene rendered before drift existed).
    """

    seed: Int = Field(0, ge=0, description="seed of the whole sequence")
    frames: Int = Field(20, ge=1, description="frames with people")
    background_frames: Int = Field(10, ge=0, description="frames of the empty room")
    people: Int = Field(5, ge=0, description="people walking, or drones flying")
    kind: Literal["people", "drones"] = Field("people", description="what is rendered")
    area: Annotated[tuple[float, float, float, float], _numbers(4)] = Field(
        (-2.7, 2.7, 1.5, 6.7), description="x_min, x_max, y_min, y_max where they move, metres")
    altitude: Pair = Field((0.6, 2.1), description="drones' heights, metres")
    obstacles: Int = Field(0, ge=0, description="free-standing cabinets")
    room: Annotated[tuple[float, float, float, float, float], _numbers(5)] = Field(
        (-3.6, 3.6, -0.5, 8.0, 3.0), description="x_min, x_max, y_min, y_max, height of the walls, metres")
    furniture: Int = Field(4, ge=0, description="furniture pieces placed in the room")
    step_m: Num = Field(0.3, ge=0, description="walk per frame, metres")
    pair_gap: Num = Field(0.0, ge=0, description="> 0: people walk in pairs this far apart")
    min_gap: Num = Field(0.6, gt=0, description="people keep this far apart, metres")
    tables: Int = Field(0, ge=0, description="free-standing tables inside the area")
    in_view: Literal["body", "head"] = Field("body", description="what of a person must be in "
                                             "the image: body (eye level) or head (ceiling cameras)")
    motion: Literal["random", "paths"] = Field("random", description="random: a random walk in view; "
                                               "paths: straight walks to waypoints with stops (tracking scenes)")
    leave: Num = Field(0.0, ge=0, description="paths: waypoints up to this far outside the area "
                                                       "(people leave the view and come back), metres")
    noise: Pair = Field((0.002, 0.0015), description="depth noise a + b z^2, metres")
    dropout: Num = Field(0.01, ge=0, le=1, description="share of pixels with no reading")
    edge_holes: Num = Field(0.5, ge=0, le=1,
                            description="probability of no reading at a depth edge")
    range_m: Pair = Field((0.5, 8.0), description="near, far sensor range, metres")
    drift: Annotated[tuple[float, float, float, float], _numbers(4)] = Field(
        (0.0, 0.0, 0.0, 0.0), description="frame-wide depth drift [sigma, jump_share, jump_min, jump_max]: each "
                                          "frame's (and background frame's) depths times 1 + N(0, sigma), and "
                                          "jump_share of them jump by jump_min to jump_max either way (scales in "
                                          "drift.json)")

    @model_validator(mode="after")
    def _drift(self):
        sigma, share, lo, hi = self.drift
        if min(self.drift) < 0 or share > 1 or lo > hi or max(sigma, hi) >= 0.5:
            raise _fail(f"expected [sigma, jump_share, jump_min, jump_max] >= 0 with jump_share <= 1, "
                        f"jump_min <= jump_max and drifts under 0.5, found {list(self.drift)}", "drift")
        return self


def drift_scales(spec: SceneSpec) -> dict:
    """Each background frame's and frame's depth scale (SceneSpec.drift), from a random stream of
    their own (the scene's other draws are those of the same scene without drift)."""
    sigma, share, lo, hi = spec.drift
    n = {"background": spec.background_frames, "frames": spec.frames}
    if not any(spec.drift):
        return {k: [1.0] * v for k, v in n.items()}
    rng = np.random.default_rng([spec.seed, 2026])
    out = {}
    for key, count in n.items():
        s = 1.0 + sigma * rng.standard_normal(count)
        jump = rng.random(count) < share
        s = s + jump * rng.choice([-1.0, 1.0], count) * rng.uniform(lo, hi, count)
        out[key] = [round(float(x), 6) for x in s]
    return out

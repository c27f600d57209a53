"""Tracks placed at their detections' heads (heads.py): the head's centre from its points, by
hand on spheres cast into a camera (from above, level, the demo's camera, whole frames from the
ceiling and eye level, a rig's two cameras); what is not a head (a wall beside it, unless the
background has it; too few points; a taller neighbour's); the placement of tracks (a rendered
run's tracks nearer the truth than the cells': test_track_runs)."""

from __future__ import annotations

import numpy as np
import pytest

from dpom_warp.heads import MIN_POINTS, head_centre, place_tracks, placed_rows
from dpom_warp.track_files import Track

R = 0.11  # the head's radius (object.head_radius's default)
WIDTH, HEIGHT = 0.4, 1.85  # the object's


def cast(centre, forward, head, f=4000.0, n=801, wall_x=None, other=None):
    """The points a pinhole camera at `centre` looking along `forward` (pixels of 1/f radians, an
    n x n image) sees of a sphere of radius R centred at `head` (and one at `other`), and of the
    plane x = wall_x (from the floor to 2.5 m) where given: the nearest hit of each ray."""
    forward = np.asarray(forward, float) / np.linalg.norm(forward)
    side = np.cross(forward, [0.0, 0.0, 1.0] if abs(forward[2]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, forward)
    a = (np.arange(n) - n // 2) / f
    u, v = np.meshgrid(a, a)
    rays = forward + u[..., None] * side + v[..., None] * up
    rays = rays.reshape(-1, 3) / np.linalg.norm(rays.reshape(-1, 3), axis=1)[:, None]
    t = np.full(len(rays), np.inf)
    for h in [head] + ([other] if other is not None else []):
        oc = centre - np.asarray(h, float)
        b = rays @ oc
        disc = b * b - (oc @ oc - R * R)
        t = np.minimum(t, np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf))
    if wall_x is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            tw = (wall_x - centre[0]) / rays[:, 0]
        z = centre[2] + tw * rays[:, 2]
        tw = np.where((tw > 0) & (z >= 0) & (z <= 2.5), tw, np.inf)
        t = np.minimum(t, tw)
    hit = np.isfinite(t)
    return centre + t[hit, None] * rays[hit]


@pytest.mark.parametrize("view", ["above", "side"])
def test_a_head_seen_from_far_above_or_level_is_found_at_its_centre(view):
    """Seen from far away (rays nearly parallel, pixels even over the head's outline), the points
    of the head's upper half (above its top less R) are: from above, the half facing the camera;
    from the side at its height, the upper half of the half facing the camera. Either way their
    mean is 2/3 R nearer the camera than the centre along the ray (a hemisphere's mean depth
    over its disc, the same over a half disc) and level with it across the ray, so moving it 2/3
    R back along the ray gives the centre: to within the pixels' steps (a millimetre here)."""
    head = np.array([0.3, 4.2, HEIGHT - R])
    if view == "above":
        centre, forward = head + [0.0, 0.0, 30.0], [0.0, 0.0, -1.0]
    else:
        centre, forward = head + [0.0, -30.0, 0.0], [0.0, 1.0, 0.0]
    points = cast(centre, forward, head, f=20000.0)
    assert len(points) > 10000
    got = head_centre(points, head[:2] + [0.12, -0.1], centre, WIDTH, HEIGHT, R)
    assert got is not None and np.hypot(*(got[:2] - head[:2])) < 0.002


def test_a_head_seen_by_the_demo_s_camera_is_within_a_fifth_of_its_radius():
    """Between those two views the head's upper half is not the half facing the camera, and the
    mean moves by part of R: an eye-level camera 2.2 m up, 4 m away (the demo's), still places
    it within R / 5, where the cells put people a cell's half-width off."""
    head = np.array([-0.5, 4.0, 1.75 - R])
    centre = np.array([0.0, 0.0, 2.2])
    points = cast(centre, head - centre, head, f=365.0, n=121)
    got = head_centre(points, head[:2] + [0.05, 0.05], centre, WIDTH, HEIGHT, R)
    assert got is not None and np.hypot(*(got[:2] - head[:2])) < R / 5


def test_a_wall_beside_the_head_or_too_few_points_give_no_position():
    """A wall 0.15 m beside the head, 2.5 m high, rises more than HEAD_ABOVE over the object's
    height within half its width of the cell: no head is that tall, no position. Fewer than
    MIN_POINTS points: none either."""
    head = np.array([0.0, 4.0, HEIGHT - R])
    centre = np.array([0.0, 0.0, 2.2])
    points = cast(centre, head - centre, head, f=365.0, n=121, wall_x=0.15)
    assert head_centre(points, head[:2], centre, WIDTH, HEIGHT, R) is None
    alone = cast(centre, head - centre, head, f=365.0, n=121)
    assert head_centre(alone, head[:2], centre, WIDTH, HEIGHT, R) is not None
    assert head_centre(alone[:MIN_POINTS - 1], head[:2], centre, WIDTH, HEIGHT, R) is None


def test_a_taller_neighbour_half_a_metre_away_is_not_taken_for_the_head():
    """A person 1.70 m tall with a neighbour of 1.95 m 0.5 m beside them, the cell 0.1 m toward
    the neighbour: within half the object's width (0.2 m) of the cell only the person's own head
    (the neighbour's reaches 0.39 - 0.11 = 0.28 m of it), so their head is found, within R / 5 as
    from the demo's camera alone; the neighbour's cell finds the neighbour's."""
    own, tall = np.array([0.0, 4.0, 1.70 - R]), np.array([0.5, 4.0, 1.95 - R])
    centre = np.array([0.0, 0.0, 2.2])
    points = cast(centre, own - centre, own, f=365.0, n=161, other=tall)
    got = head_centre(points, own[:2] + [0.1, 0.0], centre, WIDTH, HEIGHT, R)
    assert got is not None and np.hypot(*(got[:2] - own[:2])) < R / 5
    got = head_centre(points, tall[:2] - [0.1, 0.0], centre, WIDTH, HEIGHT, R)
    assert got is not None and np.hypot(*(got[:2] - tall[:2])) < R / 5


def test_tracks_take_the_head_of_their_frame_s_nearest_detection_within_the_radius():
    """By hand: frame 0 has detections at cells (0, 0) (head (0.03, -0.02)) and (1, 0) (no
    head); frame 1 one at (2, 2) with head (2.01, 2.04). A row at (0.1, 0) is nearest the
    first (0.1 m), within 0.2: its head; one at (1, 0.1) is nearest the second, which has none;
    a bridged row stays; a row 0.3 m from every detection stays."""
    found = [[(0.0, 0.0, (0.03, -0.02)), (1.0, 0.0, None)], [(2.0, 2.0, (2.01, 2.04))]]
    rows = [(1, (0.1, 0.0, 0.0), False), (2, (1.0, 0.1, 0.0), False), (3, (0.0, 0.1, 0.0), True),
            (4, (0.0, 0.3, 0.0), False)]
    def plain(rows):
        return [(t, tuple(float(v) for v in p), b) for t, p, b in rows]

    assert plain(placed_rows(rows, found[0], 0.2)) == [(1, (0.03, -0.02, 0.0), False), rows[1], rows[2], rows[3]]
    assert plain(placed_rows(rows, [], 0.2)) == rows
    track = Track(7, [0, 1], np.array([[0.1, 0.0, 0.0], [2.1, 2.1, 0.0]]), np.ones(2), np.array([False, False]))
    place_tracks([track], found, 0.2)
    assert np.allclose(track.xyz, [[0.03, -0.02, 0.0], [2.01, 2.04, 0.0]])


def depth_image(camera, head, wall_x=None, wall_top=2.5):
    """The z-depth image `camera` reads of a sphere of radius R centred at `head` over the floor
    (z = 0) and before the plane x = wall_x (`wall_top` high) where given, by casting each pixel's ray
    (geometry.Camera.rays: its parameter is z-depth)."""
    rays, c = camera.rays(), camera.centre
    oc = c - np.asarray(head, float)
    a = np.sum(rays * rays, axis=-1)
    b = rays @ oc
    disc = b * b - a * (oc @ oc - R * R)
    t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / a, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(rays[..., 2] < 0, -c[2] / rays[..., 2], np.inf)
        if wall_x is not None:
            tw = (wall_x - c[0]) / rays[..., 0]
            z = c[2] + tw * rays[..., 2]
            t = np.minimum(t, np.where((tw > 0) & (z >= 0) & (z <= wall_top), tw, np.inf))
    t = np.minimum(t, floor)
    return np.where(np.isfinite(t), t, 0.0).astype(np.float32)


@pytest.mark.parametrize("mounting", ["ceiling", "eye level"])
def test_a_frame_s_head_is_found_from_the_ceiling_and_from_eye_level(mounting):
    """heads() on whole frames (the pixels it reads projected from the cell, every step-th, the
    floor left out by height, no background): a camera on the ceiling straight over the head
    (the exact case above: within the pixels' steps, 5 mm at 160 x 120) and the demo's camera
    2.2 m up, pitched 20 deg (within R / 5, as above)."""
    from types import SimpleNamespace

    from dpom_warp.geometry import Camera, pose_from_angles
    from dpom_warp.heads import heads

    if mounting == "ceiling":
        head, pose, bound = np.array([0.0, 4.0, HEIGHT - R]), pose_from_angles(3.0, 90.0, y_m=4.0), 0.005
    else:
        head, pose, bound = np.array([-0.5, 4.0, 1.75 - R]), pose_from_angles(2.2, 20.0), R / 5
    camera = Camera(160, 120, 150.0, 150.0, 79.5, 59.5, pose)
    geometry = SimpleNamespace(rays=camera.rays(), centre=camera.centre)
    obj = SimpleNamespace(head_radius=R, width=WIDTH, height=HEIGHT)
    cell = SimpleNamespace(x=head[0] + 0.1, y=head[1] - 0.1)  # a cell's centre beside the person
    (got,) = heads([cell], [depth_image(camera, head)], [camera], [geometry], [None], 1, [1.0], obj)
    assert got is not None and np.hypot(got[0] - head[0], got[1] - head[1]) < bound
    empty = np.where(depth_image(camera, head) > 0, depth_image(camera, head[:2].tolist() + [-5.0]), 0)
    assert heads([cell], [empty], [camera], [geometry], [None], 1, [1.0], obj) == [None]  # the floor alone


def test_a_rig_s_head_is_the_mean_of_its_cameras_and_a_camera_without_a_frame_is_left_out():
    """Two cameras (the ceiling's and the demo's eye-level one) see one head: the rig's position
    is the mean of what each finds alone; with the second camera's frame missing (None) it is the
    first camera's alone."""
    from types import SimpleNamespace

    from dpom_warp.geometry import Camera, pose_from_angles
    from dpom_warp.heads import heads

    head = np.array([0.2, 4.0, HEIGHT - R])
    cams = [Camera(160, 120, 150.0, 150.0, 79.5, 59.5, pose_from_angles(3.0, 90.0, y_m=4.0)),
            Camera(160, 120, 150.0, 150.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))]
    geos = [SimpleNamespace(rays=c.rays(), centre=c.centre) for c in cams]
    obj = SimpleNamespace(head_radius=R, width=WIDTH, height=HEIGHT)
    cell = SimpleNamespace(x=head[0] + 0.1, y=head[1])
    depths = [depth_image(c, head) for c in cams]
    alone = [heads([cell], [d], [c], [g], [None], 1, [1.0], obj)[0] for d, c, g in zip(depths, cams, geos)]
    assert all(a is not None for a in alone) and alone[0] != alone[1]
    (both,) = heads([cell], depths, cams, geos, [None, None], 1, [1.0, 1.0], obj)
    assert np.allclose(both, np.mean(alone, axis=0), atol=1e-12)
    assert heads([cell], [depths[0], None], cams, geos, [None, None], 1, [1.0, 1.0], obj) == [alone[0]]


def test_a_wall_in_the_background_is_left_out_and_the_head_beside_it_found():
    """The demo's camera, a head 0.15 m before a 2.2 m wall (on its far side, nothing read above
    it): with no background the wall rises over any head within reach (no position); with the
    background (the wall and floor alone, at half the resolution as an engine at stride 2 holds
    it, as head_background gives it a run: where a frame's pixel on the wall's top edge falls in
    an engine pixel above it, which reads nothing, its neighbours' nearest depth is the wall's)
    its points are not the frame's and the head is found within R / 5, as without the wall."""
    from types import SimpleNamespace

    from dpom_warp.geometry import Camera, pose_from_angles
    from dpom_warp.heads import head_background, heads
    from dpom_warp.model import Background

    head = np.array([-0.5, 4.0, 1.75 - R])
    camera = Camera(160, 120, 150.0, 150.0, 79.5, 59.5, pose_from_angles(2.2, 20.0))
    geometry = SimpleNamespace(rays=camera.rays(), centre=camera.centre)
    obj = SimpleNamespace(head_radius=R, width=WIDTH, height=HEIGHT)
    cell = SimpleNamespace(x=head[0], y=head[1] - 0.1)
    frame = depth_image(camera, head, wall_x=head[0] - 0.15, wall_top=2.2)
    assert heads([cell], [frame], [camera], [geometry], [None], 1, [1.0], obj) == [None]
    mu = depth_image(camera, head - [0.0, 0.0, 10.0], wall_x=head[0] - 0.15, wall_top=2.2)[::2, ::2].astype(np.float64)
    bg = head_background((Background(mu, np.full(mu.shape, 0.01), np.zeros(mu.shape), np.zeros(mu.shape)), None))
    (got,) = heads([cell], [frame], [camera], [geometry], [bg], 2, [1.0], obj)
    assert got is not None and np.hypot(got[0] - head[0], got[1] - head[1]) < R / 5

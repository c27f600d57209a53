"""The clustering baseline (bench/baseline.py) on hand-made point sets: people found at their
centres, walls, tables and floors rejected, an arm clustered apart merged with its body."""

import numpy as np

from bench.baseline import ClusterParams, detect_people, heads, score_config

from test_cli import small_config
from paths import CONFIGS

RNG = np.random.default_rng(0)


def person(x, y, height=1.75, n=3000):
    """Points on a person's stand-in: a body cylinder (radius 0.2 m) up to the shoulders,
    0.25 m below the top, and a head cylinder (radius 0.1 m) above them."""
    a, z = RNG.uniform(0, 2 * np.pi, n), RNG.uniform(0, height, n)
    radius = np.where(z > height - 0.25, 0.1, 0.2)
    return np.column_stack([x + radius * np.cos(a), y + radius * np.sin(a), z])


def box(x0, x1, y0, y1, z0, z1, n=4000):
    return np.column_stack([RNG.uniform(x0, x1, n), RNG.uniform(y0, y1, n), RNG.uniform(z0, z1, n)])


FLOOR = box(-3, 3, 0, 8, 0, 0.01, 20000)


def test_people_found_walls_tables_and_floor_rejected():
    points = np.vstack([FLOOR, person(0, 3), person(0.6, 3.1, 1.6), box(-2.05, -2.0, 0, 8, 0, 3.0, 20000),
                        box(1.5, 2.3, 4, 4.8, 0, 0.75)])
    found = detect_people(points)
    assert len(found) == 2
    np.testing.assert_allclose(found[0], [0, 3], atol=0.05)  # the taller first
    np.testing.assert_allclose(found[1], [0.6, 3.1], atol=0.05)


def test_detached_arm_is_merged_and_area_limits_the_search():
    arm = box(0.24, 0.3, 2.95, 3.05, 0.9, 1.4, 500)  # apart from the body by more than eps
    found = detect_people(np.vstack([FLOOR, person(0, 3), arm]))
    assert len(found) == 1
    assert len(detect_people(np.vstack([FLOOR, person(0, 3)]), area=(1, 3, 0, 8))) == 0
    assert len(detect_people(FLOOR)) == 0 and len(detect_people(np.zeros((0, 3)))) == 0


def test_heads_keep_distance_and_height():
    p = ClusterParams()
    tops = heads(np.vstack([person(0, 0, 1.8), person(1.0, 0, 1.0)]), p)
    assert len(tops) == 1 and np.linalg.norm(tops[0]) < 0.15  # the 1.0 m one is too low
    assert len(heads(np.vstack([person(0, 0), person(0.45, 0)]), p)) == 2  # side by side: two


def test_baseline_scores_a_rendered_scene(tmp_path):
    from dpom_warp.loading import load_config
    from dpom_warp.frames import render_synthetic

    import yaml

    demo = yaml.safe_load(open(CONFIGS / "demo_people.yaml"))  # full resolution, as the bench runs it
    cfg = load_config(small_config(tmp_path, camera=demo["camera"]))
    render_synthetic(cfg, log=lambda *_: None)
    s = score_config(cfg)
    assert s["n_gt"] == 9 and s["recall"] >= 8 / 9 and s["precision"] >= 8 / 9

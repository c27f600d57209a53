"""Every config in configs/ and every bench scene (fast and exact) writes the detections, maps,
tracks and per-frame counts recorded in tests/golden.json (issue 58: a restructuring changes no
byte of what a run produces). Record again only for a change meant to alter results, and say
so in its commit: python tests/golden.py"""

import json

import pytest

from golden import GOLDEN, digest, run_scenario, scenarios

RECORDED = json.loads(GOLDEN.read_text())


def test_every_config_and_bench_scene_is_recorded():
    assert sorted(RECORDED) == sorted(scenarios())


@pytest.mark.parametrize("name", sorted(scenarios()))
def test_outputs_are_byte_identical_to_the_recorded(name, tmp_path):
    got = digest(run_scenario(name, tmp_path))
    want = RECORDED[name]
    for key in ("detections.csv", "tracks.csv", "track_table.csv"):
        assert got[key] == want[key], f"{name}: {key} differs from the recorded run"
    assert sorted(got["maps"]) == sorted(want["maps"]), f"{name}: other maps"
    changed = [m for m in want["maps"] if got["maps"][m] != want["maps"][m]]
    assert not changed, f"{name}: maps {changed} differ from the recorded run"
    assert got["frames"] == want["frames"], f"{name}: the frames' counts differ"

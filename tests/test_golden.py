"""Every config in configs/ and every bench scene (fast and exact) writes the detections, maps,
tracks and per-frame counts recorded in tests/golden.json (issue 58: a restructuring changes no
byte of what a run produces). The maps and list counts byte for byte on the machine that
recorded them, to rounding on another (their last bits depend on the CPU: golden.py). Record
again only for a change meant to alter results, and say so in its commit: python tests/golden.py"""

import json

import pytest

from golden import GOLDEN, digest, machine, run_scenario, scenarios

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
    if want["machine"] == machine():
        changed = [m for m in want["maps"] if got["maps"][m] != want["maps"][m]]
        assert not changed, f"{name}: maps {changed} differ from the recorded run"
        assert got["frames"] == want["frames"], f"{name}: the frames' counts differ"
    assert_close_to_the_recorded(name, got, want)  # (what another machine checks: it holds here too)


def assert_close_to_the_recorded(name, got, want):
    """What a machine other than the recording one can check of the maps and counts: each
    map's sum within 0.05 and the same cells at rho* >= 0.5; the same detections a frame,
    iterations within 2 and list entries within 0.1 %."""
    for m, (total, high) in want["map_sums"].items():
        assert abs(got["map_sums"][m][0] - total) <= 0.05 and got["map_sums"][m][1] == high, (
            f"{name}: map {m} (sum, cells >= 0.5) {got['map_sums'][m]} against the recorded {[total, high]}")
    for f, rec in want["frames"].items():
        now = got["frames"][f]
        assert now["detections"] == rec["detections"] and abs(now["iterations"] - rec["iterations"]) <= 2, (
            f"{name}: frame {f} {now} against the recorded {rec}")
        for key in ("entries", "kept_entries", "live"):
            if rec[key] is not None:
                assert abs(now[key] - rec[key]) <= 1e-3 * rec[key] + 1, f"{name}: frame {f} {key} {now} against {rec}"

"""Reading depth frames: good files come back in metres, bad ones give one-line errors."""


import numpy as np
import pytest
from PIL import Image

from dpom_warp.io import InputError, read_depth, write_depth_png
import paths

REAL = paths.REAL / "five_people" / "depth_mm.png"


def test_png_roundtrip_in_metres(tmp_path):
    d = np.array([[0.0, 1.2345], [7.5, 0.0005]])
    write_depth_png(tmp_path / "d.png", d)
    got = read_depth(tmp_path / "d.png", 0.001, (2, 2))
    np.testing.assert_allclose(got, [[0, 1.234], [7.5, 0.0]], atol=1e-6)  # rounded to mm
    assert got.dtype == np.float32


def test_real_kinect_frame_reads():
    d = read_depth(REAL, 0.001, (480, 640))
    valid = d[d > 0]
    assert 0.5 < valid.min() and valid.max() < 10 and valid.size > 0.5 * d.size


def test_npy_frame(tmp_path):
    np.save(tmp_path / "d.npy", np.full((3, 4), 2000, np.uint16))
    assert read_depth(tmp_path / "d.npy", 0.001, (3, 4)).max() == pytest.approx(2.0)


@pytest.mark.parametrize("make, message", [
    (lambda p: None, "no such file"),
    (lambda p: p.write_bytes(b""), "not a readable image"),
    (lambda p: p.write_bytes(open(REAL, "rb").read()[:2000]), "not a readable image"),
    (lambda p: Image.fromarray(np.zeros((4, 4), np.uint8)).save(p), "found mode L"),
    (lambda p: Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(p), "found mode RGB"),
])
def test_bad_png(tmp_path, make, message):
    p = tmp_path / "bad.png"
    make(p)
    with pytest.raises(InputError, match=message) as e:
        read_depth(p, 0.001)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("values, message", [
    (np.array([[1.0, np.nan]]), "NaN or infinite"),
    (np.array([[1.0, np.inf]]), "NaN or infinite"),
    (np.array([[1.0, -2.0]]), "negative"),
    (np.zeros((2, 2, 2)), "expected a 2-D numeric depth array"),
])
def test_bad_npy(tmp_path, values, message):
    p = tmp_path / "bad.npy"
    np.save(p, values)
    with pytest.raises(InputError, match=message):
        read_depth(p, 1.0)


def test_wrong_size(tmp_path):
    write_depth_png(tmp_path / "d.png", np.ones((4, 5)))
    with pytest.raises(InputError, match="expected 6x4 pixels .* found 5x4"):
        read_depth(tmp_path / "d.png", 0.001, (4, 6))


def test_outputs_are_ordinary_readable_files(tmp_path):
    from dpom_warp.io import write_json_atomic

    write_json_atomic(tmp_path / "s.json", {"a": 1})
    assert (tmp_path / "s.json").stat().st_mode & 0o044 == 0o044  # group and others can read
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]


def test_a_depth_scale_off_by_a_thousand_is_named(tmp_path, capsys):
    """The real frame at 1 m per unit (its readings are millimetres): the median reading is no
    depth camera's, so the floor fit's error says so, and a run with its pose given warns at
    once (it would find nothing: every reading kilometres away); at 0.001 nothing is said."""
    import yaml

    from dpom_warp.cli import main
    from dpom_warp.io import depth_scale_hint

    raw = np.asarray(Image.open(paths.REAL / "five_people" / "depth_mm.png"))
    assert depth_scale_hint(raw * 0.001, 0.001) is None
    hint = depth_scale_hint(raw * 1.0, 1.0)
    assert hint.startswith("its readings' median is 2570 m, at input.depth_scale 1 m per unit")
    assert depth_scale_hint(np.zeros((4, 4)), 1.0) is None  # no reading: nothing to judge
    config = paths.CONFIGS / "real_five_people.yaml"
    assert main(["run", str(config), "--set", "input.depth_scale=1.0", "--output", str(tmp_path / "a"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "too few depth readings for a floor" in err and "is the scale right?" in err
    cfg = yaml.safe_load(config.read_text())
    cfg["input"]["frames"] = str(paths.REAL / "five_people" / "depth_mm.png")
    cfg["camera"]["extrinsics"] = {"height": 1.3, "pitch_deg": 5.0}
    cfg["output"] = {"dir": str(tmp_path / "b"), "images": False}
    cfg["device"] = "cpu"
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--set", "input.depth_scale=1.0", "--no-progress"]) == 0
    assert f"warning: {cfg['input']['frames']}: its readings' median is 2570 m" in capsys.readouterr().out
    assert main(["run", str(path), "--no-progress", "--overwrite"]) == 0
    assert "is the scale right" not in capsys.readouterr().out

"""A rendered small sequence (6 frames) and its config, shared by the bad-input and long-run
tests (test_errors, test_long_runs), and ways to damage the config and the frames."""

import json

import numpy as np
import pytest
import yaml
from PIL import Image

from dpom_warp.cli import main

from test_cli import small_config


@pytest.fixture(scope="module", name="scene")
def scene_fixture(tmp_path_factory):
    """A rendered small sequence (6 frames) and its config, shared by the tests here."""
    tmp = tmp_path_factory.mktemp("scene")
    path = small_config(tmp, frames=6)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "first")]) == 0
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]  # the frames now exist; tests copy and damage them
    return tmp, cfg


def write_config(tmp_path, cfg, **sets):
    cfg = json.loads(json.dumps(cfg))
    for key, value in sets.items():
        node = cfg
        *parents, last = key.split("__")
        for p in parents:
            node = node.setdefault(p, {})
        if value is DELETE:
            node.pop(last, None)
        else:
            node[last] = value
    cfg["output"]["dir"] = str(tmp_path / "out")
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


DELETE = object()


def frames_with(tmp_path, scene_dir, bad_name, make):
    """A copy of the frames folder with frame `bad_name` replaced by what `make` writes."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for f in sorted((scene_dir / "scene" / "frames").glob("*.png")):
        (folder / f.name).write_bytes(f.read_bytes())
    target = folder / bad_name
    target.unlink(missing_ok=True)
    make(target)
    return folder


def png8(p):
    Image.fromarray(np.zeros((106, 128), np.uint8)).save(p)


def png_rgb(p):
    Image.fromarray(np.zeros((106, 128, 3), np.uint8)).save(p)


def truncated(p):
    src = sorted(p.parent.glob("*.png"))[0].read_bytes()
    p.write_bytes(src[: len(src) // 3])


def npy(values):
    def make(p):
        np.save(p.with_suffix(".npy"), values)
    return make
